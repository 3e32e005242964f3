"""The ``pacjax`` command line (:mod:`pacjax.cli.main`) and the runs behind it: many equilibria
to a columnar file (:mod:`pacjax.cli.batchrun`) and the benchmark (:mod:`pacjax.cli.bench`).

Importing this package imports click and numpy, not JAX: ``pacjax --help`` and usage errors
answer at once; a command imports JAX when it runs.
"""

from .main import DEMO_COMMANDS as DEMO_COMMANDS
from .main import cli as cli
from .main import main as main
