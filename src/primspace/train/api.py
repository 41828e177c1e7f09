"""The training functions: :func:`fit` (θ and the codes, the paper's training),
:func:`infer` (codes only, θ frozen, the paper's evaluation), :func:`reconstruct` (codes
to motion) and :func:`evaluate` (the loss of given codes).

Each accepts what the others return (a :class:`TrainedRun`) or a run directory, and runs
in memory unless given an ``out_dir``. None of them changes process-wide settings
(:func:`primspace.train.config.configure_process` does, called by entry points) or the
caller's model: ``TrainConfig.threads`` limits torch's and BLAS's threads while ``fit`` or
``infer`` trains and is put back after (:func:`~primspace.train.config.thread_limit`).
"""

from __future__ import annotations

import contextlib
import copy
import os
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from primspace.data import JointScaler, MotionDataset
from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.model.latent import LatentTable
from primspace.train.checks import select
from primspace.train.config import TrainConfig, resolve_device
from primspace.train.loop import epoch_values, evaluate_loop, opened_stream
from primspace.train.loss import DataTensors
from primspace.train.run import TrainedRun
from primspace.train.sessions import (
    FitRequest,
    InferRequest,
    as_run,
    fit_session,
    infer_session,
    run_session,
    uses_images,
)
from primspace.utils.errors import UserError

__all__ = [
    "fit",
    "infer",
    "reconstruct",
    "decode_keypoints",
    "evaluate",
    "uses_images",
    "as_run",
]


def fit(
    dataset: MotionDataset,
    out_dir: str | os.PathLike | None = None,
    *,
    model_config: ModelConfig | None = None,
    train_config: TrainConfig | None = None,
    init: str = "projection",
    indices=None,
    resume: bool = False,
    overwrite: bool = False,
    weights_from: TrainedRun | str | os.PathLike | None = None,
    initial_latents: np.ndarray | None = None,
    images: bool | None = None,
    scaler: JointScaler | None = None,
    progress: bool | None = None,
    log_to: tuple | None = None,
) -> TrainedRun:
    """Train the decoder's weights θ and one code per sample jointly (the paper's training).

    Parameters
    ----------
    dataset : MotionDataset
        Training data (motor in physical units; images optional).
    out_dir : path-like, optional
        The run directory to create (or resume). None: train in memory, write nothing
        (the returned run can be saved later with :func:`primspace.train.rundir.write_run`).
    model_config : ModelConfig, optional
        Sizes; J, T and the image size are filled in from ``dataset``. Default:
        ``ModelConfig()`` with an image head when the data has images (see ``images``).
    train_config : TrainConfig, optional
        Its ``stream_frames`` reads the frames from the file batch by batch; under a
        started ``torch.distributed`` group the processes train one model (docs/scale.md).
    init : {"zero", "random", "projection", "pca", "calibrated"}
        How the codes start (:class:`primspace.model.latent.LatentInitializer`); ``calibrated``
        (with ``weights_from`` only): the parent's initialiser, its codes mapped by the
        parent's calibration (:class:`primspace.model.calibration.CodeCalibration`). A fit whose
        initialiser is ``projection`` or ``pca`` ends by fitting its own calibration map
        (``TrainedRun.calibration``; diagnostics in ``calibration.json``).
    indices : array-like of int, optional
        Samples of ``dataset`` to train on (recorded in config.json). Default: all.
    resume : bool
        Continue the run in ``out_dir`` from its checkpoint (up to ``train_config.epochs``
        in total); starts afresh if there is no checkpoint yet. The configs must match
        the saved ones (only ``epochs``, ``checkpoint_every``, ``threads`` may change).
        ``epochs`` below the checkpoint's is refused; above it extends the run (with a
        cosine schedule, ``final_lr_fraction < 1``, the rest of the decay is stretched
        to the new length: not the numbers of a run started with that many epochs).
    overwrite : bool
        Replace an earlier run of the same kind in ``out_dir``: only the files a run
        writes are replaced, anything else in the directory stays. Not with ``resume``.
        ``out_dir`` may not be, contain or lie inside the data file or ``weights_from``.
    weights_from : TrainedRun or path-like, optional
        A run (or its directory): start from its θ, scaler and initialiser (its model config is
        used; a fresh optimiser). For incremental learning (the paper's inter-primitive
        experiment).
    initial_latents : ndarray (N, q), optional
        Starting codes, one row per selected sample; rows containing NaN use ``init``
        instead. E.g. replayed samples keep the codes they learned.
    images : bool, optional
        Give the model an image head and train it on the data's images. Default: when
        the data has images. (A ``model_config.image_size`` must match the data's.) Whether
        the vision loss is trained then follows one rule, :func:`uses_images`.
    scaler : JointScaler, optional
        A fitted joint scaler to use instead of one fitted on the training samples.
        The paper: "for each joint angle all the values in all sequences were
        normalized to be in [-1, 1] interval"; an experiment that fits on a part of its
        data passes a scaler fitted on every motion it uses, so the targets of every
        part lie in [-1, 1]. Not with ``weights_from`` (the parent's
        scaler is used). Recorded in config.json.
    progress : bool, optional
        Progress bar (default: when stderr is a terminal); False is silent.
    log_to : ("tensorboard", path-like), optional
        Also write each epoch's metrics (``metrics.jsonl``'s) as TensorBoard event files
        into that folder (:mod:`primspace.train.logger`; ``pip install 'primspace[tensorboard]'``).

    Returns
    -------
    TrainedRun

    Raises
    ------
    UserError
        Bad configuration or data, an existing ``out_dir`` without ``resume=True`` /
        ``overwrite=True``, a resume with an incompatible configuration.
    TrainingDivergedError
        The loss became NaN/inf (the last good checkpoint is kept).
    """
    args = dict(locals())  # a FitRequest of every argument but progress
    progress = args.pop("progress")
    session, ckpt = fit_session(FitRequest(**args))
    return run_session(session, ckpt, progress, "fit")


def infer(
    run: TrainedRun | str | os.PathLike,
    dataset: MotionDataset,
    out_dir: str | os.PathLike | None = None,
    *,
    epochs: int,
    init: str | None = None,
    indices=None,
    train_config: TrainConfig | None = None,
    initial_latents: np.ndarray | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool | None = None,
    observe=None,
    observe_frames=None,
    fitted_data: MotionDataset | None = None,
    log_to: tuple | None = None,
    **overrides: Any,
) -> TrainedRun:
    """Find codes for new samples with the trained weights θ frozen (the paper's evaluation).

    Parameters
    ----------
    run : TrainedRun or path-like
        A trained run or its directory (its θ, scaler and initialiser are used; the run
        itself is not changed).
    dataset : MotionDataset
        New samples with the same J and T (and image size, if it has images; without
        images only the motor loss is used).
    out_dir : path-like, optional
        The new run directory (kind ``infer``); it holds its own copy of θ, so
        :func:`load_run` / :func:`reconstruct` work on it alone. None: in memory.
    epochs : int
    init : str, optional
        How the new codes start; default: the trained run's init. The same init reuses
        the run's initialiser (its ``P``); another one is fitted here (``pca`` on the new
        data, ``projection`` with a new ``P`` from ``seed``). ``calibrated``: the run's
        initialiser, its codes mapped by the run's calibration (``B P m + c``, ridge from
        the training samples' initial to fitted codes; runs fitted with ``projection`` or
        ``pca`` init have one, :mod:`primspace.model.calibration`). ``nearest``: the fitted code
        of the fitted demonstration whose motor is nearest (over the observed steps).
    indices : array-like of int, optional
        Samples of ``dataset`` to use.
    train_config : TrainConfig, optional
        Default: the trained run's with the default ``threads``, ``epochs`` and ``overrides``
        applied (e.g. ``latent_lr=...``, ``batch_size=...``, ``device=...``). ``lr`` is unused.
    initial_latents : ndarray (N, q), optional
        Starting codes, one row per selected sample; rows containing NaN start by
        ``init`` (e.g. to try another start with the same weights).
    resume, overwrite, progress, log_to
        As in :func:`fit` (``log_to``: the inference's metrics).
    observe : float, int or "none", optional
        Infer from a prefix of each motion (:mod:`primspace.train.observe`): a fraction in
        (0, 1] of each sample's valid steps (rounded up, at least one), a number of steps,
        or ``"none"`` (no joints: frames only; start by ``zero``, ``random`` or ``calibrated``,
        the last from the observed frames, :mod:`primspace.train.frames_start`). The loss
        counts the observed entries only and the starts read the observed part. None: every step.
    observe_frames : float, int, "first" or "none", optional
        The same for the frames (default: as ``observe``); ``"first"``: the first frame.
    fitted_data : MotionDataset, optional
        The data set ``run`` was fitted on, for the starts that read its demonstrations
        (``nearest``; ``calibrated`` under ``observe``). Default: the run's data file.

    Returns
    -------
    TrainedRun
    """
    args = dict(locals())  # an InferRequest of every argument but progress
    progress = args.pop("progress")
    session, ckpt = infer_session(InferRequest(**args))
    return run_session(session, ckpt, progress, "infer")


@torch.no_grad()
def reconstruct(
    run: TrainedRun | str | os.PathLike,
    latents: np.ndarray | None = None,
    *,
    images: bool = True,
    batch_size: int = 64,
    device: str = "cpu",
) -> tuple[np.ndarray, np.ndarray | None]:
    """Decode codes into motion: ``d(θ, z)`` in physical units.

    Parameters
    ----------
    run : TrainedRun or path-like
    latents : ndarray (n, q), optional
        Codes to decode (default: the run's own codes).
    images : bool
        Also decode frames (if the model has an image head).
    batch_size : int
    device : str
        Where to decode; the run's model is copied there if it lives elsewhere (the
        caller's model is never moved).

    Returns
    -------
    motor : ndarray (n, T, J) float32
        Joint values in physical units (the run's scaler inverted).
    frames : ndarray (n, T, H, W, 3) uint8 or None
    """
    run = as_run(run)
    z_all = _codes(run, latents)
    dev = resolve_device(device)
    motors, frames = [], []
    with _eval_model(run.model, dev) as model:
        want_images = images and model.image_head is not None
        for start in range(0, len(z_all), batch_size):
            z = torch.from_numpy(np.ascontiguousarray(z_all[start : start + batch_size])).to(dev)
            out = model(z, images=want_images)
            motors.append(out.motor.float().cpu().numpy())
            if want_images:
                frames.append(out.images.float().mul(255).round_().clamp_(0, 255).to(torch.uint8).cpu().numpy())
    motor = run.scaler.inverse_transform(np.concatenate(motors, 0)).astype(np.float32)
    return motor, (np.concatenate(frames, 0) if want_images else None)


def _codes(run: TrainedRun, latents: np.ndarray | None) -> np.ndarray:
    """The codes to decode: ``latents`` checked (shape, finite), or the run's own."""
    z_all = run.latents if latents is None else np.asarray(latents, dtype=np.float32)
    q = run.model_config.code_size
    if z_all.ndim != 2 or z_all.shape[1] != q:
        raise UserError(f"latents must have shape (n, {q}), got {z_all.shape}")
    if not np.isfinite(z_all).all():
        raise UserError("latents contain NaN or inf")
    return z_all


@torch.no_grad()
def decode_keypoints(
    run: TrainedRun | str | os.PathLike,
    latents: np.ndarray | None = None,
    *,
    batch_size: int = 64,
    device: str = "cpu",
) -> np.ndarray | None:
    """The keypoints the decoder predicts for codes (``ModelConfig.keypoints``): the points
    its frames are drawn through, ``(n, T, K, 2)`` float32 ``(x, y)`` in [-1, 1] (``x`` from
    the left edge, ``y`` from the top), or None for a model without keypoints. ``latents``,
    ``batch_size`` and ``device`` as in :func:`reconstruct`."""
    run = as_run(run)
    z_all = _codes(run, latents)
    if not run.model_config.keypoints:
        return None
    dev = resolve_device(device)
    points = []
    with _eval_model(run.model, dev) as model:
        for start in range(0, len(z_all), batch_size):
            z = torch.from_numpy(np.ascontiguousarray(z_all[start : start + batch_size])).to(dev)
            points.append(model(z, images=False).keypoints.float().cpu().numpy())
    return np.concatenate(points, 0).astype(np.float32)


@torch.no_grad()
def evaluate(
    run: TrainedRun | str | os.PathLike,
    dataset: MotionDataset,
    latents: np.ndarray | None = None,
    *,
    indices=None,
    batch_size: int = 64,
    device: str = "cpu",
) -> dict:
    """The loss (as logged in metrics.jsonl) of codes on a data set, without training.

    Parameters
    ----------
    run : TrainedRun or path-like
    dataset : MotionDataset
    latents : ndarray (n, q), optional
        Default: the run's codes (then ``dataset`` / ``indices`` must select its samples).
    indices : array-like of int, optional

    Returns
    -------
    dict
        ``loss`` (the objective of the run's ``TrainConfig.loss_reduction``, every frame),
        ``motor``, ``vision`` (per-element mean squared errors under either reduction;
        ``vision`` None without images).
    """
    run = as_run(run)
    data, _ = select(dataset, indices)
    z = run.latents if latents is None else np.asarray(latents, dtype=np.float32)
    if z.shape != (len(data), run.model_config.code_size):
        raise UserError(f"latents must have shape ({len(data)}, {run.model_config.code_size}), got {z.shape}")
    tc = replace(run.train_config, batch_size=batch_size, device=device, amp=False)
    use_images = uses_images(run.model_config, data, tc)
    dev = resolve_device(device)
    table = LatentTable(torch.from_numpy(np.ascontiguousarray(z)).to(dev), 0.0)
    with opened_stream(tc, data, use_images, dev) as stream, _eval_model(run.model, dev) as model:
        tensors = DataTensors.build(data, run.scaler, use_images, dev, stream=stream is not None)
        sums = evaluate_loop(model, table, tensors, tc, dev, stream=stream)
    return epoch_values(sums, len(data), use_images)


# --------------------------------------------------------------------------- helpers


@contextlib.contextmanager
def _eval_model(model: MTRNNDecoder, device: torch.device):
    """The model in eval mode on ``device``: itself if it is there (its mode restored
    after), else a copy, so the caller's model is never moved."""
    on = next(model.parameters()).device
    if on != device:
        yield copy.deepcopy(model).to(device).eval()
        return
    was_training = model.training
    model.eval()
    try:
        yield model
    finally:
        model.train(was_training)
