"""Figures: equilibria (:mod:`pacjax.plots.equilibria`), identifications
(:mod:`pacjax.plots.fit`), simulated motions (:mod:`pacjax.plots.animation`) and batch
workspaces (:mod:`pacjax.plots.batch`). Imports matplotlib."""

from .equilibria import CASE_COLORS as CASE_COLORS
from .equilibria import draw_backbone as draw_backbone
from .equilibria import plot_equilibria as plot_equilibria
from .equilibria import plot_equilibrium_grid as plot_equilibrium_grid
