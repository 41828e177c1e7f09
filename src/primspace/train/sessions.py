"""The sessions behind :func:`~primspace.train.api.fit` and :func:`~primspace.train.api.infer`:
each builds a :class:`~primspace.train.loop.Session` (model, optimiser, codes, run directory)
without running it (:func:`fit_session`, :func:`infer_session`), so that one session runs
alone (:func:`run_session`) or several run packed on one device
(:func:`primspace.train.packed.train_packed`); and the rules they share (:func:`uses_images`,
:func:`as_run`).
"""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from primspace.data import JointScaler, MotionDataset
from primspace.model.calibration import CodeCalibration
from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.model.latent import CALIBRATABLE, INFER_STARTS, LatentInitializer, LatentTable
from primspace.train.checkpoint import unpack_checkpoint
from primspace.train.checks import (
    check_calibrated,
    check_data_fits,
    check_init,
    check_initial_latents,
    check_precision_learned,
    check_scaler,
    check_something_to_train,
    fit_model_config,
    run_name,
    select,
)
from primspace.train.config import TrainConfig, resolve_device, thread_limit
from primspace.train.distributed import current_world
from primspace.train.logger import check_log_to
from primspace.train.loop import Session
from primspace.train.observe import Observation, observation_record
from primspace.train.run import TrainedRun
from primspace.train.rundir import load_run, open_run_dir, run_config, run_from_state
from primspace.train.starts import derived_seeds, inference_start, initial_codes, run_initializer
from primspace.utils.errors import UserError

__all__ = [
    "FitRequest",
    "InferRequest",
    "fit_session",
    "infer_session",
    "run_session",
    "theta_optimizer",
    "uses_images",
    "learns_precision",
    "as_run",
]


@dataclass(frozen=True)
class FitRequest:
    """The arguments of :func:`~primspace.train.api.fit` (its docstring gives each), as one value."""

    dataset: MotionDataset
    out_dir: str | os.PathLike | None = None
    model_config: ModelConfig | None = None
    train_config: TrainConfig | None = None
    init: str = "projection"
    indices: Any = None
    resume: bool = False
    overwrite: bool = False
    weights_from: TrainedRun | str | os.PathLike | None = None
    initial_latents: np.ndarray | None = None
    images: bool | None = None
    scaler: JointScaler | None = None
    log_to: tuple | None = None


@dataclass(frozen=True)
class InferRequest:
    """The arguments of :func:`~primspace.train.api.infer` (its docstring gives each), as one value;
    ``overrides`` the train-config overrides."""

    run: TrainedRun | str | os.PathLike
    dataset: MotionDataset
    out_dir: str | os.PathLike | None = None
    epochs: int | None = None
    init: str | None = None
    indices: Any = None
    train_config: TrainConfig | None = None
    initial_latents: np.ndarray | None = None
    resume: bool = False
    overwrite: bool = False
    observe: Any = None
    observe_frames: Any = None
    fitted_data: MotionDataset | None = None
    log_to: tuple | None = None
    overrides: dict = field(default_factory=dict)


def _request(cls, args: tuple, kwargs: dict):
    """A request of ``cls``: the one given, or built of the arguments (unknown keywords: ``overrides``
    where the request has them)."""
    if len(args) == 1 and not kwargs and isinstance(args[0], cls):
        return args[0]
    names = {f.name for f in fields(cls)}
    extra = {k: v for k, v in kwargs.items() if k not in names}
    if extra and "overrides" in names:
        kwargs = {k: v for k, v in kwargs.items() if k in names} | {
            "overrides": {**kwargs.get("overrides", {}), **extra}
        }
    try:
        return cls(*args, **kwargs)
    except TypeError as exc:
        raise UserError(f"{cls.__name__}: {exc}") from None


def fit_session(*args, **kwargs) -> tuple[Session, dict | None]:
    """The :class:`~primspace.train.loop.Session` that :func:`fit` runs (a :class:`FitRequest`, or its
    fields as arguments), not yet run, and the checkpoint it resumes from (None: from the start);
    :func:`run_session` runs it, :func:`primspace.train.packed.train_packed` runs several together.
    A ``weights_from`` directory is read here (the one place for ``fit`` and packed jobs)."""
    request = _request(FitRequest, args, kwargs)
    dataset, out_dir, model_config = request.dataset, request.out_dir, request.model_config
    init, indices, resume, overwrite = request.init, request.indices, request.resume, request.overwrite
    weights_from, initial_latents, images = request.weights_from, request.initial_latents, request.images
    scaler, log_to, train_config = request.scaler, request.log_to, request.train_config
    tc = (train_config or TrainConfig()).validate()
    check_init(init)
    data, _ = select(dataset, indices)
    parent = None if weights_from is None else as_run(weights_from)
    check_calibrated(init, parent)
    check_scaler(scaler, parent, data)
    mc = replace(fit_model_config(model_config, parent, data, images), learned_precision=learns_precision(tc))
    use_images = uses_images(mc, data, tc, images, where=None if parent is None else run_name(parent))
    check_something_to_train(tc, use_images)
    initial_latents = check_initial_latents(initial_latents, len(data), mc.code_size)
    config = run_config("fit", init, mc, tc, data, use_images, parent=_run_path(parent))
    config["scaler"] = None if scaler is None else scaler.to_dict()
    world = current_world(tc.micro_batches)
    store, ckpt = _open(out_dir, config, resume, overwrite, (dataset.path, _run_path(parent)), tc.epochs, log_to, world)
    device = world.device(resolve_device(tc.device, tc.amp))
    seeds = derived_seeds(tc.seed)
    if ckpt is not None:
        parts = unpack_checkpoint(ckpt, out_dir)
        scaler, initializer = parts.scaler, parts.initializer
        model = _new_model(mc, seeds["model"], parts.model)
        model.to(device)
        theta_opt = theta_optimizer(model, tc)
        theta_opt.load_state_dict(parts.theta_optimizer)
        table = LatentTable.from_state_dict(parts.latents, device)
        scaled = scaler.transform(data.motor)
    else:
        scaler = parent.scaler if parent is not None else scaler or JointScaler().fit(data.motor)
        model = _new_model(mc, seeds["model"], None if parent is None else parent.model.state_dict())
        scaled = scaler.transform(data.motor)
        initializer = run_initializer(init, parent, mc, scaled, seeds, data)
        model.to(device)
        theta_opt = theta_optimizer(model, tc)
        codes = initial_codes(init, parent, initializer, scaled, seeds["codes_fit"], initial_latents, data)
        table = LatentTable(torch.from_numpy(codes.astype(np.float32)).to(device), tc.latent_lr, optimizer=tc.optimizer)
    session = Session(
        store=store,
        config=config,
        model=model,
        theta_opt=theta_opt,
        table=table,
        scaler=scaler,
        initializer=initializer,
        data=data,
        use_images=use_images,
        tc=tc,
        device=device,
        shuffle_seed=seeds["shuffle"],
        frames_seed=seeds["frames"],
        calibrate=_calibrator(initializer, scaled, mc.latent_dim),
        log_to=log_to,
    )
    return session, ckpt


def run_session(session: Session, ckpt: dict | None, progress: bool | None, label: str) -> TrainedRun:
    """Run a session of :func:`fit_session` / :func:`infer_session` to its last epoch (under its
    ``threads``) and return its run."""
    with thread_limit(session.tc.threads):  # torch's and BLAS's threads, put back after (no process-wide change)
        session.run(ckpt, progress, label=label)
    return run_from_state(session.state(), session.history, None if session.run_dir is None else session.run_dir.path)


def infer_session(*args, **kwargs) -> tuple[Session, dict | None]:
    """The session that :func:`infer` runs (an :class:`InferRequest`, or its fields as arguments, unknown
    keywords the train-config overrides), not yet run, and its checkpoint (:func:`fit_session`). A run
    directory is read here (the one place for ``infer`` and packed jobs)."""
    request = _request(InferRequest, args, kwargs)
    dataset, out_dir, indices, initial_latents = (
        request.dataset,
        request.out_dir,
        request.indices,
        request.initial_latents,
    )
    resume, overwrite, fitted_data, log_to = request.resume, request.overwrite, request.fitted_data, request.log_to
    parent = as_run(request.run)
    tc = _infer_config(parent, request)
    init = request.init or parent.init
    check_init(init, INFER_STARTS)
    check_calibrated(init, parent)
    observation = Observation.build(request.observe, request.observe_frames)
    data, _ = select(dataset, indices)
    mc = parent.model_config
    check_precision_learned(tc, parent)
    initial_latents = check_initial_latents(initial_latents, len(data), mc.code_size)
    use_images = uses_images(mc, data, tc)
    check_something_to_train(tc, use_images)
    config = run_config("infer", init, mc, tc, data, use_images, parent=_run_path(parent))
    config.update(observation_record(observation, data, use_images, mc.has_images))
    world = current_world(tc.micro_batches)
    store, ckpt = _open(out_dir, config, resume, overwrite, (dataset.path, _run_path(parent)), tc.epochs, log_to, world)
    device = world.device(resolve_device(tc.device, tc.amp))
    seeds = derived_seeds(tc.seed)
    model = copy.deepcopy(parent.model)  # θ frozen, but the caller's model is never moved or changed
    if ckpt is not None:
        parts = unpack_checkpoint(ckpt, out_dir)
        model.load_state_dict(parts.model)
        initializer = parts.initializer
        table = LatentTable.from_state_dict(parts.latents, device)
    else:
        scaled = parent.scaler.transform(data.motor)
        initializer, codes = inference_start(
            parent, init, data, scaled, observation, fitted_data, tc.seed, initial_latents
        )
        table = LatentTable(torch.from_numpy(codes.astype(np.float32)).to(device), tc.latent_lr, optimizer=tc.optimizer)
    model.to(device).requires_grad_(False)
    session = Session(
        store=store,
        config=config,
        model=model,
        theta_opt=None,
        table=table,
        scaler=parent.scaler,
        initializer=initializer,
        data=data,
        use_images=use_images,
        tc=tc,
        device=device,
        shuffle_seed=seeds["shuffle"],
        frames_seed=seeds["frames"],
        calibration=parent.calibration,
        observation=observation,
        log_to=log_to,
    )
    return session, ckpt


def _infer_config(parent: TrainedRun, request: InferRequest) -> TrainConfig:
    """The train config of an inference: the request's, or the run's with the default ``threads`` (not the
    fit's machine's), with ``epochs`` and the overrides."""
    if request.epochs is None:
        raise UserError("infer needs epochs=")
    base = request.train_config or replace(parent.train_config, threads=TrainConfig.threads)
    try:
        return replace(base, epochs=request.epochs, **request.overrides).validate()
    except TypeError as exc:
        raise UserError(f"unknown train config override ({exc})") from None


def theta_optimizer(model: MTRNNDecoder, tc: TrainConfig) -> torch.optim.Optimizer:
    """θ's optimiser of ``tc.optimizer``: Adam, or plain gradient descent (``torch.optim.SGD``, no momentum)."""
    if tc.optimizer == "sgd":
        return torch.optim.SGD(model.parameters(), lr=tc.lr)
    return torch.optim.Adam(model.parameters(), lr=tc.lr)


def uses_images(
    mc: ModelConfig, data: MotionDataset, tc: TrainConfig, images: bool | None = None, *, where: str | None = None
) -> bool:
    """Whether a run trains (or scores) the vision loss: the one rule.

    Yes when the model has an image head, the data has images (and ``images`` is not
    False), and ``vision_weight > 0``. ``images=True`` with a model without an image
    head, or with data without images, is an error; so is data whose T, J or image size
    differ from the model's.
    """
    if images and not mc.has_images:
        raise UserError(f"{where + ': ' if where else ''}the model has no image head")
    want = mc.has_images and (data.has_images if images is None else bool(images))
    check_data_fits(data, mc, want)
    return bool(want) and tc.vision_weight > 0


def as_run(run: TrainedRun | str | os.PathLike) -> TrainedRun:
    """A :class:`TrainedRun` as is, or the run read from its directory."""
    if isinstance(run, TrainedRun):
        return run
    if isinstance(run, (str, os.PathLike)):
        return load_run(run)
    raise UserError(f"expected a TrainedRun or a run directory, got {type(run).__name__}")


# --------------------------------------------------------------------------- helpers


def _open(out_dir, config: dict, resume: bool, overwrite: bool, inputs: tuple, epochs: int, log_to=None, world=None):
    """The run directory to write (None: in memory) and the checkpoint to resume from;
    ``log_to`` checked (:func:`~primspace.train.logger.check_log_to`). With several
    processes, process 0 checks and reads, and hands both to the others."""
    if world is not None and world.distributed:
        return world.from_main(lambda: _open(out_dir, config, resume, overwrite, inputs, epochs, log_to))
    check_log_to(log_to, inputs)
    if out_dir is None:
        if resume:
            raise UserError("resume=True needs the out_dir of the run to continue")
        return None, None
    return open_run_dir(Path(out_dir), config, resume, overwrite, inputs, epochs)


def _calibrator(initializer: LatentInitializer, scaled: np.ndarray, latent_dim: int):
    """What fits a run's calibration map from its final codes (None: its initialiser has no data map)."""
    if initializer.method not in CALIBRATABLE:
        return None
    return lambda codes: CodeCalibration(latent_dim).fit(initializer.transform(scaled), codes)


def learns_precision(tc: TrainConfig) -> bool:
    """Whether a fit under ``tc`` gives its decoder learned precisions (``ModelConfig.learned_precision``)."""
    return tc.loss_reduction == "precision"


def _new_model(mc: ModelConfig, seed: int, state: dict | None = None) -> MTRNNDecoder:
    """A decoder with weights drawn from ``seed`` (without touching the global RNG), then ``state`` loaded
    (a parent's learned precisions, ``precision.*``, only where this decoder has them; fresh ones where the
    parent has none)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = MTRNNDecoder(mc)
    if state is not None:
        own = model.state_dict()
        state = {k: v for k, v in state.items() if not k.startswith("precision.") or k in own}
        state |= {k: v for k, v in own.items() if k.startswith("precision.") and k not in state}
        model.load_state_dict(state)
    return model


def _run_path(run: TrainedRun | None) -> str | None:
    return None if run is None or run.run_dir is None else str(Path(run.run_dir).resolve())
