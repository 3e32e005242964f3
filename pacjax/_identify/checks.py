"""The checks of :func:`pacjax.identify`'s inputs, before anything is solved: the data against
the scene (control columns, marker sites, tensions), enough variation to separate the
parameters, and the fit's settings, each a one-line error that names what is wrong."""

from __future__ import annotations

import numpy as np
import optax

from .._model.inputs import check_scene
from .._model.scene import Scene
from .._model.sites import normalise_sites
from .dataset import MocapDataset


def _check_dataset(scene: Scene, dataset: MocapDataset, name: str) -> None:
    if not isinstance(dataset, MocapDataset):
        raise TypeError(f"{name} must be a pacjax.MocapDataset, got {type(dataset).__name__}")
    if dataset.n_controls != scene.n_tendons:
        raise ValueError(
            f"{name} has {dataset.n_controls} control column(s) but the scene has "
            f"{scene.n_tendons} tendon(s)"
        )
    normalise_sites(dataset.sites, scene.n_segments, f"{name}.sites")
    for i, t in enumerate(scene.tendons):
        if t.mode == "tension" and np.any(dataset.controls[:, i] < 0):
            raise ValueError(f"{name}.controls[:, {i}] are tensions and must be >= 0")


def _check_variation(dataset: MocapDataset) -> None:
    if dataset.n_frames < 2:
        return
    cond = dataset.conditions()
    if np.all(cond == cond[0]):
        raise ValueError(
            "every training frame has the same controls and loads (no variation): the data "
            "cannot separate the parameters; record poses under different commands or payloads"
        )
    m = dataset.markers
    spread = np.nanmax(np.nanmax(m, 0) - np.nanmin(m, 0))
    if spread == 0.0:
        raise ValueError(
            "the markers are identical in every frame although the controls change: the marker "
            "columns look frozen or mismatched"
        )


def check_data(
    scene: Scene, dataset: MocapDataset, validation: MocapDataset | None, holdout: float, seed: int
) -> tuple[MocapDataset, MocapDataset | None]:
    """The checked training and held-out frames (``holdout``: split off ``dataset``)."""
    check_scene(scene)
    _check_dataset(scene, dataset, "dataset")
    chosen = np.iterable(holdout) and not isinstance(holdout, (str, bytes))
    if validation is not None and (chosen or holdout):
        raise ValueError("give either validation= or holdout=, not both")
    if validation is None and not (chosen or holdout) and dataset.holdout is not None:
        if dataset.holdout.any():
            holdout, chosen = np.flatnonzero(dataset.holdout).tolist(), True
    if chosen or holdout:
        dataset, validation = dataset.split(holdout, seed)
    if validation is not None:
        _check_dataset(scene, validation, "validation")
        if validation.sites != dataset.sites:
            raise ValueError("validation must have the same marker sites as dataset")
    _check_variation(dataset)
    return dataset, validation


def check_settings(loss, noise, orientation_noise, huber_delta, max_iterations, optimizer) -> None:
    """Raise for a loss, a noise scale, an iteration limit or an optimiser ``identify`` lacks."""
    if loss not in ("l2", "huber"):
        raise ValueError(f"loss must be 'l2' or 'huber', got {loss!r}")
    if not noise > 0 or not orientation_noise > 0 or not huber_delta > 0:
        raise ValueError("noise, orientation_noise and huber_delta must be > 0")
    if max_iterations < 0:
        raise ValueError(f"max_iterations must be >= 0, got {max_iterations}")
    lm = isinstance(optimizer, str)
    if lm and optimizer != "levenberg-marquardt":
        raise ValueError(
            f"optimizer must be 'levenberg-marquardt' or an optax optimiser, got {optimizer!r}"
        )
    if not lm and not isinstance(optimizer, optax.GradientTransformation):
        raise TypeError(
            "optimizer must be 'levenberg-marquardt' or an optax.GradientTransformation"
        )
