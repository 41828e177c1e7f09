"""The training loop: one :class:`Session` per ``fit`` / ``infer`` call steps θ (unless
frozen) and the codes, logs every epoch and checkpoints through an optional
:class:`~primspace.train.rundir.RunDirectory` (None: the run lives in memory only).

The loss (paper, *Main Results*: ``L(θ, z_1..z_n) = Σ_i ‖d(θ, z_i) − o_i‖²``) is taken here
as ``w_m · mean((m̂ − m)²) + w_v · mean((ŝ − s)²)`` (see :mod:`primspace.train`), or with
``TrainConfig.loss_reduction="sum"`` as the paper's sums over each sample's entries. For
data of different lengths (``MotionDataset.lengths``) each sample's loss is its mean (or
sum) over its own valid steps and the batch loss the mean over samples, so padding never
counts and a code's gradient does not depend on the other samples of its batch.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import time
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from primspace.data import JointScaler, MotionDataset
from primspace.data.steps import valid_steps
from primspace.latent import LatentInitializer, LatentTable
from primspace.model import MTRNNDecoder
from primspace.progress import progress_bar
from primspace.train.config import TrainConfig, TrainingDivergedError, lr_factor
from primspace.train.distributed import World, current_world, data_parallel, no_sync
from primspace.train.logger import open_logger
from primspace.train.observe import observation_masks
from primspace.train.rundir import RunDirectory, checkpoint_state, restore_rng, unpack_checkpoint
from primspace.train.streaming import FrameStream, should_stream

__all__ = [
    "DataTensors",
    "Session",
    "batch_loss",
    "code_step",
    "batch_frames",
    "evaluate_loop",
    "epoch_values",
    "local_parts",
    "frame_batches",
    "open_stream",
    "opened_stream",
]


@dataclass
class DataTensors:
    """Training targets on the device: scaled motor (float32) and frames (uint8, converted per batch).

    ``mask`` marks the valid steps (padding); ``motor_mask`` and ``frame_mask``, when set,
    the observed ones of each modality (inference from a part of each motion,
    :mod:`primspace.train.observe`), padding included. The loss counts the entries of
    :meth:`motor_steps` / :meth:`frame_steps` only.
    """

    motor: torch.Tensor  # (N, T, J) float32, scaled to [-1, 1]
    images: torch.Tensor | None  # (N, T, H, W, 3) uint8
    mask: torch.Tensor | None = None  # (N, T) float32, 1 at valid steps; None: every step
    motor_mask: torch.Tensor | None = None  # (N, T) float32, 1 at observed valid steps; None: ``mask``
    frame_mask: torch.Tensor | None = None  # the same for the frames
    streamed: bool = False  # the frames are trained on but not held: each batch brings its own

    @classmethod
    def build(
        cls, data: MotionDataset, scaler: JointScaler, use_images: bool, device, observation=None, stream: bool = False
    ) -> "DataTensors":
        """The tensors of ``data``; ``observation`` (:class:`~primspace.train.observe.Observation`)
        sets the observed masks (a modality observed at every valid step keeps ``mask``);
        ``stream``: the frames are left in the file (:mod:`primspace.train.streaming`)."""
        motor = torch.from_numpy(np.ascontiguousarray(scaler.transform(data.motor), dtype=np.float32)).to(device)
        images = None
        if use_images and not stream:
            loaded = data.load_images().images
            images = torch.from_numpy(np.ascontiguousarray(loaded)).to(device)
        mask = None
        if data.lengths is not None:
            mask = torch.from_numpy(valid_steps(data.lengths, data.length).astype(np.float32)).to(device)
        tensors = cls(motor, images, mask, streamed=use_images and stream)
        if observation is not None:
            valid = observation_masks(None, data)[0]
            motor_mask, frame_mask = (
                None if np.array_equal(m, valid) else torch.from_numpy(m.astype(np.float32)).to(device)
                for m in observation_masks(observation, data)
            )
            tensors.motor_mask, tensors.frame_mask = motor_mask, frame_mask
        return tensors

    @property
    def use_images(self) -> bool:
        """Whether the vision loss is trained (frames held here, or streamed per batch)."""
        return self.images is not None or self.streamed

    def motor_steps(self) -> torch.Tensor | None:
        """The motor entries the loss counts (N, T) (None: every one)."""
        return self.mask if self.motor_mask is None else self.motor_mask

    def frame_steps(self) -> torch.Tensor | None:
        """The frames the loss counts (N, T) (None: every one)."""
        return self.mask if self.frame_mask is None else self.frame_mask


def _rows(mask: torch.Tensor | None, idx: torch.Tensor) -> torch.Tensor | None:
    return None if mask is None else mask.index_select(0, idx)


def _mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean squared error; with ``mask`` (B, K) over the first two axes, each sample's mean
    over its valid entries, then the mean over samples."""
    if mask is None:
        return F.mse_loss(pred, target)
    per_step = (pred - target).pow(2).flatten(2).mean(dim=2)
    return ((per_step * mask).sum(dim=1) / mask.sum(dim=1).clamp_min(1.0)).mean()


def _sse(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None, scale: float = 1.0
) -> tuple[torch.Tensor, torch.Tensor]:
    """The paper's summed squared error (*Main Results*, ``Σ_i ‖d(θ, z_i) − o_i‖²``) and,
    detached, the per-element mean squared error that :func:`_mse` computes.

    The first is the mean over samples of each sample's sum over its valid entries
    (``mask`` (B, K) over the first two axes), times ``scale``; the second is for logging,
    so that ``motor`` / ``vision`` read the same under both reductions.
    """
    per_step = (pred - target).pow(2).flatten(2).sum(dim=2)  # (B, K): one sum per step
    valid = per_step if mask is None else per_step * mask
    summed = valid.sum(dim=1).mean()
    if scale != 1.0:
        summed = summed * scale
    with torch.no_grad():
        size = per_step.new_tensor(float(pred[0, 0].numel()))  # entries per step
        if mask is None:
            mse = per_step.mean() / size
        else:
            mse = (valid.sum(dim=1) / size / mask.sum(dim=1).clamp_min(1.0)).mean()
    return summed, mse


def batch_frames(images: torch.Tensor, idx: torch.Tensor, steps: torch.Tensor | None) -> torch.Tensor:
    """The stored frames of samples ``idx`` (B, T, H, W, 3) uint8, or at ``steps`` (B, K) only (B, K, H, W, 3)."""
    if steps is None:
        return images.index_select(0, idx)
    n, t = images.shape[:2]
    rows = (idx.unsqueeze(1) * t + steps).reshape(-1)
    return images.view(n * t, *images.shape[2:]).index_select(0, rows).view(*steps.shape, *images.shape[2:])


def batch_loss(
    model,
    z,
    idx,
    tensors: DataTensors,
    tc: TrainConfig,
    autocast,
    steps: torch.Tensor | None = None,
    frames: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The loss of one batch and the detached ``[loss, motor, vision]`` means.

    ``loss`` is the objective of ``tc.loss_reduction`` (``"mean"``: ``w_m · motor + w_v ·
    vision``; ``"sum"``: the same weights on each sample's summed squared errors, then the
    mean over samples); ``motor`` and ``vision`` are per-element mean squared errors
    under both. ``steps`` (B, K): the vision loss on those frames of each sequence only
    (every frame when None); a sum over them is scaled by ``T / K``, an unbiased estimate
    of the sum over all frames (each step is drawn with probability ``K / T``). ``frames``:
    the batch's stored frames (:func:`batch_frames`), given when they are streamed;
    None: taken from ``tensors``. ``model`` may be wrapped (DDP).
    """
    summed = tc.loss_reduction == "sum"
    use_images = tensors.use_images
    mask, motor_mask = _rows(tensors.mask, idx), _rows(tensors.motor_steps(), idx)
    with autocast:
        out = model(z, images=use_images, frame_steps=steps if use_images else None)
    if summed:
        motor_term, motor = _sse(out.motor.float(), tensors.motor.index_select(0, idx), motor_mask)
    else:
        motor = motor_term = _mse(out.motor.float(), tensors.motor.index_select(0, idx), motor_mask)
    if use_images:
        frame_mask = _rows(tensors.frame_steps(), idx)
        if steps is not None and frame_mask is not None:
            frame_mask = frame_mask.gather(1, steps)
        target = batch_frames(tensors.images, idx, steps) if frames is None else frames
        target = target.to(torch.float32).div_(255.0)
        if summed:
            scale = 1.0 if steps is None else tensors.motor.shape[1] / steps.shape[1]
            vision_term, vision = _sse(out.images.float(), target, frame_mask, scale)
        else:
            vision = vision_term = _mse(out.images.float(), target, frame_mask)
        loss = tc.motor_weight * motor_term + tc.vision_weight * vision_term
    else:
        vision = torch.zeros((), device=motor.device)
        loss = tc.motor_weight * motor_term
    config = getattr(model, "module", model).config  # DDP holds the decoder as .module
    if tc.code_smoothness > 0 and config.code_window is not None:
        loss = loss + tc.code_smoothness * code_variation(z, config, mask)
    return loss, torch.stack([loss.detach(), motor.detach(), vision.detach()])


def code_step(
    model, table: LatentTable, idx: torch.Tensor, tensors: DataTensors, tc: TrainConfig, autocast, to_code=None
) -> torch.Tensor:
    """One Adam step of the rows ``idx`` of ``table`` with θ frozen, each row on the gradient of
    its own sample's loss (:func:`batch_loss` of the batch ``idx``; its mean over the batch
    scaled each row's gradient by 1/B, undone here). ``to_code``: maps the table's rows to
    the decoder's codes (e.g. coordinates in a subspace, ``mean + a @ basis``); None: the rows
    are the codes. Returns the detached ``[loss, motor, vision]`` means.
    """
    rows = table.batch(idx)
    loss, values = batch_loss(model, rows if to_code is None else to_code(rows), idx, tensors, tc, autocast)
    loss.backward()
    table.step(idx, rows.grad.mul_(idx.numel()))
    return values


def code_variation(z: torch.Tensor, config, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean over samples of ``Σ_k ‖z_{k+1} − z_k‖₂`` over each sample's valid windows
    (a window is valid when its first step is; :class:`~primspace.train.TrainConfig`
    ``code_smoothness``)."""
    codes = z.view(z.shape[0], config.n_codes, config.latent_dim)
    steps = torch.sqrt(codes.diff(dim=1).pow(2).sum(dim=2) + 1e-12)  # (B, K-1); smooth at 0
    if mask is not None:
        steps = steps * mask[:, :: config.code_window][:, 1:]
    return steps.sum(dim=1).mean()


def autocast_for(tc: TrainConfig, device: torch.device):
    if tc.amp and device.type == "cuda":
        return torch.autocast(device_type="cuda", dtype=torch.bfloat16)
    return contextlib.nullcontext()


def evaluate_loop(
    model,
    table: LatentTable,
    tensors: DataTensors,
    tc: TrainConfig,
    device,
    world: World | None = None,
    stream: FrameStream | None = None,
) -> torch.Tensor:
    """Sums over samples of ``[loss, motor, vision]`` (no updates, samples in order), over
    every process of ``world``; ``stream``: where the frames come from (None: ``tensors``)."""
    world = world or World()
    n = len(table)
    order = torch.arange(n, device=device)
    work = local_parts([(order[start : start + tc.batch_size], None) for start in range(0, n, tc.batch_size)], world)
    frames = frame_batches(work, stream)
    sums = torch.zeros(world.micro_batches, 3, dtype=torch.float64, device=device)
    with torch.no_grad():
        for parts in work:
            for part, idx, steps in parts:
                z = table.codes.index_select(0, idx)
                _, values = batch_loss(model, z, idx, tensors, tc, autocast_for(tc, device), steps, next(frames))
                sums[part.micro] += values.double() * part.size
    return world.sum(sums.sum(0))


def local_parts(plan: list, world: World, join: bool = False) -> list[list]:
    """For each batch ``(idx, steps)`` of ``plan``, this process's parts: ``(part, idx, steps)``
    (:meth:`~primspace.train.distributed.World.parts`)."""
    return [
        [
            (part, idx[part.rows], None if steps is None else steps[part.rows])
            for part in world.parts(idx.numel(), join=join)
        ]
        for idx, steps in plan
    ]


def frame_batches(work: list, stream: FrameStream | None):
    """The streamed frames of each part of ``work`` (:func:`local_parts`) in order; None for each when held in memory."""
    if stream is None:
        return itertools.repeat(None)
    return stream.batches([(idx, steps) for parts in work for _, idx, steps in parts])


def epoch_values(sums: torch.Tensor, n: int, use_images: bool) -> dict:
    loss, motor, vision = (sums / n).tolist()
    return {"loss": loss, "motor": motor, "vision": vision if use_images else None}


def open_stream(tc: TrainConfig, data: MotionDataset, use_images: bool, device, world: World) -> FrameStream | None:
    """The frame stream of a session that streams its frames (:func:`~primspace.train.streaming.should_stream`), else None."""
    if not should_stream(tc, data, use_images, device, world.local_size):
        return None
    return FrameStream(data.images, tc.loader_workers, device)


@contextlib.contextmanager
def opened_stream(tc: TrainConfig, data: MotionDataset, use_images: bool, device, world: World | None = None):
    """:func:`open_stream` for the length of a ``with`` block (its workers stopped at the end)."""
    stream = open_stream(tc, data, use_images, device, world or World())
    try:
        yield stream
    finally:
        if stream is not None:
            stream.close()


class Session:
    """One run's training loop: θ (unless ``theta_opt`` is None: frozen) and the codes.

    ``store`` receives the config, metrics and checkpoints (written after epoch 0, every
    ``checkpoint_seconds`` or ``checkpoint_every`` epochs, and at the end); with None the
    run is kept in memory: :attr:`history` and :meth:`state` are all there is. ``log_to``
    (``("tensorboard", DIR)``, :mod:`primspace.train.logger`) also receives every metrics
    line, from the first epoch this session logs; it is flushed before each checkpoint.
    ``world``: the processes that train the model together
    (:mod:`primspace.train.distributed`; only process 0 writes; default: this process's
    :func:`~primspace.train.distributed.current_world`). The frames are streamed
    from the data file when ``tc`` says so (:mod:`primspace.train.streaming`).
    """

    def __init__(
        self,
        *,
        store: RunDirectory | None,
        config: dict,
        model: MTRNNDecoder,
        theta_opt,
        table: LatentTable,
        scaler: JointScaler,
        initializer: LatentInitializer,
        data: MotionDataset,
        use_images: bool,
        tc: TrainConfig,
        device: torch.device,
        shuffle_seed: int,
        frames_seed: int = 0,
        calibrate=None,
        calibration=None,
        observation=None,
        log_to=None,
        world: World | None = None,
    ) -> None:
        # calibrate: codes -> CodeCalibration, fitted when the last epoch is done (fit);
        # calibration: a map carried as is (infer: the trained run's)
        self.calibrate, self.calibration = calibrate, calibration
        self.world = world or current_world(tc.micro_batches)
        self.run_dir = store  # named in messages by every process; written by process 0 only
        self.store = store if self.world.is_main else None
        self.config, self.model, self.theta_opt = config, model, theta_opt
        self.table, self.scaler, self.initializer, self.tc, self.device = table, scaler, initializer, tc, device
        self.stream = open_stream(tc, data, use_images, device, self.world)
        self.tensors = DataTensors.build(data, scaler, use_images, device, observation, stream=self.stream is not None)
        self.use_images = use_images
        # what computes the loss: θ's DDP wrapper when several processes train it
        unused = model.image_head is not None and not use_images
        self.net = model if theta_opt is None else data_parallel(model, self.world, device, unused)
        self.generator = torch.Generator().manual_seed(shuffle_seed)
        length = self.tensors.motor.shape[1]
        k = tc.vision_frames
        # the vision loss on K drawn frames per sequence (None: every frame, the exact loss)
        self.frames = None if not use_images or k is None or k >= length else (k, length)
        self.frame_generator = torch.Generator().manual_seed(frames_seed) if self.frames else None
        self.initial_codes = table.codes.detach().cpu().clone()
        self.log_to, self.sink = (log_to if self.world.is_main else None), None
        self.history: list[dict] = []
        self.epoch = 0
        self.n = len(table)
        self._last_checkpoint = 0
        self._checkpoint_time = time.monotonic()

    @property
    def name(self) -> str:
        return self.run_dir.path.name if self.run_dir is not None else "(in memory)"

    def state(self) -> dict:
        """The checkpoint of the session as it stands (:func:`~primspace.train.rundir.checkpoint_state`)."""
        return checkpoint_state(
            config=self.config,
            epoch=self.epoch,
            model=self.model,
            theta_opt=self.theta_opt,
            table=self.table,
            initial_codes=self.initial_codes,
            scaler=self.scaler,
            initializer=self.initializer,
            generator=self.generator,
            frame_generator=self.frame_generator,
            calibration=self.calibration,
        )

    # ------------------------------------------------------------------------ loop
    def run(self, ckpt: dict | None, progress: bool | None, label: str) -> None:
        """Train up to ``tc.epochs``, from ``ckpt`` (a checkpoint dict) or from the start."""
        try:
            self._run(ckpt, progress if self.world.is_main else False, label)
        finally:
            if self.sink is not None:
                self.sink.close()
                self.sink = None
            if self.stream is not None:
                self.stream.close()

    def _run(self, ckpt: dict | None, progress: bool | None, label: str) -> None:
        tc = self.tc
        if ckpt is not None:
            self._restore(ckpt)
            self.sink = open_logger(self.log_to, self.epoch + 1)  # the epochs after the checkpoint: logged anew
        else:
            if self.store is not None:
                self.store.begin(self.config, self.initial_codes.numpy())
            self.sink = open_logger(self.log_to, 0)
            if tc.log_initial:
                t0 = time.perf_counter()
                self.model.eval()
                sums = evaluate_loop(self.model, self.table, self.tensors, tc, self.device, self.world, self.stream)
                self._log(0, epoch_values(sums, self.n, self.use_images), time.perf_counter() - t0)
            self._checkpoint()
        calibrated = False
        fields_fmt = "loss {task.fields[loss]:.4g}  {task.fields[sps]:.0f} samples/s"
        with progress_bar(tc.epochs, f"{label} {self.name}", enabled=progress, fields=fields_fmt) as advance:
            if self.epoch:
                advance(self.epoch)
            while self.epoch < tc.epochs:
                t0 = time.perf_counter()
                values = epoch_values(self._train_epoch(), self.n, self.use_images)
                seconds = time.perf_counter() - t0
                self._check_finite(values)
                self.epoch += 1
                self._log(self.epoch, values, seconds)
                due = tc.checkpoint_every is not None and self.epoch % tc.checkpoint_every == 0
                if self.epoch == tc.epochs and self.calibrate is not None:
                    self.calibration = self.calibrate(self.table.numpy())
                    calibrated = True
                if due or self.epoch == tc.epochs or time.monotonic() - self._checkpoint_time >= tc.checkpoint_seconds:
                    self._checkpoint()
                advance(loss=values["loss"], sps=self.n / max(seconds, 1e-9))
        if self.calibrate is not None and not calibrated:  # a finished fit: its map as this version fits it
            fresh = self.calibrate(self.table.numpy())
            if not fresh.same_map(self.calibration):  # none yet (primspace 0.4), or fitted another way
                self.calibration = fresh
                self._checkpoint()

    def _check_finite(self, values: dict) -> None:
        bad = [k for k, v in values.items() if v is not None and not math.isfinite(v)]
        if bad:
            what = "loss" if bad[0] == "loss" else f"{bad[0]} loss"
            then = (
                (
                    f"the last good checkpoint (epoch {self._last_checkpoint}) is kept (lower the learning "
                    "rates, then resume)"
                )
                if self.run_dir
                else "nothing was saved (lower the learning rates and run again)"
            )
            raise TrainingDivergedError(
                f"{self.name}: the {what} became {values[bad[0]]} in epoch {self.epoch + 1}; stopped, {then}"
            )

    def _train_epoch(self) -> torch.Tensor:
        tc = self.tc
        factor = lr_factor(self.epoch, tc.epochs, tc.final_lr_fraction)
        self.table.lr = tc.latent_lr * factor
        if self.theta_opt is not None:
            for group in self.theta_opt.param_groups:
                group["lr"] = tc.lr * factor
        self.model.train(self.theta_opt is not None)
        order = torch.randperm(self.n, generator=self.generator).to(self.device)
        plan = [
            (order[start : start + tc.batch_size], self._draw_frames(min(tc.batch_size, self.n - start)))
            for start in range(0, self.n, tc.batch_size)
        ]  # the epoch's draws, as one process makes them
        work = local_parts(plan, self.world, join=self.net is not self.model)
        frames = frame_batches(work, self.stream)
        sums = torch.zeros(self.world.micro_batches, 3, dtype=torch.float64, device=self.device)
        autocast = autocast_for(tc, self.device)
        for (idx, _), parts in zip(plan, work):
            self._step(idx, parts, frames, sums, autocast)
        return self.world.sum(sums.sum(0))

    def _step(self, idx: torch.Tensor, parts: list, frames, sums: torch.Tensor, autocast) -> None:
        """One batch: θ steps on the gradient of its mean loss (its parts' gradients summed,
        over the processes by DDP), each code on its own sample's loss gradient."""
        if self.theta_opt is not None:
            self.theta_opt.zero_grad(set_to_none=True)
        grads = []
        for i, (part, rows, steps) in enumerate(parts):
            z = self.table.batch(rows)
            with no_sync(self.net, last=i == len(parts) - 1):
                loss, values = batch_loss(self.net, z, rows, self.tensors, self.tc, autocast, steps, next(frames))
                (loss if part.weight == 1.0 else loss * part.weight).backward()
            if not part.dummy:
                # the mean over the part scaled z.grad by weight/b: undo it, so each code steps
                # on the gradient of its own sample's loss whatever the batch (module docstring)
                grads.append(z.grad.mul_(part.code_scale))
                sums[part.micro] += values.double() * part.size
        if self.theta_opt is not None:
            self.theta_opt.step()
        codes = self.table.codes
        local = torch.cat(grads) if grads else codes.new_zeros((0, codes.shape[1]))
        self.table.step(idx, self.world.gather_rows(local, idx.numel()))

    def _draw_frames(self, batch: int) -> torch.Tensor | None:
        """K distinct steps per sequence, uniformly drawn (None: every frame)."""
        if self.frames is None:
            return None
        k, length = self.frames
        steps = torch.rand(batch, length, generator=self.frame_generator).argsort(dim=1)[:, :k]
        return steps.to(self.device)

    def _log(self, epoch: int, values: dict, seconds: float) -> None:
        line = {
            "epoch": epoch,
            **values,
            "seconds": round(seconds, 6),
            "samples_per_s": round(self.n / max(seconds, 1e-9), 3),
        }
        self.history.append(line)
        if self.store is not None:
            self.store.log(line)
        if self.sink is not None:
            self.sink.log(line)

    # ----------------------------------------------------------------- checkpoints
    def _checkpoint(self) -> None:
        if self.sink is not None:  # the logged epochs reach the event files before the checkpoint that keeps them
            self.sink.flush()
        if self.store is not None:
            self.store.save(self.state(), self.table.numpy())
        self._last_checkpoint = self.epoch
        self._checkpoint_time = time.monotonic()

    def _restore(self, state: dict) -> None:
        ckpt = unpack_checkpoint(state)
        self.epoch = self._last_checkpoint = ckpt.epoch
        self._checkpoint_time = time.monotonic()
        self.initial_codes = ckpt.initial_codes
        if ckpt.calibration is not None and (self.calibrate is None or ckpt.epoch >= self.tc.epochs):
            self.calibration = ckpt.calibration  # a fit extended past it fits a new one at its new end
        restore_rng(ckpt.rng, self.generator, self.frame_generator)
        self.history = self.store.history_through(self.epoch) if self.store is not None else []
