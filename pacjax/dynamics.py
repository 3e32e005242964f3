"""Dynamics: the paper's full model (its eq. 7) integrated in time (see :func:`simulate`)."""

from ._chord import kvaerno5 as kvaerno5
from ._dynamics.batch import simulate_batch as simulate_batch
from ._dynamics.damping import DEFAULT_DAMPING_RATIO as DEFAULT_DAMPING_RATIO
from ._dynamics.damping import Damping as Damping
from ._dynamics.equations import accelerations as accelerations
from ._dynamics.equations import natural_frequencies as natural_frequencies
from ._dynamics.equations import total_energy as total_energy
from ._dynamics.rosenbrock import Rosenbrock23 as Rosenbrock23
from ._dynamics.simulate import ATOL as ATOL
from ._dynamics.simulate import KNOT_GRID as KNOT_GRID
from ._dynamics.simulate import RTOL as RTOL
from ._dynamics.simulate import Trajectory as Trajectory
from ._dynamics.simulate import rosenbrock23 as rosenbrock23
from ._dynamics.simulate import simulate as simulate
