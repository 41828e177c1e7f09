"""Training the decoder and its latent codes (``fit``), codes for new data (``infer``),
and decoding codes back to motion (``reconstruct``).

Paper, *Main Results* and *Experimental Results*: the loss

.. math::  L(θ, z_1..z_n) = Σ_i ‖d(θ, z_i) − o_i‖²

is minimised over θ and the codes jointly ("train"), then over fresh codes with θ fixed
for new samples ("evaluation"). Here the loss is a weighted sum of per-element means,

.. math::  L = w_m · mean((m̂ − m)²) + w_v · mean((ŝ − s)²),

with ``m`` the motor sequence scaled per joint to [-1, 1] and ``s`` the frames in [0, 1]
(``uint8 / 255``). Means rather than the paper's sum, so that motor and vision weigh
equally at ``w_m = w_v = 1`` (a 48x64x3 frame has 1024 times as many values as a 9-joint
vector) and numbers do not depend on the batch size. ``fit`` and ``infer`` use the same
definition, so their curves compare.

Each code's gradient is that of its own sample's loss, whatever the batch: the batch
mean divides it by the batch size ``B``, so the table steps with ``B`` times the code
gradient of the batch loss. With θ frozen (``infer``) every code therefore receives
exactly the same updates for any batch size (up to floating-point summation order): a
large inference batch is only faster. (Before 0.2 the codes stepped on the batch-mean
gradient, so a code that fell in the short last batch of an epoch got a differently
scaled gradient; at 300 samples and batch 256 the final codes differed by 19-24%.)

A run directory (:mod:`primspace.rundir`, which owns its layout) holds the configs,
``metrics.jsonl`` (epoch 0 = the codes as initialised, before any update), the checkpoint
(written atomically after epoch 0, every ``checkpoint_seconds`` or ``checkpoint_every``
epochs, and at the end) and the codes.

``resume`` continues from the checkpoint bit-identically on the CPU.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import math
import os
import random
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from primspace.data import JointScaler, MotionDataset
from primspace.errors import DataError, UserError, config_from_dict
from primspace.files import atomic_path, atomic_write_json, atomic_write_text
from primspace.rundir import (
    CHECKPOINT_FORMAT,
    CHECKPOINT_NAME,
    CONFIG_NAME,
    LATENTS_INIT_NAME,
    LATENTS_NAME,
    METRICS_NAME,
    check_run_data,
    prepare_run_dir,
    read_checkpoint,
    read_config,
    read_metrics,
    run_config,
    save_npy,
    start_run_dir,
)
from primspace.latent import INIT_METHODS, LatentInitializer, LatentTable
from primspace.model import ModelConfig, MTRNNDecoder
from primspace.progress import progress_bar

__all__ = [
    "TrainConfig",
    "TrainedRun",
    "TrainingDivergedError",
    "fit",
    "infer",
    "load_run",
    "reconstruct",
    "evaluate",
    "read_indices",
    "check_run_data",
    "resolve_device",
    "configure_process",
]

# ----------------------------------------------------------------------------- config


@dataclass
class TrainConfig:
    """How to optimise (saved as JSON in a run's ``config.json``).

    Parameters
    ----------
    epochs : int
        Total epochs of the run (a resumed run trains up to this many).
    batch_size : int
        Samples per mini-batch. Every code is updated once per epoch; θ once per batch.
    lr : float
        Adam learning rate of the model weights θ.
    latent_lr : float
        Learning rate of the codes (row-wise Adam, :class:`primspace.latent.LatentTable`).
    final_lr_fraction : float
        Both learning rates follow a cosine from their value in the first epoch to this
        fraction of it in the last (1.0: constant). The factor depends only on the epoch
        index and ``epochs``, so a resumed run continues the same schedule (unless
        ``epochs`` is changed on resume, which stretches the rest of it).
    motor_weight, vision_weight : float
        ``w_m``, ``w_v`` of the loss (module docstring). ``vision_weight = 0`` skips the
        image head.
    seed : int
        Seeds the weights, ``P``, random codes and the batch order.
    device : str
        ``auto`` (CUDA when present, else CPU), ``cpu``, ``cuda`` or ``cuda:N``.
    amp : bool
        bfloat16 autocast on CUDA (LayerNorm and the loss stay float32).
    checkpoint_every : int, optional
        Also write the checkpoint every this many epochs.
    checkpoint_seconds : float
        Write the checkpoint when this long has passed since the last one. It is always
        written after epoch 0 (the initial state) and after the last epoch; a checkpoint
        costs ~10 ms for a small model, so tiny runs are not slowed by one per epoch.
    log_initial : bool
        Log epoch 0: the loss of the initial codes, before any update.
    threads : int, optional
        ``torch.set_num_threads`` for this process (None: leave as is).
    tune_malloc : bool
        On Linux/glibc CPU runs, keep freed memory in the heap (``mallopt``) so large
        activation buffers are reused instead of page-faulted in every batch (the image
        head ran 1.6x faster in a measurement; see docs/model.md). Process-wide.
    """

    epochs: int = 100
    batch_size: int = 32
    lr: float = 1e-3
    latent_lr: float = 1e-2
    final_lr_fraction: float = 1.0
    motor_weight: float = 1.0
    vision_weight: float = 1.0
    seed: int = 0
    device: str = "auto"
    amp: bool = False
    checkpoint_every: int | None = None
    checkpoint_seconds: float = 60.0
    log_initial: bool = True
    threads: int | None = None
    tune_malloc: bool = True

    def validate(self) -> "TrainConfig":
        if not isinstance(self.epochs, int) or self.epochs < 0:
            raise UserError(f"epochs must be a whole number >= 0, got {self.epochs}")
        if not isinstance(self.batch_size, int) or self.batch_size < 1:
            raise UserError(f"batch_size must be at least 1, got {self.batch_size}")
        for name in ("lr", "latent_lr"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise UserError(f"{name} must be a finite number >= 0, got {v}")
        f = self.final_lr_fraction
        if not (isinstance(f, (int, float)) and 0 < f <= 1):
            raise UserError(f"final_lr_fraction must be in (0, 1], got {f}")
        for name in ("motor_weight", "vision_weight"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise UserError(f"{name} must be a finite number >= 0, got {v}")
        if self.motor_weight == 0 and self.vision_weight == 0:
            raise UserError("motor_weight and vision_weight are both 0: nothing to train")
        if self.checkpoint_every is not None and (not isinstance(self.checkpoint_every, int) or self.checkpoint_every < 1):
            raise UserError(f"checkpoint_every must be at least 1, got {self.checkpoint_every}")
        if not (isinstance(self.checkpoint_seconds, (int, float)) and self.checkpoint_seconds >= 0):
            raise UserError(f"checkpoint_seconds must be a number >= 0, got {self.checkpoint_seconds}")
        if self.threads is not None and (not isinstance(self.threads, int) or self.threads < 1):
            raise UserError(f"threads must be at least 1, got {self.threads}")
        resolve_device(self.device, self.amp)
        return self

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        return config_from_dict(cls, d, "train config")


def lr_factor(epoch: int, epochs: int, final_fraction: float) -> float:
    """Cosine factor of the learning rates in epoch ``epoch`` (0-based) of ``epochs``: 1 → ``final_fraction``."""
    if final_fraction >= 1.0 or epochs <= 1:
        return 1.0
    progress = min(epoch, epochs - 1) / (epochs - 1)
    return final_fraction + (1.0 - final_fraction) * 0.5 * (1.0 + math.cos(math.pi * progress))


def resolve_device(device: str = "auto", amp: bool = False) -> torch.device:
    """``auto`` -> CUDA when available, else CPU. Raises :class:`UserError` for a device
    that is not there, or ``amp`` off CUDA."""
    name = str(device).strip().lower()
    if name == "auto":
        dev = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    else:
        try:
            dev = torch.device(name)
        except RuntimeError:
            raise UserError(f"unknown device '{device}'; use auto, cpu or cuda[:N]") from None
        if dev.type == "cuda":
            if not torch.cuda.is_available():
                raise UserError(f"device '{device}' asked for but CUDA is not available on this machine")
            if dev.index is not None and dev.index >= torch.cuda.device_count():
                raise UserError(f"device '{device}': only {torch.cuda.device_count()} CUDA device(s)")
        elif dev.type != "cpu":
            raise UserError(f"unsupported device '{device}'; use auto, cpu or cuda[:N]")
    if amp and dev.type != "cuda":
        raise UserError("mixed precision (amp) needs a CUDA device")
    return dev


class TrainingDivergedError(UserError):
    """The loss became NaN or infinite; the run directory keeps its last good checkpoint."""


# -------------------------------------------------------------------------------- run


@dataclass
class TrainedRun:
    """A run directory, loaded: the model, its codes and everything to use them.

    Attributes
    ----------
    run_dir : Path
    kind : {"fit", "infer"}
    init : str
        The latent initialisation of this run's codes.
    model : MTRNNDecoder
        On the CPU, in eval mode.
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
    """

    run_dir: Path
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

    @property
    def final_loss(self) -> float | None:
        """The last logged epoch's total loss."""
        return self.history[-1]["loss"] if self.history else None


# ------------------------------------------------------------------------- public API


def fit(
    dataset: MotionDataset,
    out_dir: str | os.PathLike,
    *,
    model_config: ModelConfig | None = None,
    train_config: TrainConfig | None = None,
    init: str = "projection",
    indices=None,
    resume: bool = False,
    overwrite: bool = False,
    weights_from: str | os.PathLike | None = None,
    initial_latents: np.ndarray | None = None,
    images: bool | None = None,
    scaler: JointScaler | None = None,
    progress: bool | None = None,
) -> TrainedRun:
    """Train the decoder's weights θ and one code per sample jointly (the paper's training).

    Parameters
    ----------
    dataset : MotionDataset
        Training data (motor in physical units; images optional).
    out_dir : path-like
        The run directory to create (or resume).
    model_config : ModelConfig, optional
        Sizes; J, T and the image size are filled in from ``dataset``. Default:
        ``ModelConfig()`` with an image head when the data has images (see ``images``).
    train_config : TrainConfig, optional
    init : {"zero", "random", "projection", "pca"}
        How the codes start (:class:`primspace.latent.LatentInitializer`).
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
    weights_from : path-like, optional
        A run directory: start from its θ, scaler and initialiser (its model config is
        used; a fresh optimiser). For incremental learning (the paper's inter-primitive
        experiment).
    initial_latents : ndarray (N, q), optional
        Starting codes, one row per selected sample; rows containing NaN use ``init``
        instead. E.g. replayed samples keep the codes they learned.
    images : bool, optional
        Give the model an image head and train it on the data's images. Default: when
        the data has images. (A ``model_config.image_size`` must match the data's.)
    scaler : JointScaler, optional
        A fitted joint scaler to use instead of one fitted on the training samples.
        The paper: "for each joint angle all the values in all sequences were
        normalized to be in [-1, 1] interval"; an experiment that fits on a part of its
        data passes a scaler fitted on every motion it uses, so the targets of every
        part lie in [-1, 1]. Not with ``weights_from`` (the parent's
        scaler is used). Recorded in config.json.
    progress : bool, optional
        Progress bar (default: when stderr is a terminal); False is silent.

    Returns
    -------
    TrainedRun

    Raises
    ------
    UserError
        Bad configuration or data, an existing ``out_dir`` without ``resume`` /
        ``overwrite``, a resume with an incompatible configuration.
    TrainingDivergedError
        The loss became NaN/inf (the last good checkpoint is kept).
    """
    out_dir = Path(out_dir)
    tc = (train_config or TrainConfig()).validate()
    if init not in INIT_METHODS:
        raise UserError(f"unknown latent init '{init}'; choose one of {', '.join(INIT_METHODS)}")
    data, idx = _select(dataset, indices)
    parent = load_run(weights_from) if weights_from is not None else None
    if scaler is not None:
        if parent is not None:
            raise UserError("give either weights_from (its scaler is used) or scaler, not both")
        if not isinstance(scaler, JointScaler) or scaler.data_min_ is None:
            raise UserError("scaler must be a fitted primspace.data.JointScaler")
        if scaler.n_joints != data.n_joints:
            raise UserError(f"scaler was fitted on {scaler.n_joints} joints, the data has {data.n_joints}")
    if parent is not None:
        mc = parent.model_config
        if model_config is not None:
            given = model_config.fitted_to(data, images=mc.has_images if images is None else images)
            if given.to_dict() != mc.to_dict():
                raise UserError(f"{weights_from}: model config differs from the one given; omit model_config")
        use_images = mc.has_images and data.has_images if images is None else images
        if use_images and not mc.has_images:
            raise UserError(f"{weights_from}: the model has no image head")
        _check_data_fits(data, mc, use_images)
    else:
        base = model_config or ModelConfig()
        mc = base.fitted_to(data, images=data.has_images if images is None else images)
        use_images = mc.has_images
    use_images = bool(use_images) and tc.vision_weight > 0
    if initial_latents is not None:
        initial_latents = np.asarray(initial_latents, dtype=np.float64)
        if initial_latents.shape != (len(data), mc.latent_dim):
            raise UserError(
                f"initial_latents must have shape ({len(data)}, {mc.latent_dim}), got {initial_latents.shape}"
            )
        if np.isinf(initial_latents).any():
            row = int(np.argwhere(np.isinf(initial_latents))[0, 0])
            raise UserError(f"initial_latents row {row} contains inf (use NaN rows for 'no initial code')")
    config = run_config(
        "fit", init, mc, tc, data, idx, use_images,
        parent=None if parent is None else str(parent.run_dir.resolve()),
    )
    config["scaler"] = None if scaler is None else scaler.to_dict()
    ckpt = prepare_run_dir(out_dir, config, resume, overwrite, inputs=(dataset.path, weights_from), epochs=tc.epochs)
    device = resolve_device(tc.device, tc.amp)
    seeds = _seeds(tc.seed)
    _set_threads(tc, device)

    if ckpt is not None:
        scaler = JointScaler.from_dict(ckpt["scaler"])
        initializer = LatentInitializer.from_state_dict(ckpt["initializer"])
        model = _new_model(mc, seeds["model"])
        model.load_state_dict(ckpt["model"])
    else:
        if parent is not None:
            scaler = parent.scaler
            model = _new_model(mc, seeds["model"])
            model.load_state_dict(parent.model.state_dict())
        else:
            if scaler is None:
                scaler = JointScaler().fit(data.motor)  # float64 extremes: restores bit-identically
            model = _new_model(mc, seeds["model"])
        scaled = scaler.transform(data.motor)
        if parent is not None and init == parent.init:
            initializer = parent.initializer
        else:
            initializer = LatentInitializer(init, mc.latent_dim, random_state=seeds["projection"]).fit(scaled)
    model.to(device)
    theta_opt = torch.optim.Adam(model.parameters(), lr=tc.lr)
    if ckpt is not None:
        table = LatentTable.from_state_dict(ckpt["latents"], device)
        theta_opt.load_state_dict(ckpt["theta_optimizer"])
    else:
        codes = initializer.transform(scaled, random_state=seeds["codes_fit"]).astype(np.float64)
        if initial_latents is not None:
            given = ~np.isnan(initial_latents).any(axis=1)
            codes[given] = initial_latents[given]
        table = LatentTable(torch.from_numpy(codes.astype(np.float32)).to(device), tc.latent_lr)

    session = _Session(
        out_dir=out_dir, config=config, model=model, theta_opt=theta_opt, table=table, scaler=scaler,
        initializer=initializer, data=data, use_images=use_images, tc=tc, device=device,
        shuffle_seed=seeds["shuffle"],
    )
    session.run(ckpt, progress, label="fit")
    return load_run(out_dir)


def infer(
    run_dir: str | os.PathLike,
    dataset: MotionDataset,
    out_dir: str | os.PathLike,
    *,
    epochs: int,
    init: str | None = None,
    indices=None,
    train_config: TrainConfig | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool | None = None,
    **overrides: Any,
) -> TrainedRun:
    """Find codes for new samples with the trained weights θ frozen (the paper's evaluation).

    Parameters
    ----------
    run_dir : path-like
        A trained run (its θ, scaler and initialiser are used).
    dataset : MotionDataset
        New samples with the same J and T (and image size, if it has images; without
        images only the motor loss is used).
    out_dir : path-like
        The new run directory (kind ``infer``); it holds its own copy of θ, so
        :func:`load_run` / :func:`reconstruct` work on it alone.
    epochs : int
    init : str, optional
        How the new codes start; default: the trained run's init. The same init reuses
        the run's initialiser (its ``P``); another one is fitted here (``pca`` on the new
        data, ``projection`` with a new ``P`` from ``seed``).
    indices : array-like of int, optional
        Samples of ``dataset`` to use.
    train_config : TrainConfig, optional
        Default: the trained run's, with ``epochs`` and ``overrides`` applied
        (e.g. ``latent_lr=...``, ``batch_size=...``, ``device=...``). ``lr`` is unused.
    resume, overwrite, progress
        As in :func:`fit`.

    Returns
    -------
    TrainedRun
    """
    parent = load_run(run_dir)
    out_dir = Path(out_dir)
    base = train_config or replace(parent.train_config, threads=None)
    try:
        tc = replace(base, epochs=epochs, **overrides).validate()
    except TypeError as exc:
        raise UserError(f"unknown train config override ({exc})") from None
    init = init or parent.init
    if init not in INIT_METHODS:
        raise UserError(f"unknown latent init '{init}'; choose one of {', '.join(INIT_METHODS)}")
    data, idx = _select(dataset, indices)
    mc = parent.model_config
    use_images = mc.has_images and data.has_images and tc.vision_weight > 0
    _check_data_fits(data, mc, use_images)
    config = run_config("infer", init, mc, tc, data, idx, use_images, parent=str(parent.run_dir.resolve()))
    ckpt = prepare_run_dir(out_dir, config, resume, overwrite, inputs=(dataset.path, run_dir), epochs=tc.epochs)
    device = resolve_device(tc.device, tc.amp)
    seeds = _seeds(tc.seed)
    _set_threads(tc, device)

    model = parent.model
    if ckpt is not None:
        model.load_state_dict(ckpt["model"])
        initializer = LatentInitializer.from_state_dict(ckpt["initializer"])
        table = LatentTable.from_state_dict(ckpt["latents"], device)
    else:
        scaled = parent.scaler.transform(data.motor)
        if init == parent.init:
            initializer = parent.initializer
        else:
            initializer = LatentInitializer(init, mc.latent_dim, random_state=seeds["projection"]).fit(scaled)
        codes = initializer.transform(scaled, random_state=seeds["codes_infer"])
        table = LatentTable(torch.from_numpy(codes).to(device), tc.latent_lr)
    model.to(device).requires_grad_(False)
    session = _Session(
        out_dir=out_dir, config=config, model=model, theta_opt=None, table=table, scaler=parent.scaler,
        initializer=initializer, data=data, use_images=use_images, tc=tc, device=device,
        shuffle_seed=seeds["shuffle"],
    )
    session.run(ckpt, progress, label="infer")
    return load_run(out_dir)


def load_run(run_dir: str | os.PathLike, *, map_location: str | torch.device = "cpu") -> TrainedRun:
    """Read a run directory written by :func:`fit` or :func:`infer`.

    Raises
    ------
    UserError
        If the directory is not a run or its files are unreadable.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UserError(f"{run_dir}: no such run directory")
    config = read_config(run_dir)
    ckpt = read_checkpoint(run_dir / CHECKPOINT_NAME, map_location)
    if ckpt is None:
        raise UserError(f"{run_dir}: has no {CHECKPOINT_NAME} (the run never completed an epoch)")
    try:
        mc = ModelConfig.from_dict(config["model"]).validate()
        tc = TrainConfig.from_dict(config["train"])
        model = MTRNNDecoder(mc)
        model.load_state_dict(ckpt["model"])
        model.eval()
        scaler = JointScaler.from_dict(ckpt["scaler"])
        initializer = LatentInitializer.from_state_dict(ckpt["initializer"])
        latents = ckpt["latents"]["codes"].numpy().astype(np.float32)
        initial = ckpt["initial_codes"].numpy().astype(np.float32)
        epoch = int(ckpt["epoch"])
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise UserError(f"{run_dir / CHECKPOINT_NAME}: not a primspace checkpoint ({str(exc).splitlines()[0]})") from None
    history = [h for h in read_metrics(run_dir / METRICS_NAME) if h["epoch"] <= epoch]
    data = config.get("data", {})
    return TrainedRun(
        run_dir=run_dir, kind=config["kind"], init=config["init"], model=model, model_config=mc,
        train_config=tc, scaler=scaler, initializer=initializer, latents=latents, initial_latents=initial,
        history=history, indices=np.asarray(data.get("indices", []), dtype=np.int64),
        data_path=data.get("path"), parent=config.get("parent"), epoch=epoch, config=config,
    )


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

    Returns
    -------
    motor : ndarray (n, T, J) float32
        Joint values in physical units (the run's scaler inverted).
    frames : ndarray (n, T, H, W, 3) uint8 or None
    """
    run = run if isinstance(run, TrainedRun) else load_run(run)
    z_all = run.latents if latents is None else np.asarray(latents, dtype=np.float32)
    q = run.model_config.latent_dim
    if z_all.ndim != 2 or z_all.shape[1] != q:
        raise UserError(f"latents must have shape (n, {q}), got {z_all.shape}")
    if not np.isfinite(z_all).all():
        raise UserError("latents contain NaN or inf")
    dev = resolve_device(device)
    model = run.model.to(dev).eval()
    want_images = images and model.image_head is not None
    motors, frames = [], []
    for start in range(0, len(z_all), batch_size):
        z = torch.from_numpy(np.ascontiguousarray(z_all[start : start + batch_size])).to(dev)
        out = model(z, images=want_images)
        motors.append(out.motor.float().cpu().numpy())
        if want_images:
            frames.append(out.images.float().mul(255).round_().clamp_(0, 255).to(torch.uint8).cpu().numpy())
    model.to("cpu")
    motor = run.scaler.inverse_transform(np.concatenate(motors, 0)).astype(np.float32)
    return motor, (np.concatenate(frames, 0) if want_images else None)


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
        ``loss``, ``motor``, ``vision`` (None without images).
    """
    run = run if isinstance(run, TrainedRun) else load_run(run)
    data, _ = _select(dataset, indices)
    z = run.latents if latents is None else np.asarray(latents, dtype=np.float32)
    if z.shape != (len(data), run.model_config.latent_dim):
        raise UserError(f"latents must have shape ({len(data)}, {run.model_config.latent_dim}), got {z.shape}")
    tc = replace(run.train_config, batch_size=batch_size, device=device, amp=False)
    use_images = run.model_config.has_images and data.has_images and tc.vision_weight > 0
    _check_data_fits(data, run.model_config, use_images)
    dev = resolve_device(device)
    model = run.model.to(dev).eval()
    tensors = _DataTensors.build(data, run.scaler, use_images, dev)
    table = LatentTable(torch.from_numpy(np.ascontiguousarray(z)).to(dev), 0.0)
    sums = _evaluate_loop(model, table, tensors, tc, dev)
    model.to("cpu")
    return _epoch_values(sums, len(data), use_images)


def read_indices(path: str | os.PathLike, dataset: MotionDataset | None = None) -> np.ndarray:
    """Sample indices from a ``.npy`` file or a text file (integers separated by
    whitespace or commas; ``#`` starts a comment); with ``dataset``, each must be one of
    its samples (the error names the index file and the data file)."""
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", path=path, field="indices")
    try:
        if path.suffix.lower() == ".npy":
            arr = np.load(path, allow_pickle=False)
        else:
            text = path.read_text(encoding="utf-8")
            tokens = [t for line in text.splitlines() for t in line.split("#", 1)[0].replace(",", " ").split()]
            arr = np.array([int(t) for t in tokens], dtype=np.int64)
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read sample indices ({str(exc).splitlines()[0]})", path=path, field="indices") from None
    arr = np.asarray(arr)
    if arr.ndim != 1 or arr.size == 0 or arr.dtype.kind not in "iu":
        raise DataError("must be a non-empty list of integers", path=path, field="indices")
    if len(np.unique(arr)) != arr.size:
        raise DataError("lists a sample more than once", path=path, field="indices")
    if dataset is not None:
        bad = arr[(arr < 0) | (arr >= len(dataset))]
        if bad.size:
            where = f" of {dataset.path}" if dataset.path is not None else ""
            raise DataError(f"sample {int(bad[0])} is out of range for the {len(dataset)} samples{where}",
                            path=path, field="indices")
    return arr.astype(np.int64)


# --------------------------------------------------------------------------- session


@dataclass
class _DataTensors:
    """Training targets on the device: scaled motor (float32) and frames (uint8, converted per batch)."""

    motor: torch.Tensor  # (N, T, J) float32, scaled to [-1, 1]
    images: torch.Tensor | None  # (N, T, H, W, 3) uint8

    @classmethod
    def build(cls, data: MotionDataset, scaler: JointScaler, use_images: bool, device) -> "_DataTensors":
        motor = torch.from_numpy(np.ascontiguousarray(scaler.transform(data.motor), dtype=np.float32)).to(device)
        images = None
        if use_images:
            loaded = data.load_images().images
            images = torch.from_numpy(np.ascontiguousarray(loaded)).to(device)
        return cls(motor, images)


def _batch_loss(model, z, idx, tensors: _DataTensors, tc: TrainConfig, autocast) -> tuple[torch.Tensor, torch.Tensor]:
    """The loss of one batch and the detached ``[loss, motor, vision]`` means."""
    use_images = tensors.images is not None
    with autocast:
        out = model(z, images=use_images)
    motor = F.mse_loss(out.motor.float(), tensors.motor.index_select(0, idx))
    if use_images:
        target = tensors.images.index_select(0, idx).to(torch.float32).div_(255.0)
        vision = F.mse_loss(out.images.float(), target)
        loss = tc.motor_weight * motor + tc.vision_weight * vision
    else:
        vision = torch.zeros((), device=motor.device)
        loss = tc.motor_weight * motor
    return loss, torch.stack([loss.detach(), motor.detach(), vision.detach()])


def _autocast(tc: TrainConfig, device: torch.device):
    if tc.amp and device.type == "cuda":
        return torch.autocast(device_type="cuda", dtype=torch.bfloat16)
    return contextlib.nullcontext()


def _evaluate_loop(model, table: LatentTable, tensors: _DataTensors, tc: TrainConfig, device) -> torch.Tensor:
    """Sums over samples of ``[loss, motor, vision]`` (no updates, samples in order)."""
    n = len(table)
    order = torch.arange(n, device=device)
    sums = torch.zeros(3, dtype=torch.float64, device=device)
    with torch.no_grad():
        for start in range(0, n, tc.batch_size):
            idx = order[start : start + tc.batch_size]
            z = table.codes.index_select(0, idx)
            _, parts = _batch_loss(model, z, idx, tensors, tc, _autocast(tc, device))
            sums += parts.double() * idx.numel()
    return sums


def _epoch_values(sums: torch.Tensor, n: int, use_images: bool) -> dict:
    loss, motor, vision = (sums / n).tolist()
    return {"loss": loss, "motor": motor, "vision": vision if use_images else None}


class _Session:
    """One run's training loop: θ (unless frozen) and the codes, checkpoints, metrics."""

    def __init__(
        self, *, out_dir: Path, config: dict, model: MTRNNDecoder, theta_opt, table: LatentTable,
        scaler: JointScaler, initializer: LatentInitializer, data: MotionDataset, use_images: bool,
        tc: TrainConfig, device: torch.device, shuffle_seed: int,
    ) -> None:
        self.out_dir, self.config, self.model, self.theta_opt = out_dir, config, model, theta_opt
        self.table, self.scaler, self.initializer, self.tc, self.device = table, scaler, initializer, tc, device
        if device.type == "cuda":
            torch.backends.cudnn.benchmark = True  # fixed shapes: let cuDNN pick the fastest kernels
        self.tensors = _DataTensors.build(data, scaler, use_images, device)
        self.use_images = use_images
        self.generator = torch.Generator().manual_seed(shuffle_seed)
        self.initial_codes = table.codes.detach().cpu().clone()
        self.epoch = 0
        self.n = len(table)

    # ------------------------------------------------------------------------ loop
    def run(self, ckpt: dict | None, progress: bool | None, label: str) -> None:
        tc = self.tc
        if ckpt is not None:
            self._restore(ckpt)
        else:
            start_run_dir(self.out_dir)
            atomic_write_json(self.out_dir / CONFIG_NAME, self.config)
            save_npy(self.out_dir / LATENTS_INIT_NAME, self.initial_codes.numpy())
            atomic_write_text(self.out_dir / METRICS_NAME, "")
            if tc.log_initial:
                t0 = time.perf_counter()
                self.model.eval()
                values = _epoch_values(_evaluate_loop(self.model, self.table, self.tensors, tc, self.device), self.n, self.use_images)
                self._log(0, values, time.perf_counter() - t0)
            self._checkpoint()
        if self.tc.tune_malloc and self.device.type == "cpu" and self.use_images:
            _tune_malloc()
        description = f"{label} {self.out_dir.name}"
        fields_fmt = "loss {task.fields[loss]:.4g}  {task.fields[sps]:.0f} samples/s"
        with progress_bar(tc.epochs, description, enabled=progress, fields=fields_fmt) as advance:
            if self.epoch:
                advance(self.epoch)
            while self.epoch < tc.epochs:
                t0 = time.perf_counter()
                sums = self._train_epoch()
                values = _epoch_values(sums, self.n, self.use_images)
                seconds = time.perf_counter() - t0
                bad = [k for k, v in values.items() if v is not None and not math.isfinite(v)]
                if bad:
                    what = "loss" if bad[0] == "loss" else f"{bad[0]} loss"
                    raise TrainingDivergedError(
                        f"{self.out_dir}: the {what} became {values[bad[0]]} in epoch {self.epoch + 1}; "
                        f"stopped, the last good checkpoint (epoch {self._last_checkpoint}) is kept "
                        f"(lower the learning rates, then resume)"
                    )
                self.epoch += 1
                self._log(self.epoch, values, seconds)
                due = tc.checkpoint_every is not None and self.epoch % tc.checkpoint_every == 0
                if due or self.epoch == tc.epochs or time.monotonic() - self._checkpoint_time >= tc.checkpoint_seconds:
                    self._checkpoint()
                advance(loss=values["loss"], sps=self.n / max(seconds, 1e-9))

    def _train_epoch(self) -> torch.Tensor:
        model, table, tc = self.model, self.table, self.tc
        train_theta = self.theta_opt is not None
        factor = lr_factor(self.epoch, tc.epochs, tc.final_lr_fraction)
        table.lr = tc.latent_lr * factor
        if train_theta:
            for group in self.theta_opt.param_groups:
                group["lr"] = tc.lr * factor
        model.train(train_theta)
        order = torch.randperm(self.n, generator=self.generator).to(self.device)
        sums = torch.zeros(3, dtype=torch.float64, device=self.device)
        autocast = _autocast(tc, self.device)
        for start in range(0, self.n, tc.batch_size):
            idx = order[start : start + tc.batch_size]
            z = table.batch(idx)
            loss, parts = _batch_loss(model, z, idx, self.tensors, tc, autocast)
            if train_theta:
                self.theta_opt.zero_grad(set_to_none=True)
            loss.backward()
            if train_theta:
                self.theta_opt.step()
            # the batch mean scaled z.grad by 1/B: undo it, so each code steps on the
            # gradient of its own sample's loss whatever the batch (module docstring)
            table.step(idx, z.grad.mul_(idx.numel()))
            sums += parts.double() * idx.numel()
        return sums

    def _log(self, epoch: int, values: dict, seconds: float) -> None:
        line = {"epoch": epoch, **values, "seconds": round(seconds, 6), "samples_per_s": round(self.n / max(seconds, 1e-9), 3)}
        with open(self.out_dir / METRICS_NAME, "a", encoding="utf-8") as f:
            f.write(json.dumps(line) + "\n")

    # ----------------------------------------------------------------- checkpoints
    def _checkpoint(self) -> None:
        state = {
            "format": CHECKPOINT_FORMAT,
            "kind": self.config["kind"],
            "epoch": self.epoch,
            "model": self.model.state_dict(),
            "theta_optimizer": None if self.theta_opt is None else self.theta_opt.state_dict(),
            "latents": self.table.state_dict(),
            "initial_codes": self.initial_codes,
            "scaler": self.scaler.to_dict(),
            "initializer": self.initializer.state_dict(),
            "rng": {
                "shuffle": self.generator.get_state(),
                "torch": torch.get_rng_state(),
                "python": random.getstate(),
                "numpy": _numpy_state(),
            },
            "config": self.config,
        }
        with atomic_path(self.out_dir / CHECKPOINT_NAME) as tmp:
            torch.save(state, tmp)
        save_npy(self.out_dir / LATENTS_NAME, self.table.numpy())
        self._last_checkpoint = self.epoch
        self._checkpoint_time = time.monotonic()

    def _restore(self, ckpt: dict) -> None:
        self.epoch = int(ckpt["epoch"])
        self._last_checkpoint = self.epoch
        self._checkpoint_time = time.monotonic()
        self.initial_codes = ckpt["initial_codes"]
        rng = ckpt["rng"]
        self.generator.set_state(rng["shuffle"])
        torch.set_rng_state(rng["torch"])
        random.setstate(_to_tuple(rng["python"]))
        _set_numpy_state(rng["numpy"])
        # metrics past the checkpoint (written before a kill) are dropped: they will be redone
        kept = [h for h in read_metrics(self.out_dir / METRICS_NAME) if h["epoch"] <= self.epoch]
        atomic_write_text(self.out_dir / METRICS_NAME, "".join(json.dumps(h) + "\n" for h in kept))


# --------------------------------------------------------------------------- helpers


def _select(dataset: MotionDataset, indices) -> tuple[MotionDataset, np.ndarray]:
    if not isinstance(dataset, MotionDataset):
        raise UserError(f"expected a MotionDataset, got {type(dataset).__name__}")
    if indices is None:
        return dataset, np.arange(len(dataset), dtype=np.int64)
    idx = np.asarray(indices)
    if idx.ndim != 1 or (idx.size and idx.dtype.kind not in "iu"):
        raise UserError("sample indices must be a 1-d list of integers")
    idx = idx.astype(np.int64)
    if len(np.unique(idx)) != idx.size:
        raise UserError("sample indices list a sample more than once")
    return dataset.subset(idx), idx


def _check_data_fits(data: MotionDataset, mc: ModelConfig, use_images: bool) -> None:
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


def _new_model(mc: ModelConfig, seed: int) -> MTRNNDecoder:
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return MTRNNDecoder(mc)


def _seeds(seed: int) -> dict:
    """Independent seeds for each use of randomness, all derived from ``seed``."""
    names = ("model", "projection", "codes_fit", "codes_infer", "shuffle")
    values = np.random.SeedSequence(int(seed)).generate_state(len(names), dtype=np.uint32)
    return {name: int(v) for name, v in zip(names, values)}


def configure_process(tc: TrainConfig) -> None:
    """Apply the process-wide settings of ``tc``: the torch CPU thread count
    (``threads``), glibc's heap thresholds on a CPU device (``tune_malloc``) and cuDNN's
    kernel autotuning on CUDA.

    The library never changes process-wide state itself: entry points call this (the
    ``primspace`` command's train / infer, an experiment's worker job) before training.
    """
    device = resolve_device(tc.device, tc.amp)
    if tc.threads is not None and torch.get_num_threads() != tc.threads:
        torch.set_num_threads(tc.threads)
    if device.type == "cuda":
        torch.backends.cudnn.benchmark = True  # fixed shapes: let cuDNN pick the fastest kernels
    elif tc.tune_malloc:
        _tune_malloc()


def _set_threads(tc: TrainConfig, device: torch.device) -> None:
    if tc.threads is not None and torch.get_num_threads() != tc.threads:
        torch.set_num_threads(tc.threads)


_MALLOC_TUNED = False


def _tune_malloc() -> None:
    """Raise glibc's mmap and trim thresholds so large freed buffers stay in the heap.

    glibc serves blocks above its (at most 32 MiB) mmap threshold with fresh ``mmap``
    calls and unmaps them on free; an image-head activation of a batch is ~100 MB, so
    every batch page-faulted it in again (measured: the head's forward+backward ran at
    ~48 instead of ~77 GFLOP/s). No-op off Linux/glibc.
    """
    global _MALLOC_TUNED
    if _MALLOC_TUNED or not sys.platform.startswith("linux"):
        return
    _MALLOC_TUNED = True
    try:
        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3
        libc.mallopt(m_mmap_threshold, 1 << 30)
        libc.mallopt(m_trim_threshold, (1 << 31) - 1)
    except (OSError, AttributeError):  # not glibc
        pass


def _numpy_state() -> dict:
    name, keys, pos, has_gauss, cached = np.random.get_state()
    return {"name": name, "keys": torch.from_numpy(keys.astype(np.int64)), "pos": int(pos),
            "has_gauss": int(has_gauss), "cached": float(cached)}


def _set_numpy_state(s: dict) -> None:
    np.random.set_state((s["name"], s["keys"].numpy().astype(np.uint32), s["pos"], s["has_gauss"], s["cached"]))


def _to_tuple(x):
    return tuple(_to_tuple(v) for v in x) if isinstance(x, (list, tuple)) else x
