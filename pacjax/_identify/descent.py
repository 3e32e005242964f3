"""One descent of a fit on the data's equilibrium branches, and the starting points of several.

A descent alternates the optimiser (:func:`pacjax._identify.optimise.optimise`) with the branch
checks of :class:`pacjax._identify.branches.BranchTracker`: a check at the start, and one after
every optimiser run that stops short of its iteration limit; a check that moves frames starts
another run. ``fit`` is the set-up of :func:`pacjax.identify` (its problem, training frames,
noise, observation count and bounds).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._results import RESULTS
from .branches import Branches, BranchTracker
from .evaluation import Evaluator
from .optimise import History, optimise

#: Descents after which frames still moving to better-fitting branches end a fit.
MAX_ROUNDS = 4


@dataclasses.dataclass(frozen=True)
class DescentSettings:
    """How one descent runs."""

    optimizer: object
    max_iterations: int
    tol: float
    progress: bool | None
    branch_starts: int
    seed: int


@dataclasses.dataclass
class Descent:
    """One descent: its optimum, evaluation, history, stop and the frames' branches."""

    theta: np.ndarray
    current: object
    history: History
    stop: tuple  # (iterations, result, message)
    branches: Branches

    @property
    def successful(self) -> bool:
        return bool(self.stop[1] == RESULTS.successful)


def starting_points(fit, n_starts: int, seed: int) -> list[np.ndarray]:
    """The internal coordinates of each start: the given values, then random factors within
    x1/4..x4 on every positive parameter (clipped to the bounds)."""
    rng = np.random.default_rng(seed)
    log = np.concatenate([np.full(b.size, b.log) for b in fit.problem.blocks])
    points = [np.zeros(fit.problem.n_theta)]
    for _ in range(n_starts - 1):
        theta = np.where(log, rng.uniform(-np.log(4.0), np.log(4.0), log.size), 0.0)
        points.append(np.clip(theta, *fit.bounds))
    return points


def descend(fit, train: Evaluator, theta, current, settings: DescentSettings) -> Descent:
    """Optimiser descents from ``theta`` on the data's branches: a branch check first, and
    after every descent that stops short of the iteration limit; a check that moves frames
    starts another descent."""
    n = fit.dataset.n_frames
    tracker = BranchTracker(
        fit.problem.scene, fit.dataset.markers, fit.noise, settings.branch_starts, settings.seed
    )
    history = History(
        current,
        fit.n_observations,
        fit.dataset.markers,
        settings.max_iterations,
        settings.progress,
    )
    current, moved = tracker.check(train, theta, current)
    if moved.any():
        history.restart(current)
    iterations = 0
    for _ in range(MAX_ROUNDS):
        theta, current, (its, result, message) = optimise(
            train,
            theta,
            current,
            settings.optimizer,
            settings.max_iterations - iterations,
            settings.tol,
            history,
            fit.bounds,
            tracker,
        )
        iterations += its
        if bool(result == RESULTS.max_steps_reached):
            break
        current, moved = tracker.check(train, theta, current)
        if not moved.any():
            break
        history.restart(current)
    else:
        tracker.branches.off_branch = moved[:n]
        result = RESULTS.branch_mismatch
        message = (
            f"stopped: frames {np.flatnonzero(moved).tolist()} still fit better on another "
            f"equilibrium branch after {MAX_ROUNDS} descents"
        )
    history.bar.close()
    return Descent(theta, current, history, (iterations, result, message), tracker.branches)


def run_summary(run: Descent, n_obs: int) -> dict:
    iterations, _, message = run.stop
    return {
        "loss": run.current.cost() / n_obs,
        "rmse_mm": run.history.rmse[-1],
        "iterations": iterations,
        "message": message,
    }
