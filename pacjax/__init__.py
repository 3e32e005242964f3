"""pacjax: differentiable statics of tendon-driven continuum robots (PCC, PAC and polynomial
curvature) in JAX."""

from . import _config as _config  # noqa: F401  (float64 by default)
from . import _deprecated as _deprecated
from ._model.loads import Gravity as Gravity
from ._model.loads import PointForce as PointForce
from ._model.loads import PointMass as PointMass
from ._model.loads import PointMoment as PointMoment
from ._model.robot import ExponentialStiffening as ExponentialStiffening
from ._model.robot import Robot as Robot
from ._model.robot import Segment as Segment
from ._model.robot import StiffeningLaw as StiffeningLaw
from ._model.scene import Scene as Scene
from ._model.strain import PAC as PAC
from ._model.strain import PCC as PCC
from ._model.strain import PolynomialCurvature as PolynomialCurvature
from ._model.strain import StrainModel as StrainModel
from ._model.tendons import Tendon as Tendon
from ._results import RESULTS as RESULTS

__version__ = "0.1.0"
from . import dynamics as dynamics
from . import inverse as inverse
from . import presets as presets
from ._identify.dataset import MocapDataset as MocapDataset
from ._identify.dataset import static_frames as static_frames
from ._identify.identify import identify as identify
from ._identify.report import IdentificationReport as IdentificationReport
from ._identify.synthetic import high_fidelity as high_fidelity
from ._identify.synthetic import synthetic_mocap as synthetic_mocap
from ._model.query import astype as astype
from ._model.query import backbone as backbone
from ._model.query import markers as markers
from ._model.query import tendon_tensions as tendon_tensions
from ._model.query import tip_pose as tip_pose
from ._statics.batch import iter_batch as iter_batch
from ._statics.batch import solve_batch as solve_batch
from ._statics.equilibrium import solve_equilibrium as solve_equilibrium
from ._statics.multistart import Equilibria as Equilibria
from ._statics.multistart import find_equilibria as find_equilibria
from ._statics.options import SolverOptions as SolverOptions
from ._statics.solution import Equilibrium as Equilibrium
from .dynamics import Damping as Damping
from .dynamics import Trajectory as Trajectory
from .dynamics import simulate as simulate
from .inverse import InverseResult as InverseResult
from .inverse import Tracking as Tracking
from .inverse import Workspace as Workspace
from .inverse import inverse_statics as inverse_statics
from .inverse import inverse_statics_batch as inverse_statics_batch
from .inverse import sample_workspace as sample_workspace
from .inverse import track as track

_deprecated.install()
