"""How to optimise: :class:`TrainConfig`, the learning-rate schedule, the device, and the
process-wide settings an entry point applies (:func:`configure_process`).

Torch is imported only by the functions that need it, so configurations (and the command
line's defaults, read from :class:`TrainConfig`) load without it.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import sys
from collections.abc import Iterator
from dataclasses import asdict, dataclass

from primspace.utils.errors import UserError, config_from_dict
from primspace.utils.seeds import check_seed

__all__ = [
    "TrainConfig",
    "TrainingDivergedError",
    "LOSS_REDUCTIONS",
    "STEPS",
    "OPTIMIZERS",
    "lr_factor",
    "resolve_device",
    "configure_process",
    "thread_limit",
]

#: :attr:`TrainConfig.loss_reduction`'s values: primspace's per-element means, the paper's sums,
#: the per-element means weighed by learned precisions.
LOSS_REDUCTIONS = ("mean", "sum", "precision")
#: How a batch's step runs (TrainConfig.step).
STEPS = ("eager", "compiled", "captured")
#: How θ and the codes step (TrainConfig.optimizer).
OPTIMIZERS = ("adam", "sgd")


class TrainingDivergedError(UserError):
    """The loss became NaN or infinite; a run directory keeps its last good checkpoint."""


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
        Learning rate of the model weights θ.
    latent_lr : float
        Learning rate of the codes (row-wise, :class:`primspace.model.latent.LatentTable`).
    optimizer : {"adam", "sgd"}
        How θ and the codes step. ``"adam"`` (default): Adam for θ, a row-wise Adam for the
        codes (each code's moments its own). ``"sgd"``: plain gradient descent of both, the
        paper's setting (*Main Results*: "It is minimized with usual batch gradient
        descend"), on the same mini-batches and cosine schedule; its rates are not Adam's
        (choose them on a validation split: ``primspace experiment tune``).
    final_lr_fraction : float
        Both learning rates follow a cosine from their value in the first epoch to this
        fraction of it in the last (1.0: constant). Default 0.1, the experiment presets'
        (:func:`primspace.experiments.presets.default_train`): on the paper preset (343
        fitted, q = 40, 800 epochs, motor only) a constant rate ended at loss 2.4e-4, the
        decay at 2.0e-5. The factor depends only on the epoch
        index and ``epochs``, so a resumed run continues the same schedule (unless
        ``epochs`` is changed on resume, which stretches the rest of it).
    motor_weight, vision_weight : float
        ``w_m``, ``w_v`` of the loss (module docstring). ``vision_weight = 0`` skips the
        image head.
    loss_reduction : {"mean", "sum", "precision"}
        How the squared errors of a sample are reduced (docs/model.md, "The paper's
        summed loss"). ``"mean"`` (default, primspace's loss): each sample's mean over
        its valid motor entries and over its pixels,
        ``ℓ_i = w_m · mean_{t,j}(m̂_itj − m_itj)² + w_v · mean_{t,pixels}(ŝ_it − s_it)²``,
        so motor and vision weigh alike at weights 1. ``"sum"``: the paper's loss
        (*Main Results*, ``L(θ, z_1..z_n) = Σ_i ‖d(θ, z_i) − o_i‖²``): sums instead of
        means, ``ℓ_i = w_m · Σ_{t valid, j}(m̂_itj − m_itj)² + w_v · Σ_{t valid, pixels}(ŝ_it − s_it)²``,
        so each pixel weighs as much as each joint value (vision then outweighs motor
        by the ratio of their sizes, ~1000 for 9 joints and 48x64x3 frames). Under
        both, the batch objective is the mean of ``ℓ_i`` over the batch's samples (θ's
        step does not depend on the batch size; a code steps on its own ``∇ℓ_i``); the
        paper's ``L`` is ``n`` times the mean over all samples, the same minimiser.
        Padded steps never count. With ``vision_frames=K`` the vision sum runs over the
        K drawn frames times ``T / K`` (each step is drawn with probability ``K / T``):
        an unbiased estimate of the all-frame sum. The learning rates are not rescaled:
        Adam's step is invariant to a constant factor on the loss except through its
        ``eps`` (1e-8), whose damping becomes ``D`` times weaker for a loss ``D`` times
        larger (``D`` = T·J for motor, more with frames), negligible at the gradient
        sizes of training; tested stable (finite, decreasing) with the default rates.
        ``"precision"``: the per-element means, each modality's weighed by its learned
        precision as a Gaussian likelihood, ``ℓ_i = Σ_m ½ (e^{-s_m} · w_m · MSE_im + s_m)``
        with one log-variance ``s_m`` per modality trained with θ (Kendall, Gal & Cipolla
        2018; :mod:`primspace.model.precision`): ``s_m`` settles at ``log`` of its
        modality's error, so each sense weighs by how well it is predicted, not by its
        size; the fit gives its decoder the ``s_m`` (``ModelConfig.learned_precision``);
        inference with θ frozen keeps them frozen (a code's gradient still depends on its
        own sample only). A modality at weight 0 has no term.
        The logged ``loss`` is the objective (under ``"precision"`` it can be negative);
        ``motor`` and ``vision`` stay the per-element mean squared errors under each,
        comparable across reductions.
    vision_frames : int, optional
        Compute the vision loss of each training step on this many frames per sequence,
        drawn uniformly without replacement (a fresh draw per sequence and step, from
        the run's seed): an unbiased estimate of the all-frame loss and of its gradient,
        at about ``K / T`` of the image head's cost. None (default) or ``>= T``: every
        frame, the exact loss. Epoch 0 and :func:`~primspace.train.evaluate` always use
        every frame; logged training epochs report the estimate.
    code_smoothness : float
        λ ≥ 0 of a total-variation penalty ``λ Σ_k ‖z_{k+1} − z_k‖₂`` on each sample's
        sequence of codes (models with a code window; valid windows only), added to its
        loss: codes that change seldom and then at once, piecewise constant as
        primitives are (docs/sequences.md). 0 (default): none.
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
        CPU threads of torch's intra-op pool and of numpy's BLAS while :func:`~primspace.train.fit`
        or :func:`~primspace.train.infer` runs, put back after (:func:`thread_limit`;
        :func:`configure_process` sets them for the whole process). Default 1: more threads
        than free cores make the threads wait on each other (on a 2-core machine that
        others used, a small fit took 8.2-9.1 s with 1 thread, 52.8-173.9 s with 2 and
        541.7 s with torch's default; numpy's BLAS 3.1 s with 1 thread, 17.2 s with 2), and
        one thread gives the same numbers on every machine (the count changes float
        summation order). Raise it on a machine of your own with an image
        head or large batches. None: leave both as they are.
    tune_malloc : bool
        On Linux/glibc CPU runs, keep freed memory in the heap (``mallopt``) so large
        activation buffers are reused instead of page-faulted in every batch (the image
        head ran 1.6x faster in a measurement; see docs/model.md). Process-wide: applied by
        :func:`configure_process`.
    stream_frames : bool, optional
        Read each batch's camera frames from the data file while training (a
        ``torch.utils.data.DataLoader`` whose worker processes open the file themselves)
        instead of loading every frame into memory first; motor, masks and codes stay in
        memory. The numbers are the same bit for bit either way (:mod:`primspace.train.streaming`).
        None (default): stream when the frames would not fit in ``frames_memory_gb``.
        Frames already in memory (a data set not read from a file) are used as they are.
    frames_memory_gb : float, optional
        The memory the frames may take when loaded (GB; all the processes of a machine
        together when several train one model). None: half of the device's memory (the
        host's RAM on the CPU, the GPU's on CUDA).
    loader_workers : int
        Worker processes that read and decode the streamed frames (0: the training
        process reads them itself, between steps).
    micro_batches : int
        Split each batch into this many parts, processed one after another with their
        gradients summed: the numbers of as many data-parallel processes, bit for bit on
        the CPU (:mod:`primspace.train.distributed`), at a part's peak memory.
    step : {"eager", "compiled", "captured"}
        How each batch's step runs (docs/performance.md, "Training at the speed of the
        hardware"). ``"eager"`` (default): operation by operation, the numbers of every
        earlier version bit for bit. ``"compiled"``: the recurrent loop
        (:meth:`~primspace.model.decoder.MTRNNDecoder.dynamics`) through ``torch.compile``, its
        cell fused (a compile of minutes the first time, cached on disk after). ``"captured"``:
        every batch padded to ``batch_size`` with rows that weigh 0, and on CUDA the whole
        step (forward, loss, backward, both optimisers, the codes' update) replayed as one
        CUDA graph; on the CPU the same padded step without a graph
        (:mod:`primspace.train.captured`). Both equal ``"eager"`` within float tolerance;
        one process, frames in memory. May change on resume.
    """

    epochs: int = 100
    batch_size: int = 32
    lr: float = 1e-3
    latent_lr: float = 1e-2
    optimizer: str = "adam"
    final_lr_fraction: float = 0.1
    motor_weight: float = 1.0
    vision_weight: float = 1.0
    vision_frames: int | None = None
    loss_reduction: str = "mean"
    code_smoothness: float = 0.0
    seed: int = 0
    device: str = "auto"
    amp: bool = False
    checkpoint_every: int | None = None
    checkpoint_seconds: float = 60.0
    log_initial: bool = True
    threads: int | None = 1
    tune_malloc: bool = True
    stream_frames: bool | None = None
    frames_memory_gb: float | None = None
    loader_workers: int = 2
    micro_batches: int = 1
    step: str = "eager"

    def validate(self) -> TrainConfig:
        """This config, checked: one UserError naming the first field out of its range."""
        if not isinstance(self.epochs, int) or self.epochs < 0:
            raise UserError(f"epochs must be a whole number >= 0, got {self.epochs}")
        if not isinstance(self.batch_size, int) or self.batch_size < 1:
            raise UserError(f"batch_size must be at least 1, got {self.batch_size}")
        check_seed(self.seed)
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
        if not (self.code_smoothness >= 0 and math.isfinite(self.code_smoothness)):
            raise UserError(f"code_smoothness must be a finite number >= 0, got {self.code_smoothness}")
        if self.vision_frames is not None and (not isinstance(self.vision_frames, int) or self.vision_frames < 1):
            raise UserError(
                f"vision_frames must be a whole number >= 1 (or None: every frame), got {self.vision_frames}"
            )
        if self.loss_reduction not in LOSS_REDUCTIONS:
            raise UserError(f"loss_reduction must be 'mean', 'sum' or 'precision', got {self.loss_reduction!r}")
        if self.motor_weight == 0 and self.vision_weight == 0:
            raise UserError("motor_weight and vision_weight are both 0: nothing to train")
        if self.checkpoint_every is not None and (
            not isinstance(self.checkpoint_every, int) or self.checkpoint_every < 1
        ):
            raise UserError(f"checkpoint_every must be at least 1, got {self.checkpoint_every}")
        if not (isinstance(self.checkpoint_seconds, (int, float)) and self.checkpoint_seconds >= 0):
            raise UserError(f"checkpoint_seconds must be a number >= 0, got {self.checkpoint_seconds}")
        if self.threads is not None and (not isinstance(self.threads, int) or self.threads < 1):
            raise UserError(f"threads must be at least 1, got {self.threads}")
        self._validate_scale()
        resolve_device(self.device, self.amp)
        return self

    def _validate_scale(self) -> None:
        """The fields of streaming and data-parallel training."""
        if self.stream_frames is not None and not isinstance(self.stream_frames, bool):
            raise UserError(f"stream_frames must be True, False or None (automatic), got {self.stream_frames!r}")
        budget = self.frames_memory_gb
        if budget is not None and not (isinstance(budget, (int, float)) and math.isfinite(budget) and budget > 0):
            raise UserError(f"frames_memory_gb must be a number > 0 (or None: half of the memory), got {budget}")
        if not isinstance(self.loader_workers, int) or isinstance(self.loader_workers, bool) or self.loader_workers < 0:
            raise UserError(f"loader_workers must be a whole number >= 0, got {self.loader_workers}")
        if not isinstance(self.micro_batches, int) or isinstance(self.micro_batches, bool) or self.micro_batches < 1:
            raise UserError(f"micro_batches must be a whole number >= 1, got {self.micro_batches}")
        if self.optimizer not in OPTIMIZERS:
            raise UserError(f"optimizer must be one of {', '.join(OPTIMIZERS)}, got {self.optimizer!r}")
        if self.step not in STEPS:
            raise UserError(f"step must be one of {', '.join(STEPS)}, got {self.step!r}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> TrainConfig:
        return config_from_dict(cls, d, "train config")


def lr_factor(epoch: int, epochs: int, final_fraction: float) -> float:
    """Cosine factor of the learning rates in epoch ``epoch`` (0-based) of ``epochs``: 1 → ``final_fraction``."""
    if final_fraction >= 1.0 or epochs <= 1:
        return 1.0
    progress = min(epoch, epochs - 1) / (epochs - 1)
    return final_fraction + (1.0 - final_fraction) * 0.5 * (1.0 + math.cos(math.pi * progress))


def resolve_device(device: str = "auto", amp: bool = False) -> torch.device:  # noqa: F821
    """``auto`` -> CUDA when available, else CPU. Raises :class:`UserError` for a device
    that is not there, or ``amp`` off CUDA."""
    import torch

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


@contextlib.contextmanager
def thread_limit(threads: int | None) -> Iterator[None]:
    """Run the body with ``threads`` CPU threads for torch's intra-op pool
    (``torch.set_num_threads``) and for numpy's BLAS (``threadpoolctl``), then put both
    back as they were: what :func:`~primspace.train.fit` and :func:`~primspace.train.infer`
    do with ``TrainConfig.threads``, so the library leaves no process-wide change behind.
    None: leave both as they are.
    """
    if threads is None:
        yield
        return
    import torch
    from threadpoolctl import threadpool_limits

    before = torch.get_num_threads()
    try:
        if before != threads:
            torch.set_num_threads(threads)
        with threadpool_limits(limits=threads, user_api="blas"):
            yield
    finally:
        if torch.get_num_threads() != before:
            torch.set_num_threads(before)


def configure_process(tc: TrainConfig) -> None:
    """Apply the process-wide settings of ``tc``: the CPU thread count of torch and of
    numpy's BLAS (``threads``), glibc's heap thresholds on a CPU device (``tune_malloc``)
    and cuDNN's kernel autotuning on CUDA.

    The library never changes process-wide state itself (``fit`` and ``infer`` limit
    the threads only while they run, :func:`thread_limit`): entry points call this (the
    ``primspace`` command's train / infer, an experiment's worker job) before training.
    """
    import torch
    from threadpoolctl import threadpool_limits

    device = resolve_device(tc.device, tc.amp)
    if tc.threads is not None:
        if torch.get_num_threads() != tc.threads:
            torch.set_num_threads(tc.threads)
        threadpool_limits(limits=tc.threads, user_api="blas")
    if device.type == "cuda":
        torch.backends.cudnn.benchmark = True  # fixed shapes: let cuDNN pick the fastest kernels
    elif tc.tune_malloc:
        _tune_malloc()


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
