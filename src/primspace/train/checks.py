"""Checks of the arguments of :func:`primspace.train.fit` and :func:`primspace.train.infer`:
each refuses bad input with one :class:`~primspace.utils.errors.UserError` line."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from primspace.data import JointScaler, MotionDataset
from primspace.data.indices import check_indices
from primspace.model.config import ModelConfig
from primspace.model.latent import CALIBRATABLE, CALIBRATED, START_METHODS
from primspace.train.run import TrainedRun
from primspace.utils.errors import UserError

__all__ = [
    "check_init",
    "check_calibrated",
    "check_scaler",
    "fit_model_config",
    "check_precision_learned",
    "check_initial_latents",
    "select",
    "check_data_fits",
    "run_name",
]


def check_init(init: str, starts: tuple[str, ...] = START_METHODS) -> None:
    """Refuse a start that is not one of ``starts`` (``fit``: :data:`~primspace.model.latent.START_METHODS`;
    ``infer`` adds ``nearest``)."""
    if init not in starts:
        raise UserError(f"unknown latent init '{init}'; choose one of {', '.join(starts)}")


def check_calibrated(init: str, parent: TrainedRun | None) -> None:
    """Refuse ``calibrated`` without a trained run that has a calibration map, in one line."""
    if init != CALIBRATED:
        return
    if parent is None:
        raise UserError(
            "init 'calibrated' starts from a trained run's calibration map: use it to infer codes "
            "with a run fitted with projection or pca init (or with weights_from such a run)"
        )
    if parent.calibration is not None:
        return
    method = parent.initializer.method
    if method in CALIBRATABLE and parent.kind == "fit":
        raise UserError(
            f"{run_name(parent)}: has no calibration map (fitted by primspace < 0.5); "
            "resume its fit once (same epochs) to add it"
        )
    raise UserError(
        f"{run_name(parent)}: init 'calibrated' needs a run fitted with projection or pca init; "
        f"this run's codes start from '{method}'"
    )


def check_scaler(scaler, parent: TrainedRun | None, data: MotionDataset) -> None:
    if scaler is None:
        return
    if parent is not None:
        raise UserError("give either weights_from (its scaler is used) or scaler, not both")
    if not isinstance(scaler, JointScaler) or scaler.data_min_ is None:
        raise UserError("scaler must be a fitted primspace.data.JointScaler")
    if scaler.n_joints != data.n_joints:
        raise UserError(f"scaler was fitted on {scaler.n_joints} joints, the data has {data.n_joints}")


def fit_model_config(model_config, parent: TrainedRun | None, data: MotionDataset, images) -> ModelConfig:
    """The model config of a fit: the parent's (a given one must agree), or the given one fitted to the data.
    ``learned_precision`` is not compared: the fit sets it from its train config."""
    if parent is None:
        return (model_config or ModelConfig()).fitted_to(data, images=data.has_images if images is None else images)
    mc = parent.model_config
    if model_config is not None:
        given = model_config.fitted_to(data, images=mc.has_images if images is None else images)
        if replace(given, learned_precision=mc.learned_precision).to_dict() != mc.to_dict():
            raise UserError(f"{run_name(parent)}: model config differs from the one given; omit model_config")
    return mc


def check_precision_learned(tc, parent: TrainedRun) -> None:
    """Refuse inferring under ``loss_reduction="precision"`` with a run whose decoder has no learned precisions."""
    if tc.loss_reduction == "precision" and not parent.model_config.learned_precision:
        raise UserError(
            f"{run_name(parent)}: loss_reduction 'precision' weighs the senses by the learned precisions "
            f"of a run fitted with it; this one was fitted with {parent.train_config.loss_reduction!r}"
        )


def check_initial_latents(initial_latents, n: int, q: int) -> np.ndarray | None:
    if initial_latents is None:
        return None
    initial_latents = np.asarray(initial_latents, dtype=np.float64)
    if initial_latents.shape != (n, q):
        raise UserError(f"initial_latents must have shape ({n}, {q}), got {initial_latents.shape}")
    if np.isinf(initial_latents).any():
        row = int(np.argwhere(np.isinf(initial_latents))[0, 0])
        raise UserError(f"initial_latents row {row} contains inf (use NaN rows for 'no initial code')")
    return initial_latents


def select(dataset: MotionDataset, indices) -> tuple[MotionDataset, np.ndarray]:
    if not isinstance(dataset, MotionDataset):
        raise UserError(f"expected a MotionDataset, got {type(dataset).__name__}")
    if indices is None:
        return dataset, np.arange(len(dataset), dtype=np.int64)
    idx = check_indices(indices, len(dataset))
    return dataset.subset(idx), idx


def check_data_fits(data: MotionDataset, mc: ModelConfig, use_images: bool) -> None:
    where = str(data.path) if data.path is not None else "the data set"
    if data.n_joints != mc.n_joints or data.length != mc.length:
        raise UserError(
            f"{where}: has T={data.length} steps x J={data.n_joints} joints, the model expects "
            f"T={mc.length} x J={mc.n_joints}"
        )
    if use_images:
        if not data.has_images:
            raise UserError(f"{where}: has no images")
        if tuple(data.image_size) != tuple(mc.image_size):
            h, w = data.image_size
            raise UserError(f"{where}: images are {h}x{w}, the model predicts {mc.image_size[0]}x{mc.image_size[1]}")


def run_name(run: TrainedRun) -> str:
    return str(run.run_dir) if run.run_dir is not None else "the given run"


def check_something_to_train(tc, use_images: bool) -> None:
    """Refuse a run whose loss is identically 0: no motor weight and no vision trained
    (``motor_weight=0`` on data without images, or with images turned off)."""
    if tc.motor_weight == 0 and not use_images:
        raise UserError(
            "motor_weight is 0 and no vision loss is trained (no images, images off, or vision_weight 0): "
            "the loss would be 0 at every step; give motor_weight > 0 or train with images"
        )
