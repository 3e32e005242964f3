"""Which equilibrium branch each frame of a fit is on, and keeping it on the data's.

A loaded soft robot can have several stable equilibria under one command (a tentacle hanging
or curled into a loop). A fit evaluates each frame at the equilibrium reached from the previous
iterate's, so it follows one branch; two things can go wrong:

- a step takes a frame over a fold, where its branch ends, and the warm-started solve lands on
  another branch: the frame's markers move far more than the step's linearisation says. Such a
  step is rejected (the optimiser shrinks it), never accepted as a decrease of the loss;
- the branch followed is not the one the data were recorded on (the fit started on another, or
  the data's branch did not exist at the starting values). Only other equilibria can tell: the
  frames are solved again from scattered starts (one batch, the same compiled solver) and a frame
  whose markers another stable equilibrium fits clearly better is moved to it. The fit checks
  at its start and whenever it stops, and resumes after a move; it reports success only when
  its last check moved nothing.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._model.scene import Scene
from .._statics.multistart import random_starts

#: A frame has jumped when its markers move further from the step's linear prediction than the
#: predicted motion itself plus this fraction of the robot's length.
JUMP_FLOOR = 0.02
#: Another equilibrium is the data's branch when its marker RMSE is below this fraction of the
#: tracked one's and lower by at least ``MARGIN_NOISE`` times the noise scale.
BETTER_FRACTION = 0.8
MARGIN_NOISE = 3.0
#: Half-width (rad per segment) of the scattered starts' strain coordinates: wide enough to
#: reach a loop curled through more than a turn.
SPREAD = 1.5 * np.pi


@dataclasses.dataclass
class Branches:
    """The equilibrium branch of every training frame, as the fit's checks found it.

    Attributes:
        starts: scattered starts each check solved every frame from (0: no checks).
        switched: (frames,) True for a frame moved during the fit to another equilibrium
            that fits its markers better than the one it was on.
        off_branch: (frames,) True for a frame whose markers another equilibrium still fits
            better at the end (the fit ran out of rounds; its result says so).
        alternatives: (frames,) distinct other stable equilibria found at the last check.
        jumps: steps rejected because a frame jumped to another branch.
    """

    starts: int
    switched: np.ndarray
    off_branch: np.ndarray
    alternatives: np.ndarray
    jumps: int = 0

    def summary(self) -> dict:
        return {
            "starts": self.starts,
            "frames_switched": np.flatnonzero(self.switched).tolist(),
            "frames_off_branch": np.flatnonzero(self.off_branch).tolist(),
            "alternatives": np.asarray(self.alternatives).tolist(),
            "rejected_jumps": self.jumps,
        }


class BranchTracker:
    """Jump detection along the fit's steps and the checks against the data's branches."""

    def __init__(self, scene: Scene, markers: np.ndarray, noise: float, starts: int, seed: int):
        """``markers``: (frames, m, 3) the training data (mocap frame); ``starts``: scattered
        starts per check (0: no checks, jump detection only)."""
        self.markers = markers
        self.noise = float(noise)
        # The robot's length summed on the host: `Robot.total_length` adds JAX scalars, one
        # more small compilation in every new process.
        self.floor = JUMP_FLOOR * sum(float(seg.length) for seg in scene.robot.segments)
        self.starts = (
            random_starts(scene, starts, seed, SPREAD, False) if starts else np.zeros((0,))
        )
        n = markers.shape[0]
        self.branches = Branches(
            len(self.starts), np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, int)
        )

    def jumped(self, current, trial, step: np.ndarray) -> np.ndarray:
        """(frames,) True where ``trial``'s markers left ``current``'s branch along ``step``."""
        linear = np.einsum("fmkp,p->fmk", current.dpred, step)
        n = len(linear)
        both = current.valid[:n] & trial.valid[:n]
        actual = trial.pred - current.pred
        off = np.linalg.norm(actual - linear, axis=-1).max(-1)
        jump = both & (off > np.linalg.norm(linear, axis=-1).max(-1) + self.floor)
        self.branches.jumps += int(jump.any())
        return jump

    def check(self, train, theta, current):
        """Solve every frame from the scattered starts at ``theta``; move each frame whose
        markers another stable equilibrium fits clearly better to it. Returns the evaluation
        (re-evaluated when a frame moved) and the (frames,) mask of moved frames."""
        n = self.markers.shape[0]
        moved = np.zeros(n, bool)
        if not len(self.starts):
            return current, moved
        best_q = current.q.copy()
        best = self._rmse(current)
        found = [np.where(current.valid[:n, None, None], current.pred, np.nan)]
        for other in train.from_starts(theta, self.starts):
            err = self._rmse(other)
            better = (err < BETTER_FRACTION * best) & (err < best - MARGIN_NOISE * self.noise)
            best_q[:n][better], best[better] = other.q[:n][better], err[better]
            moved |= better
            found.append(np.where(other.valid[:n, None, None], other.pred, np.nan))
        self.branches.alternatives = self._distinct(found) - 1
        if moved.any():
            current = train(theta, q0=best_q)
            self.branches.switched |= moved
        return current, moved

    def _rmse(self, evaluation) -> np.ndarray:
        """(frames,) marker RMSE (m) of each frame's equilibrium; inf where it failed."""
        n = self.markers.shape[0]
        d2 = np.sum((evaluation.pred - self.markers) ** 2, -1)
        with np.errstate(invalid="ignore"):
            rmse = np.sqrt(np.nanmean(np.where(np.isfinite(d2), d2, np.nan), -1))
        return np.where(evaluation.valid[:n] & np.isfinite(rmse), rmse, np.inf)

    def _distinct(self, found: list) -> np.ndarray:
        """(frames,) distinct equilibria among the solutions found (markers further apart than
        the jump floor)."""
        preds = np.stack(found, 1)  # (frames, starts + 1, m, 3)
        counts = np.zeros(preds.shape[0], int)
        for f, rows in enumerate(preds):
            kept: list[np.ndarray] = []
            for p in rows:
                if not np.all(np.isfinite(p)):
                    continue
                if all(np.linalg.norm(p - k, axis=-1).max() > self.floor for k in kept):
                    kept.append(p)
            counts[f] = max(len(kept), 1)
        return counts
