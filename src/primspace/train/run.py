"""A trained or inferred run, in memory: :class:`TrainedRun` (what ``fit``, ``infer`` and
``load_run`` return, and what ``infer``, ``reconstruct``, ``evaluate`` and ``fit(weights_from=)``
accept)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from primspace.data import JointScaler
from primspace.model.calibration import CodeCalibration
from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.model.latent import LatentInitializer
from primspace.train.config import TrainConfig
from primspace.utils.errors import UserError

__all__ = ["TrainedRun", "require_run"]


@dataclass
class TrainedRun:
    """A run directory, loaded: the model, its codes and everything to use them.

    Attributes
    ----------
    run_dir : Path or None
        The run directory; None for a run held in memory only (``out_dir=None``).
    kind : {"fit", "infer"}
    init : str
        The latent initialisation of this run's codes.
    model : MTRNNDecoder
        On the CPU, in eval mode (the run's own copy: :func:`infer` never changes it).
    model_config : ModelConfig
    train_config : TrainConfig
    scaler : JointScaler
        Fitted on the training run's motor data; maps model output to physical units.
    initializer : LatentInitializer
        Fitted (holds ``P`` for ``projection``).
    latents : ndarray (N, q) float32
        The codes at the last checkpoint, one row per sample in ``indices`` order.
    initial_latents : ndarray (N, q) float32
        The codes as initialised.
    history : list of dict
        metrics.jsonl, one dict per epoch.
    indices : ndarray (N,) int64
        The samples of the data file the run used, in row order.
    data_path : str or None
        The data file (absolute path), if the data set came from one.
    parent : str or None
        ``fit``: the run whose weights it started from; ``infer``: the trained run.
    epoch : int
        Epochs completed at the last checkpoint.
    config : dict
        config.json as written.
    state : dict or None
        The final checkpoint of a run trained in memory (what
        :func:`primspace.train.rundir.write_run` saves); None for a run read from disk.
    calibration : CodeCalibration or None
        The map from the initialiser's codes to the fitted codes (``init="calibrated"``):
        fitted at the end of a ``fit`` whose initialiser is ``projection`` or ``pca``, carried
        by the runs inferred from it; None otherwise.

    Nothing a predictor prepares (decoded candidates, calibrations per observation rule) is
    kept here: the predictors of :mod:`primspace.predict` hold their own state.
    """

    run_dir: Path | None
    kind: str
    init: str
    model: MTRNNDecoder
    model_config: ModelConfig
    train_config: TrainConfig
    scaler: JointScaler
    initializer: LatentInitializer
    latents: np.ndarray
    initial_latents: np.ndarray
    history: list[dict]
    indices: np.ndarray
    data_path: str | None
    parent: str | None
    epoch: int
    config: dict = field(repr=False, default_factory=dict)
    state: dict | None = field(repr=False, default=None)
    calibration: CodeCalibration | None = field(repr=False, default=None)

    @property
    def finished(self) -> bool:
        """Whether the run trained every epoch its config asks for (a run stopped early, by
        Ctrl-C or a kill, has not: ``epoch < train_config.epochs``)."""
        return self.epoch >= self.train_config.epochs

    @property
    def final_loss(self) -> float | None:
        """The last logged epoch's total loss."""
        return self.history[-1]["loss"] if self.history else None


def require_run(run) -> TrainedRun:
    """``run`` when it is a :class:`TrainedRun`, or one UserError: the functions inside a prediction or a
    training take the run resolved (a run directory is read once, at the entry points:
    :func:`~primspace.train.as_run`)."""
    if not isinstance(run, TrainedRun):
        raise UserError(
            f"expected a TrainedRun (read a run directory with primspace.train.load_run), got {type(run).__name__}"
        )
    return run
