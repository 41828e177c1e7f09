"""The training loop: one :class:`Session` per ``fit`` / ``infer`` call steps θ (unless
frozen) and the codes, logs every epoch and checkpoints through an optional
:class:`~primspace.train.rundir.RunDirectory` (None: the run lives in memory only).

The loss of each batch, and how padding and observed steps count in it, is
:mod:`primspace.train.loss`'s: θ steps on the gradient of the batch's mean loss, each code
on the gradient of its own sample's loss.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import time
from dataclasses import dataclass

import torch

from primspace.data import JointScaler, MotionDataset
from primspace.model.decoder import MTRNNDecoder
from primspace.model.latent import LatentInitializer, LatentTable
from primspace.train.captured import CapturedStep, CompiledDecoder, check_single_process
from primspace.train.checkpoint import checkpoint_state, restore_rng, unpack_checkpoint
from primspace.train.config import TrainConfig, TrainingDivergedError, lr_factor
from primspace.train.distributed import World, current_world, data_parallel, no_sync
from primspace.train.logger import open_logger
from primspace.train.loss import DataTensors, autocast_for, batch_loss
from primspace.train.rundir import RunDirectory
from primspace.train.streaming import FrameStream, should_stream
from primspace.utils.interrupt import Interrupted, deferred_interrupt
from primspace.utils.progress import announce, progress_bar

__all__ = [
    "Session",
    "Epoch",
    "evaluate_loop",
    "epoch_values",
    "local_parts",
    "frame_batches",
    "open_stream",
    "opened_stream",
]


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


@dataclass
class Epoch:
    """One epoch's draws (:meth:`Session.begin_epoch`): per batch its rows and this
    process's parts (:func:`local_parts`), the streamed frames in order, the loss sums
    its steps add to (one row per micro-batch) and the precision of the loss."""

    batches: list
    frames: object
    sums: torch.Tensor
    autocast: object


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
        self._calibrated = False  # the calibration map fitted at this session's last epoch
        self._checkpoint_time = time.monotonic()
        # how a batch steps (TrainConfig.step): op by op, the recurrent loop compiled, or captured
        self.captured = CapturedStep(self) if tc.step == "captured" else None
        if tc.step == "compiled":
            check_single_process(self, "step='compiled'")
            self.net = CompiledDecoder(model)

    @property
    def name(self) -> str:
        """The run as messages and bars name it: its folder's name, with the parent folder's when the
        folder is named after a kind of run (``runs/fit``, not ``fit fit`` after the label)."""
        if self.run_dir is None:
            return "(in memory)"
        path = self.run_dir.path
        return f"{path.parent.name}/{path.name}" if path.name in ("fit", "infer") and path.parent.name else path.name

    def state(self) -> dict:
        """The checkpoint of the session as it stands (:func:`~primspace.train.checkpoint.checkpoint_state`)."""
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
            self.close()

    def close(self) -> None:
        """Close the logger, the frame stream and the run directory (its writer's lock)."""
        if self.sink is not None:
            self.sink.close()
            self.sink = None
        if self.stream is not None:
            self.stream.close()
        if self.store is not None:
            self.store.close()  # the writer's lock: the run is over, however it ended

    def _run(self, ckpt: dict | None, progress: bool | None, label: str) -> None:
        """The epochs up to ``tc.epochs``. Ctrl-C (one process training into a run directory) stops
        after the epoch it comes in: that epoch is checkpointed and
        :class:`~primspace.utils.interrupt.Interrupted` says where the run stands; a second Ctrl-C
        stops at once (the last checkpoint kept). A run held in memory stops at once."""
        self.start(ckpt)
        self._announce_start(ckpt, progress, label)
        fields_fmt = "loss {task.fields[loss]:.4g}  {task.fields[sps]:.0f} samples/s"
        deferred = self.store is not None and not self.world.distributed
        with deferred_interrupt("stopping after this epoch, its checkpoint written", enabled=deferred) as stop:
            with progress_bar(self.tc.epochs, f"{label} {self.name}", enabled=progress, fields=fields_fmt) as advance:
                if self.epoch:
                    advance(self.epoch)
                while self.epoch < self.tc.epochs and not stop.requested:
                    t0 = time.perf_counter()
                    values = self.end_epoch(self._train_epoch(), time.perf_counter() - t0)
                    advance(loss=values["loss"], sps=values["samples_per_s"])
            if self.epoch < self.tc.epochs:  # stopped by Ctrl-C
                self._stop(label)
            self.finish()
        if stop.requested:
            raise Interrupted(f"{label} {self.name}: finished (epoch {self.epoch}) as Ctrl-C came")

    def _announce_start(self, ckpt: dict | None, progress: bool | None, label: str) -> None:
        """One line when a run resumes (from which epoch; the metrics lines past that checkpoint
        dropped), or when it was asked to resume and found no checkpoint (it starts over)."""
        if ckpt is not None:
            dropped = 0 if self.store is None else self.store.dropped
            after = f"; {dropped} epoch(s) logged after that checkpoint dropped from metrics.jsonl" if dropped else ""
            announce(
                f"{label} {self.name}: resuming from epoch {self.epoch} of {self.tc.epochs}{after}", enabled=progress
            )
        elif self.store is not None and self.store.resume_asked:
            announce(f"{label} {self.name}: no checkpoint to resume from: starting from epoch 0", enabled=progress)

    def checkpoint_now(self) -> None:
        """Checkpoint the epoch just done, unless it is checkpointed already (a stop on Ctrl-C)."""
        if self._last_checkpoint != self.epoch:
            self._checkpoint()

    def _stop(self, label: str) -> None:
        """After Ctrl-C: the epoch just done checkpointed, and :class:`Interrupted` saying so."""
        where = f"{label} {self.name}: stopped after epoch {self.epoch} of {self.tc.epochs}"
        self.checkpoint_now()
        raise Interrupted(f"{where}, checkpoint written; continue it with resume=True, epochs={self.tc.epochs}")

    def start(self, ckpt: dict | None) -> None:
        """From ``ckpt`` (a checkpoint dict), or from the start: the run directory begun,
        epoch 0 logged (``tc.log_initial``) and checkpointed."""
        if ckpt is not None:
            self._restore(ckpt)
            self.sink = open_logger(self.log_to, self.epoch + 1)  # the epochs after the checkpoint: logged anew
            return
        if self.store is not None:
            self.store.begin(self.config, self.initial_codes.numpy())
        self.sink = open_logger(self.log_to, 0)
        if self.tc.log_initial:
            t0 = time.perf_counter()
            self.model.eval()
            sums = evaluate_loop(self.model, self.table, self.tensors, self.tc, self.device, self.world, self.stream)
            self._log(0, epoch_values(sums, self.n, self.use_images), time.perf_counter() - t0)
        self._checkpoint()

    def begin_epoch(self) -> Epoch:
        """The next epoch's learning rates set and its draws made (:class:`Epoch`)."""
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
        sums = torch.zeros(self.world.micro_batches, 3, dtype=torch.float64, device=self.device)
        batches = [(idx, parts) for (idx, _), parts in zip(plan, work)]
        return Epoch(batches, frame_batches(work, self.stream), sums, autocast_for(tc, self.device))

    def end_epoch(self, sums: torch.Tensor, seconds: float) -> dict:
        """Log the finished epoch from its ``[loss, motor, vision]`` sums (checked finite) and
        checkpoint when due; returns the logged line."""
        tc = self.tc
        values = epoch_values(sums, self.n, self.use_images)
        self._check_finite(values)
        self.epoch += 1
        self._log(self.epoch, values, seconds)
        due = tc.checkpoint_every is not None and self.epoch % tc.checkpoint_every == 0
        if self.epoch == tc.epochs and self.calibrate is not None:
            self.calibration = self.calibrate(self.table.numpy())
            self._calibrated = True
        if due or self.epoch == tc.epochs or time.monotonic() - self._checkpoint_time >= tc.checkpoint_seconds:
            self._checkpoint()
        return self.history[-1]

    def finish(self) -> None:
        """After the last epoch: a fit resumed from a finished checkpoint gets its calibration map
        as this version fits it (none yet, primspace 0.4, or fitted another way)."""
        if self.calibrate is None or self._calibrated:
            return
        fresh = self.calibrate(self.table.numpy())
        if not fresh.same_map(self.calibration):
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
        """One epoch of steps; its ``[loss, motor, vision]`` sums over the samples (every process's)."""
        epoch = self.begin_epoch()
        if self.captured is not None:
            self.captured.run(epoch)
        else:
            for idx, parts in epoch.batches:
                self._step(idx, parts, epoch.frames, epoch.sums, epoch.autocast)
        return self.world.sum(epoch.sums.sum(0))

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
