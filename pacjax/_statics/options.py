"""The settings of every static solve: :class:`SolverOptions`."""

import dataclasses

import diffrax
import equinox as eqx
import numpy as np

from .._chord import kvaerno5

#: Default tolerance on the scaled residual per precision. Float32's round-off (~1e-7
#: relative) keeps its residual above 1e-10: with the float64 default, float32 solves ran to
#: their step limit at residuals of 1e-5 to 1e-9 (``tests/test_campaign.py``).
DEFAULT_TOL = {"float64": 1e-10, "float32": 1e-4}

#: Default first pseudo-time step of PCC/PAC (polar coordinates, no Newton start). At the
#: aligned start a plane angle's stiffness is only its regulariser's (1e-6 of the elastic
#: scale), and ``1 / dt`` is what holds it while the segments bend; 1e3 holds it and leaves the
#: other modes close to Newton steps. From 1, a soft robot hanging under gravity crept up its
#: stiffness for two more steps (``benchmarks/RESULTS.md``, "A first step as long as Newton's").
POLAR_INITIAL_DT = 1e3


def initial_dt(options: "SolverOptions", newton_start: bool) -> float:
    """``options.initial_dt``, or its default for a model with or without a Newton start."""
    if options.initial_dt is not None:
        return options.initial_dt
    return 1.0 if newton_start else POLAR_INITIAL_DT


class SolverOptions(eqx.Module):
    """Settings of the equilibrium solver, taken by every solve: :func:`pacjax.solve_equilibrium`,
    :func:`pacjax.solve_batch`, :func:`pacjax.find_equilibria` (as ``options=`` or as keyword
    overrides of single fields), and :func:`pacjax.identify`, :func:`pacjax.inverse_statics`,
    :func:`pacjax.inverse_statics_batch`, :func:`pacjax.track`, :func:`pacjax.sample_workspace`
    (as ``options=``, for their equilibria). The fields are compile-time constants: changing one
    compiles the solver again.

    Args:
        tol: tolerance on the scaled residual (see :class:`pacjax.Equilibrium`); default None:
            1e-10 in float64, 1e-4 in float32 (:data:`DEFAULT_TOL`).
        max_steps: maximum continuation steps per escape attempt; default 100.
        initial_dt: first pseudo-time step, in units of the elastic relaxation time; default
            None: :data:`POLAR_INITIAL_DT` for PCC/PAC, 1 for strain coordinates. With strain
            coordinates (``PolynomialCurvature``) a conservative solve whose stiffness at the
            start is positive definite first takes Newton steps, and starts the continuation
            from ``initial_dt`` at the first step that is shortened or rejected
            (:meth:`pacjax.StrainModel.newton_from_start`).
        max_dt: largest pseudo-time step (Newton beyond it); default 1e12.
        escapes: how many times a converged saddle is left along its negative-curvature
            direction and continued again (0: report saddles as they are); default 2.
        escape_size: size of that perturbation (rad of curvature); default 0.05.
        stability_tol: threshold on the smallest scaled eigenvalue for ``stable``; default
            None: ``1e3`` times the machine epsilon of the solve's dtype.
        method: ``"ptc"`` (continuation, default) or ``"flow"`` (diffrax's integration of the
            flow, then continuation).
        flow_solver: diffrax solver of the flow method; default ``diffrax.Kvaerno5`` with
            :class:`pacjax._chord.DenseChord`.
        hessian: ``"structured"`` (default: per-segment forward derivatives of the kinematics,
            :mod:`pacjax._model.hessian`, plus the forward derivative of the follower loads alone
            in a non-conservative scene) or ``"autodiff"`` (``jax.jacfwd`` of the residual).
            Both are exact; they differ in cost.
    """

    tol: float | None = eqx.field(static=True, default=None)
    max_steps: int = eqx.field(static=True, default=100)
    initial_dt: float | None = eqx.field(static=True, default=None)
    max_dt: float = eqx.field(static=True, default=1e12)
    escapes: int = eqx.field(static=True, default=2)
    escape_size: float = eqx.field(static=True, default=0.05)
    stability_tol: float | None = eqx.field(static=True, default=None)
    method: str = eqx.field(static=True, default="ptc")
    flow_solver: diffrax.AbstractSolver = eqx.field(static=True, default=kvaerno5())
    hessian: str = eqx.field(static=True, default="structured")

    def __check_init__(self):
        if self.hessian not in ("structured", "autodiff"):
            raise ValueError(f"hessian must be 'structured' or 'autodiff', got {self.hessian!r}")
        if self.method not in ("ptc", "flow"):
            raise ValueError(f"method must be 'ptc' or 'flow', got {self.method!r}")
        for name in ("max_steps", "escapes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"{name} must be an integer, got {value!r}")
        for name in ("tol", "initial_dt", "max_dt", "escape_size", "stability_tol"):
            value = getattr(self, name)
            if value is None and name in ("tol", "initial_dt", "stability_tol"):
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
                raise TypeError(f"{name} must be a number, got {value!r}")
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.escapes < 0:
            raise ValueError(f"escapes must be >= 0, got {self.escapes}")
        if not isinstance(self.flow_solver, diffrax.AbstractSolver):
            raise TypeError(f"flow_solver must be a diffrax solver, got {self.flow_solver!r}")


def resolve_options(options: SolverOptions | None = None, dtype=None, **overrides) -> SolverOptions:
    """``options`` (default ``SolverOptions()``) with the fields in ``overrides``
    replaced, and, given the solve's ``dtype``, its default tolerance filled in. A name that
    is not a field raises a TypeError that lists the valid ones."""
    if options is None:
        options = SolverOptions()
    elif not isinstance(options, SolverOptions):
        raise TypeError(f"options must be a pacjax.SolverOptions, got {type(options).__name__}")
    if dtype is not None and options.tol is None and "tol" not in overrides:
        options = dataclasses.replace(options, tol=DEFAULT_TOL[np.dtype(dtype).name])
    if not overrides:
        return options
    fields = [f.name for f in dataclasses.fields(SolverOptions)]
    unknown = sorted(set(overrides) - set(fields))
    if unknown:
        names = ", ".join(unknown)
        raise TypeError(f"unknown solver option {names}; valid options: {', '.join(fields)}")
    return dataclasses.replace(options, **overrides)
