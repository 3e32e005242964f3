"""The fit's optimisers: Levenberg-Marquardt with a bounded step and a damping that follows the
gain ratio, or any optax gradient transformation, over the evaluations of the fitting problem."""

import numpy as np
import optax

from .._results import RESULTS


def optimise(train, theta, current, optimizer, max_iterations, tol, history, bounds, tracker):
    """Levenberg-Marquardt (or optax) iterations from ``theta`` within ``bounds = (lower,
    upper)`` of the internal coordinates (every iterate stays inside them exactly); each trial
    point's equilibria are warm-started from the current ones, and a trial on which a frame
    jumps to another branch (``tracker``, a :class:`BranchTracker`) is rejected. Returns the
    optimum, its evaluation and ``(iterations, result, message)``; ``history`` records every
    accepted step."""
    if isinstance(optimizer, str):
        return _levenberg_marquardt(
            train, theta, current, max_iterations, tol, history, bounds, tracker
        )
    return _optax_descent(
        train, theta, current, optimizer, max_iterations, tol, history, bounds, tracker
    )


class History:
    """Loss and training RMSE after every accepted iteration, and the progress bar."""

    def __init__(self, current, n_obs: int, markers, max_iterations: int, progress):
        from tqdm.auto import tqdm

        self.n_obs, self.markers = n_obs, markers
        self.losses = [current.cost() / n_obs]
        self.rmse = [_rmse_mm(current.pred, markers)]
        self.bar = tqdm(
            total=max_iterations,
            desc="identify",
            unit="it",
            disable=None if progress is None else not progress,
            leave=False,
        )

    def accept(self, current) -> None:
        """Record the evaluation of an accepted step."""
        self.losses.append(current.cost() / self.n_obs)
        self.rmse.append(_rmse_mm(current.pred, self.markers))
        self.bar.update()
        self.bar.set_postfix_str(f"RMSE {self.rmse[-1]:.3f} mm")

    def restart(self, current) -> None:
        """Record the evaluation after frames moved to other branches (not a step)."""
        self.losses.append(current.cost() / self.n_obs)
        self.rmse.append(_rmse_mm(current.pred, self.markers))


def _levenberg_marquardt(
    train, theta, current, max_iterations, tol, history: History, bounds, tracker
):
    """The Levenberg-Marquardt loop; returns ``(theta, evaluation, (iterations, result,
    message))``."""
    result, message = RESULTS.max_steps_reached, "iteration limit reached"
    iterations = 0
    lm = LevenbergMarquardt()
    while iterations < max_iterations:
        r, jac = current.stacked()
        step, predicted = lm.step(jac, r, theta, bounds)
        if predicted <= tol * current.cost():
            result, message = RESULTS.successful, "converged (no decrease left to gain)"
            break
        trial = train(theta + step, q0=current.q)
        ok = bool(np.all(trial.valid[current.valid]))
        jumped = tracker.jumped(current, trial, step) if ok else None
        ok = ok and not jumped.any()
        actual = current.cost() - trial.cost(current.valid) if ok else -np.inf
        if lm.update(actual / predicted, np.max(np.abs(step)), ok):
            decrease = actual / max(current.cost(), 1e-300)
            theta, current = theta + step, trial
            iterations += 1
            history.accept(current)
            if np.max(np.abs(step)) < np.sqrt(tol) or decrease < tol:
                result, message = (
                    RESULTS.successful,
                    "converged (step or loss change below tolerance)",
                )
                break
        elif lm.rejected >= LevenbergMarquardt.MAX_REJECTED:
            result, message = _rejected(ok, jumped)
            break
    return theta, current, (iterations, result, message)


def _rejected(ok: bool, jumped) -> tuple:
    """The result and message of a fit whose last trial steps were all rejected."""
    if ok:
        return (
            RESULTS.successful,
            "converged (no step reduces the loss further: at the solver's accuracy)",
        )
    if jumped is not None:
        return (
            RESULTS.branch_mismatch,
            f"stopped: frames {np.flatnonzero(jumped).tolist()} jump to another equilibrium "
            "branch along every trial step (the branch they follow ends at a fold)",
        )
    return RESULTS.no_equilibrium, "stopped: equilibria fail to converge along every trial step"


def _optax_descent(
    train, theta, current, optimizer, max_iterations, tol, history: History, bounds, tracker
):
    """An optax optimiser driven with the gradient ``J^T r``, each iterate projected onto the
    bounds; returns ``(theta, evaluation, (iterations, result, message))``."""
    result, message = RESULTS.max_steps_reached, "iteration limit reached"
    iterations = 0
    state = optimizer.init(theta)
    while iterations < max_iterations:
        r, jac = current.stacked()
        updates, state = optimizer.update(jac.T @ r, state, theta)
        new_theta = np.asarray(
            optax.projections.projection_box(optax.apply_updates(theta, updates), *bounds)
        )
        trial = train(new_theta, q0=current.q)
        if not np.all(trial.valid[current.valid]):
            result = RESULTS.no_equilibrium
            message = "stopped: a frame failed to converge along the optax path"
            break
        jumped = tracker.jumped(current, trial, new_theta - theta)
        if jumped.any():
            result = RESULTS.branch_mismatch
            message = (
                f"stopped: frames {np.flatnonzero(jumped).tolist()} jumped to another "
                "equilibrium branch along the optax path"
            )
            break
        previous = current.cost()
        theta, current = new_theta, trial
        iterations += 1
        history.accept(current)
        if abs(previous - current.cost()) < tol * max(previous, 1e-300):
            result, message = RESULTS.successful, "converged (loss change below tolerance)"
            break
    return theta, current, (iterations, result, message)


# ------------------------------------------------------------------------------ the report
class LevenbergMarquardt:
    """Damping and step bound of the fit's Levenberg-Marquardt iterations.

    The residuals come from a batch of equilibria, warm-started from the current ones, and a
    trial point whose equilibria fail is a rejected step, so the loop stays here rather than in
    ``optimistix``. Two safeguards keep a poor linear model from throwing the fit far out:

    - the damping follows the gain ratio ``rho`` (actual over predicted decrease; Nielsen's
      update, Madsen, Nielsen & Tingleff 2004, eq. 3.15): a step that lowers the loss but far
      less than predicted raises the damping instead of lowering it;
    - no internal coordinate moves by more than ``radius`` per step (log-scaled parameters by
      a factor ``e`` at most at the start). The radius halves on a rejected or poor step and
      doubles, up to :attr:`MAX_RADIUS`, on a good one.

    Without them the follower-force fit of the paper study took one step that raised
    ``tendon_gain`` 4-35x past the truth and ``stiffening`` 5x, from where every trial point
    had frames whose equilibria failed.
    """

    MAX_RADIUS = 4.0
    MAX_REJECTED = 8

    def __init__(self):
        self.damping, self.nu, self.radius, self.rejected = 1e-3, 2.0, 1.0, 0

    def step(self, jac, r, theta, bounds):
        """The damped Gauss-Newton step, cut back to the radius and projected onto the bounds,
        and its predicted decrease of ``0.5 |r|^2``.

        A coordinate at a bound that the gradient pushes outwards is held there (the step is
        solved in the others: the active set of a projected Gauss-Newton method); the step is
        then clipped so that ``theta + step`` stays inside the bounds exactly."""
        lower, upper = bounds
        jtj, g = jac.T @ jac, jac.T @ r
        diag = np.maximum(np.diag(jtj), 1e-12 * max(np.max(np.diag(jtj)), 1e-300))
        free = ~(((theta <= lower) & (g > 0)) | ((theta >= upper) & (g < 0)))
        step = np.zeros_like(theta)
        if free.any():
            system = (jtj + self.damping * np.diag(diag))[np.ix_(free, free)]
            step[free] = np.linalg.solve(system, -g[free])
        size = np.max(np.abs(step), initial=0.0)
        if size > self.radius:
            step = step * (self.radius / size)
        step = np.clip(theta + step, lower, upper) - theta
        return step, -(g @ step + 0.5 * step @ jtj @ step)

    def update(self, rho: float, size: float, ok: bool) -> bool:
        """Adapt to the gain ratio of the step just tried; True when it is accepted."""
        if ok and rho > 1e-3:
            self.damping = max(self.damping * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-12)
            self.nu, self.rejected = 2.0, 0
            if rho > 0.75:
                self.radius = min(max(self.radius, 2.0 * size), self.MAX_RADIUS)
            elif rho < 0.25:
                self.radius = 0.5 * size
            return True
        self.damping *= self.nu
        self.nu *= 2.0
        self.radius = 0.5 * size
        self.rejected += 1
        return False


def _rmse_mm(pred: np.ndarray, measured: np.ndarray) -> float:
    d = np.linalg.norm(pred - measured, axis=-1)
    return float(1e3 * np.sqrt(np.nanmean(d**2)))
