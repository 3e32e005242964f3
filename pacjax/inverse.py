"""Inverse statics: the tendon commands whose equilibrium puts the robot where the user wants
it (see :func:`inverse_statics`)."""

from ._inverse.inverse import inverse_statics as inverse_statics
from ._inverse.inverse import inverse_statics_batch as inverse_statics_batch
from ._inverse.inverse import sample_workspace as sample_workspace
from ._inverse.inverse import track as track
from ._inverse.problem import default_command_range as default_command_range
from ._inverse.results import MESSAGES as MESSAGES
from ._inverse.results import NO_EQUILIBRIUM as NO_EQUILIBRIUM
from ._inverse.results import NOT_REACHED as NOT_REACHED
from ._inverse.results import REACHED as REACHED
from ._inverse.results import InverseResult as InverseResult
from ._inverse.results import Tracking as Tracking
from ._inverse.results import Workspace as Workspace
