"""The report of an identification: parameter estimates, uncertainties, errors, history."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from .. import _deprecated
from .._results import RESULTS
from .branches import Branches


@dataclasses.dataclass
class FitErrors:
    """Prediction errors of a fitted model on a set of frames (mocap frame, fitted transform).

    Attributes:
        frame_rmse_mm: (frames,) RMS marker distance error per frame (mm; NaN for a frame
            whose equilibrium did not converge).
        marker_rmse_mm: (m,) RMS distance error per marker (mm).
        rmse_mm, mean_mm, max_mm: over every observed marker of every converged frame (mm).
        tip_error_mm: (frames,) distance error of the most distal marker (mm; NaN if unseen
            or not converged).
        orientation_error_deg: (frames, m) angle between predicted and measured rotation
            (degrees), or None without orientation data.
        tip_frobenius: (frames,) ``||R_pred - R_meas||_F`` at the most distal site, or None.
        predicted, measured: (frames, m, 3) marker positions (m).
        converged: (frames,) whether each frame's equilibrium converged.
        q: (frames, n_dofs) the model's equilibria.
    """

    frame_rmse_mm: np.ndarray
    marker_rmse_mm: np.ndarray
    rmse_mm: float
    mean_mm: float
    max_mm: float
    tip_error_mm: np.ndarray
    orientation_error_deg: np.ndarray | None
    tip_frobenius: np.ndarray | None
    predicted: np.ndarray
    measured: np.ndarray
    converged: np.ndarray
    q: np.ndarray

    @staticmethod
    def compute(predicted, measured, tip_index, converged, q, rot_pred=None, rot_meas=None):
        dist = np.linalg.norm(predicted - measured, axis=-1) * 1e3  # NaN where unobserved
        # A frame whose equilibrium failed has no prediction (its markers are those of the
        # start): it is counted in ``converged``, not mixed into the errors.
        dist = np.where(np.asarray(converged, bool)[:, None], dist, np.nan)
        seen = np.isfinite(dist)
        sq = np.where(seen, dist**2, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            frame = np.sqrt(sq.sum(1) / seen.sum(1))
            marker = np.sqrt(sq.sum(0) / seen.sum(0))
        ori = frob = None
        if rot_pred is not None and rot_meas is not None:
            rel = np.einsum("fmji,fmjk->fmik", rot_pred, rot_meas)
            cos = np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
            ori = np.degrees(np.arccos(cos))
            frob = np.linalg.norm(rot_pred[:, tip_index] - rot_meas[:, tip_index], axis=(-2, -1))
            ok = np.asarray(converged, bool)
            ori, frob = np.where(ok[:, None], ori, np.nan), np.where(ok, frob, np.nan)
        any_seen = bool(seen.any())  # False when no frame converged
        return FitErrors(
            frame_rmse_mm=frame,
            marker_rmse_mm=marker,
            rmse_mm=float(np.sqrt(sq.sum() / seen.sum())) if any_seen else np.nan,
            mean_mm=float(np.nanmean(dist)) if any_seen else np.nan,
            max_mm=float(np.nanmax(dist)) if any_seen else np.nan,
            tip_error_mm=dist[:, tip_index],
            orientation_error_deg=ori,
            tip_frobenius=frob,
            predicted=predicted,
            measured=measured,
            converged=np.asarray(converged, bool),
            q=np.asarray(q),
        )

    def summary(self) -> dict:
        out = {
            "frames": int(len(self.frame_rmse_mm)),
            "rmse_mm": _scalar(self.rmse_mm),
            "mean_mm": _scalar(self.mean_mm),
            "max_mm": _scalar(self.max_mm),
            "tip_mean_mm": _nanmean(self.tip_error_mm),
            "frame_rmse_mm": _list(self.frame_rmse_mm),
            "marker_rmse_mm": _list(self.marker_rmse_mm),
            "tip_error_mm": _list(self.tip_error_mm),
            "frames_not_converged": np.flatnonzero(~self.converged).tolist(),
        }
        if self.orientation_error_deg is not None:
            out["orientation_mean_deg"] = _nanmean(self.orientation_error_deg)
            out["tip_frobenius_mean"] = _nanmean(self.tip_frobenius)
        return out


def _scalar(x) -> float | None:
    return float(x) if math.isfinite(x) else None


def _nanmean(x) -> float | None:
    x = np.asarray(x, float)
    return float(np.nanmean(x)) if np.isfinite(x).any() else None


def _list(x) -> list:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(x, float).reshape(-1)]


@dataclasses.dataclass
class IdentificationReport:
    """What :func:`pacjax.identify` found.

    Attributes:
        parameters: name -> ``{"unit", "labels", "initial", "value", "std", "relative_std",
            "at_bound"}`` (lists, one entry per fitted value; ``std`` from the Gauss-Newton /
            Laplace covariance ``s^2 (J^T J)^-1``, ``s^2`` the residual variance per
            observation; ``at_bound`` "lower", "upper" or None).
        loss_history: normalised loss ``sum(rho(r)) / n_observations`` after every accepted
            iteration (the first entry is the start), residuals in units of ``noise``.
        rmse_history_mm: training marker RMSE (mm) along the same iterations.
        train, validation: :class:`FitErrors` (validation None without held-out frames).
        rotation, translation: the mocap transform ``x_mocap = rotation @ x_world + translation``.
        iterations, evaluations: accepted steps, batch equilibrium evaluations.
        result: a :class:`pacjax.RESULTS` item: ``successful`` when a stopping tolerance was
            met, ``max_steps_reached`` at the iteration limit, ``no_equilibrium`` when frames
            stopped converging along the steps.
        message: why the fit stopped, in words.
        covariance: covariance of the internal coordinates (log-parameters, offsets); NaN
            rows and columns for coordinates the data do not see.
        coordinate_names: names of those coordinates.
        identifiable: False for a coordinate the data do not see (no effect on the markers,
            alone or in a combination with others: its ``std`` is None, never 0) or whose
            relative standard deviation exceeds 1.
        time_s: wall time of the fit; first_evaluation_s: the first batch evaluation,
            compilation included.
        noise: the residual scale (m) used.
        branches: the equilibrium branch of each training frame (:class:`pacjax.Branches`):
            frames moved to a branch that fits them better, frames still off the data's
            branch, alternatives found, steps rejected for a jump.
        starts: with ``n_starts > 1``, one summary per descent (final loss, RMSE, iterations,
            message); the report is the best one's. None otherwise.
        stages: with ``stages``, one summary per stage (its parameters, final loss, RMSE,
            iterations, message); the report is the last stage's, its histories span all.
    """

    parameters: dict
    loss_history: list
    rmse_history_mm: list
    train: FitErrors
    validation: FitErrors | None
    rotation: np.ndarray
    translation: np.ndarray
    iterations: int
    evaluations: int
    result: RESULTS
    message: str
    covariance: np.ndarray
    coordinate_names: list
    identifiable: list
    time_s: float
    first_evaluation_s: float
    noise: float
    branches: Branches | None = None
    starts: list | None = None
    stages: list | None = None

    @property
    def correlations(self) -> np.ndarray:
        """Correlation matrix of the internal coordinates (NaN where not identified)."""
        cov = np.asarray(self.covariance, float)
        std = np.sqrt(np.diag(cov))
        with np.errstate(invalid="ignore", divide="ignore"):
            return cov / np.outer(std, std)

    def strong_correlations(self, threshold: float = 0.9) -> list[tuple[str, str, float]]:
        """Pairs of coordinates whose correlation exceeds ``threshold`` in magnitude: the data
        constrain their combination better than each of them."""
        corr, names = self.correlations, self.coordinate_names
        return [
            (names[i], names[j], float(corr[i, j]))
            for i in range(len(names))
            for j in range(i + 1, len(names))
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > threshold
        ]

    @property
    def successful(self) -> bool:
        """``result == RESULTS.successful``: a stopping tolerance was met."""
        return bool(self.result == RESULTS.successful)

    @property
    def converged(self) -> bool:
        """Deprecated: use :attr:`successful`."""
        _deprecated.warn("IdentificationReport.converged", "IdentificationReport.successful")
        return self.successful

    def to_dict(self) -> dict:
        return {
            "parameters": self.parameters,
            "loss_history": [float(v) for v in self.loss_history],
            "rmse_history_mm": [float(v) for v in self.rmse_history_mm],
            "train": self.train.summary(),
            "validation": None if self.validation is None else self.validation.summary(),
            "mocap_transform": {
                "rotation": np.asarray(self.rotation).tolist(),
                "translation_m": np.asarray(self.translation).tolist(),
            },
            "iterations": self.iterations,
            "evaluations": self.evaluations,
            "converged": self.successful,
            "message": self.message,
            "coordinate_names": list(self.coordinate_names),
            "identifiable": [bool(v) for v in self.identifiable],
            "covariance": [_list(row) for row in np.asarray(self.covariance, float)],
            "time_s": self.time_s,
            "first_evaluation_s": self.first_evaluation_s,
            "noise_m": self.noise,
            "branches": None if self.branches is None else self.branches.summary(),
            "starts": self.starts,
            "stages": self.stages,
        }

    def to_json(self, path) -> None:
        with open(path, "w", encoding="utf-8") as f:
            json.dump(self.to_dict(), f, indent=2)
            f.write("\n")

    def to_markdown(self) -> str:
        lines = ["# Identification report", ""]
        lines.append(
            f"{self.message}; {self.iterations} iterations, {self.evaluations} batch evaluations, "
            f"{self.time_s:.1f} s (first evaluation, with compilation, "
            f"{self.first_evaluation_s:.1f} s)."
        )
        lines += [
            "",
            "## Parameters",
            "",
            "| parameter | unit | initial | fitted | std | rel. std |",
        ]
        lines.append("|---|---|---|---|---|---|")
        bounded = []
        for name, p in self.parameters.items():
            bounds = p.get("at_bound", [None] * len(p["labels"]))
            for label, a, b, s, r, at in zip(
                p["labels"],
                p["initial"],
                p["value"],
                p["std"],
                p["relative_std"],
                bounds,
                strict=True,
            ):
                rel = "-" if r is None else f"{100 * r:.2g} %"
                std = "-" if s is None else f"{s:.4g}"
                mark = "" if at is None else f" (at its {at} bound)"
                lines.append(
                    f"| {name}{label} | {p['unit']} | {a:.6g} | {b:.6g}{mark} | {std} | {rel} |"
                )
                if at is not None:
                    bounded.append(f"{name}{label}")
        if bounded:
            lines += [
                "",
                f"At a bound (the data push past it; its std is not a confidence): "
                f"{', '.join(bounded)}.",
            ]
        if not all(self.identifiable):
            bad = [
                n for n, ok in zip(self.coordinate_names, self.identifiable, strict=True) if not ok
            ]
            lines += [
                "",
                "Not identified by these data (no effect on the markers, alone or together "
                f"with others, or relative std > 100 %): {', '.join(bad)}.",
            ]
        strong = self.strong_correlations()
        if strong:
            pairs = ", ".join(f"{a} & {b} ({r:+.2f})" for a, b, r in strong)
            lines += ["", f"Strongly correlated (|r| > 0.9): {pairs}."]
        lines += self._branch_lines()
        lines += ["", "## Errors (mm; markers in the mocap frame)", ""]
        lines.append(
            "| frames | n | not converged | RMSE | mean | max | tip mean | orientation mean (deg) |"
        )
        lines.append("|---|---|---|---|---|---|---|---|")
        for label, e in (("train", self.train), ("held-out", self.validation)):
            if e is None:
                continue
            s = e.summary()
            ori = s.get("orientation_mean_deg")
            lines.append(
                f"| {label} | {s['frames']} | {len(s['frames_not_converged'])} | "
                f"{_fmt(s['rmse_mm'])} | {_fmt(s['mean_mm'])} | {_fmt(s['max_mm'])} | "
                f"{_fmt(s['tip_mean_mm'])} | {_fmt(ori)} |"
            )
        lines += [
            "",
            "Per-marker RMSE (mm), train: " + ", ".join(_fmt(v) for v in self.train.marker_rmse_mm),
        ]
        if self.validation is not None:
            lines.append(
                "Per-marker RMSE (mm), held-out: "
                + ", ".join(_fmt(v) for v in self.validation.marker_rmse_mm)
            )
        for title, runs in (("Starts", self.starts), ("Stages", self.stages)):
            if runs:
                lines += ["", f"## {title}", ""]
                for k, run in enumerate(runs):
                    params = f" ({', '.join(run['params'])})" if "params" in run else ""
                    lines.append(
                        f"- {k}{params}: loss {run['loss']:.6g}, RMSE {run['rmse_mm']:.3f} mm, "
                        f"{run['iterations']} iterations; {run['message']}"
                    )
        lines += ["", "## Loss history", "", "iteration, loss, train RMSE (mm):", ""]
        for k, (loss, rmse) in enumerate(zip(self.loss_history, self.rmse_history_mm, strict=True)):
            lines.append(f"- {k}: {loss:.6g}, {rmse:.4f}")
        return "\n".join(lines) + "\n"

    def _branch_lines(self) -> list[str]:
        b = self.branches
        if b is None:
            return []
        if not b.starts:
            text = "not checked (branch_starts=0)"
        else:
            text = (
                f"each frame solved again from {b.starts} scattered starts at the start and "
                f"end of every descent; {int(np.sum(b.alternatives > 0))} frame(s) have "
                "another stable equilibrium"
            )
        lines = ["", "## Equilibrium branches", "", text + "."]
        if b.switched.any():
            lines.append(
                f"Moved to a branch that fits the data better: frames "
                f"{np.flatnonzero(b.switched).tolist()}."
            )
        if b.off_branch.any():
            lines.append(
                f"Still better fitted on another branch at the end: frames "
                f"{np.flatnonzero(b.off_branch).tolist()}."
            )
        if b.jumps:
            lines.append(f"{b.jumps} step(s) rejected: a frame jumped to another branch.")
        return lines


def _fmt(v) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{v:.3f}"
