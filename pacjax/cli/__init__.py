"""The ``pacjax`` command line (:mod:`pacjax.cli.main`) and the runs behind it: many equilibria
to a columnar file (:mod:`pacjax.cli.batchrun`) and the benchmark (:mod:`pacjax.cli.bench`)."""

from .main import DEMO_COMMANDS as DEMO_COMMANDS
from .main import cli as cli
from .main import main as main
