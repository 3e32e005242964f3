"""pacjax: differentiable statics of tendon-driven continuum robots (PCC, PAC and polynomial
curvature) in JAX."""

from . import _config as _config  # noqa: F401  (float64 by default)
from ._loads import Gravity as Gravity
from ._loads import PointForce as PointForce
from ._loads import PointMass as PointMass
from ._loads import PointMoment as PointMoment
from ._robot import ExponentialStiffening as ExponentialStiffening
from ._robot import Robot as Robot
from ._robot import Segment as Segment
from ._robot import StiffeningLaw as StiffeningLaw
from ._scene import Scene as Scene
from ._strain import PAC as PAC
from ._strain import PCC as PCC
from ._strain import PolynomialCurvature as PolynomialCurvature
from ._strain import StrainModel as StrainModel
from ._tendons import Tendon as Tendon

__version__ = "0.1.0"
from . import dynamics as dynamics
from . import inverse as inverse
from . import presets as presets
from ._api import astype as astype
from ._api import backbone as backbone
from ._api import markers as markers
from ._api import tendon_tensions as tendon_tensions
from ._api import tip_pose as tip_pose
from ._batch import iter_batch as iter_batch
from ._batch import solve_batch as solve_batch
from ._equilibrium import SolverOptions as SolverOptions
from ._equilibrium import solve_equilibrium as solve_equilibrium
from ._fitreport import IdentificationReport as IdentificationReport
from ._identify import identify as identify
from ._mocap import MocapDataset as MocapDataset
from ._mocap import static_frames as static_frames
from ._multistart import Equilibria as Equilibria
from ._multistart import find_equilibria as find_equilibria
from ._solution import Equilibrium as Equilibrium
from ._synthetic import high_fidelity as high_fidelity
from ._synthetic import synthetic_mocap as synthetic_mocap
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
