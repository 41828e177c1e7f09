"""One model trained by several processes: data parallelism on ``torch.distributed``.

Launched by ``torchrun --nproc-per-node G -m primspace train ...`` (or by Ray's
``TorchTrainer``, or any launcher that starts a process group), the same
:func:`~primspace.train.fit` runs in every process; :class:`World` says where the
process stands and does its few collective operations. How a batch is shared:

- **One global batch order.** Every process draws the epoch's order and the frame steps
  of ``vision_frames`` from the same generators as a single process would, whatever the
  number of processes: the batches of an epoch are the single process's batches. Each
  batch is cut into ``size x micro_batches`` contiguous parts whose sizes differ by at
  most one (:func:`part_bounds`); process ``r`` computes parts ``r*M .. r*M + M - 1``.
  Nothing is padded and no sample is repeated (``DistributedSampler``, Ray's
  ``prepare_data_loader`` and ``accelerate`` pad the last batch with repeated samples,
  which would step those codes twice).
- **θ through DDP.** ``DistributedDataParallel`` averages the processes' gradients
  (sums them times ``1/size``); each part's loss (a mean over its ``b`` samples) is
  weighted by ``size * b / B``, so the averaged gradient is the gradient of the batch's
  mean loss. A process whose part is empty (a last batch smaller than the number of
  processes) still runs one forward and backward, on the batch's first sample with
  weight 0, so every process joins every gradient reduction: uneven batches never hang.
- **The codes replicated.** Every process holds the whole code table and its row-wise
  Adam state (:class:`~primspace.model.latent.LatentTable`); after each batch the parts' code
  gradients are gathered (``all_gather``, ``B x q`` numbers) and every process applies
  the same step to the batch's rows, so the tables stay identical without being sent.
  Why not a sharded table (SSDNeRF gives each rank a fixed range of scenes): a sample
  would then be bound to a process, so the batch order, and a resume on another number
  of processes, would depend on the number of processes. Nor ``nn.Embedding(sparse=True)``
  under DDP: its sparse gradients reduce on gloo only, and a dense Adam would move codes
  absent from the batch. The table is small (``N x q x 3`` floats: 77 MB at 100,000
  samples and q = 64).
- **One writer.** Process 0 alone opens the run directory, writes metrics and
  checkpoints, in the single-process format, and passes a checkpoint to resume from to
  the others (``broadcast_object_list``), so a run resumes on any number of processes.
- **Stopping together.** The epoch's loss sums are reduced before they are checked, so
  a divergence stops every process at the same epoch; an exception in one process ends
  it, and its launcher (torchrun, ``torch.multiprocessing.spawn``, Ray) stops the others.

With micro-batches in one process (``TrainConfig.micro_batches = G``) the parts are
computed one after another and their gradients summed: on the CPU, for G = 2 the same
numbers as two processes bit for bit (the weights scale each part's backward pass by a
power of two, and a sum of two addends does not depend on their order).
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from datetime import timedelta

import torch

from primspace.utils.errors import UserError

__all__ = ["World", "Part", "part_bounds", "current_world", "launched", "data_parallel"]


def part_bounds(n: int, parts: int) -> list[tuple[int, int]]:
    """``parts`` contiguous ``(start, stop)`` ranges of ``range(n)``, sizes differing by at most one (larger first)."""
    base, extra = divmod(n, parts)
    bounds, start = [], 0
    for p in range(parts):
        stop = start + base + (1 if p < extra else 0)
        bounds.append((start, stop))
        start = stop
    return bounds


@dataclass(frozen=True)
class Part:
    """One part of a batch that this process computes.

    ``rows``: its positions in the batch; ``weight``: the factor of its mean loss;
    ``code_scale``: the factor that turns its codes' gradients into each sample's own
    loss gradient; ``micro``: its index among the process's parts; ``dummy``: an empty
    part computed on the batch's first sample with weight 0 (a data-parallel process must
    join every gradient reduction).
    """

    rows: slice
    weight: float
    code_scale: float
    micro: int = 0
    dummy: bool = False

    @property
    def size(self) -> int:
        return 0 if self.dummy else self.rows.stop - self.rows.start


@dataclass(frozen=True)
class World:
    """Where this process stands among those that train one model (default: alone).

    Parameters
    ----------
    rank, size : int
        This process and the number of processes (``torch.distributed``'s).
    micro_batches : int
        Parts of a batch per process, computed one after another.
    local_size : int
        Processes on this machine (they share its memory).
    """

    rank: int = 0
    size: int = 1
    micro_batches: int = 1
    local_size: int = 1

    @property
    def distributed(self) -> bool:
        return self.size > 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    def parts(self, n: int, *, join: bool = False) -> list[Part]:
        """This process's parts of a batch of ``n`` samples (:func:`part_bounds`).

        ``join`` (θ trained by DDP, several processes): an empty part becomes a dummy, so
        that the process joins the batch's gradient reduction; otherwise it is left out.
        """
        m = self.micro_batches
        bounds = part_bounds(n, self.size * m)[self.rank * m : (self.rank + 1) * m]
        out = []
        for micro, (start, stop) in enumerate(bounds):
            if stop > start:
                out.append(Part(slice(start, stop), self.size * ((stop - start) / n), n / self.size, micro))
            elif join and self.distributed:
                out.append(Part(slice(0, 1), 0.0, 0.0, micro, dummy=True))
        return out

    def sum(self, tensor: torch.Tensor) -> torch.Tensor:
        """``tensor`` summed over the processes (in place; itself when alone)."""
        if self.distributed:
            torch.distributed.all_reduce(tensor)
        return tensor

    def gather_rows(self, local: torch.Tensor, n: int) -> torch.Tensor:
        """The rows of a batch of ``n``, each process holding those of its parts, in batch order."""
        if not self.distributed:
            return local
        m = self.micro_batches
        bounds = part_bounds(n, self.size * m)
        counts = [bounds[(r + 1) * m - 1][1] - bounds[r * m][0] for r in range(self.size)]
        padded = local.new_zeros((max(counts),) + tuple(local.shape[1:]))
        padded[: local.shape[0]] = local
        gathered = [torch.empty_like(padded) for _ in range(self.size)]
        torch.distributed.all_gather(gathered, padded)
        return torch.cat([g[:c] for g, c in zip(gathered, counts)])

    def from_main(self, fn):
        """``fn()`` run by process 0, its result handed to every process (pickled); an
        exception there is raised in every process (elsewhere as a :class:`UserError`
        with its message)."""
        if not self.distributed:
            return fn()
        box, error = [None], None
        if self.is_main:
            try:
                box[0] = ("ok", fn())
            except Exception as exc:  # re-raised below, after the others heard of it
                error = exc
                box[0] = ("error", f"{exc}" if isinstance(exc, UserError) else f"{type(exc).__name__}: {exc}")
        torch.distributed.broadcast_object_list(box, src=0)
        status, value = box[0]
        if error is not None:
            raise error
        if status == "error":
            raise UserError(value)
        return value

    def device(self, device: torch.device) -> torch.device:
        """The process's own GPU (``cuda:LOCAL_RANK``) for a CUDA device named without an index."""
        if self.distributed and device.type == "cuda" and device.index is None:
            return torch.device("cuda", torch.cuda.current_device())
        return device


def current_world(micro_batches: int = 1) -> World:
    """The :class:`World` of this process: the default process group's, when one is started."""
    dist = torch.distributed
    if not (dist.is_available() and dist.is_initialized()) or dist.get_world_size() == 1:
        return World(micro_batches=micro_batches)
    local = int(os.environ.get("LOCAL_WORLD_SIZE", dist.get_world_size()))
    return World(dist.get_rank(), dist.get_world_size(), micro_batches, local)


@contextlib.contextmanager
def launched(device: str = "auto", timeout_minutes: float = 30.0):
    """The process group a launcher asked for, for an entry point (the command line).

    ``torchrun`` (and Ray, and ``torch.multiprocessing`` with the same variables) set
    ``WORLD_SIZE``, ``RANK``, ``LOCAL_RANK``, ``MASTER_ADDR`` and ``MASTER_PORT``; with
    ``WORLD_SIZE`` above 1 this starts the default group, NCCL when ``device`` resolves
    to CUDA (each process on GPU ``LOCAL_RANK``), else gloo, and ends it on the way out.
    Nothing to do when there is one process or a group is already running (Ray's
    ``TorchTrainer`` starts its own). Yields this process's rank. Process-wide: called by
    entry points only.
    """
    from primspace.train.config import resolve_device

    dist = torch.distributed
    if int(os.environ.get("WORLD_SIZE", "1")) <= 1 or (dist.is_available() and dist.is_initialized()):
        yield dist.get_rank() if dist.is_available() and dist.is_initialized() else 0
        return
    dev = resolve_device(device)
    if dev.type == "cuda":
        torch.cuda.set_device(dev.index if dev.index is not None else int(os.environ.get("LOCAL_RANK", "0")))
    dist.init_process_group("nccl" if dev.type == "cuda" else "gloo", timeout=timedelta(minutes=timeout_minutes))
    try:
        yield dist.get_rank()
    finally:
        dist.destroy_process_group()


def data_parallel(model: torch.nn.Module, world: World, device: torch.device, unused: bool) -> torch.nn.Module:
    """``model`` wrapped for data-parallel training (itself when alone).

    ``unused``: some parameters get no gradient (an image head whose loss is not trained),
    so DDP must look for them every step (``find_unused_parameters``).
    """
    if not world.distributed:
        return model
    from torch.nn.parallel import DistributedDataParallel

    ids = [device.index] if device.type == "cuda" else None
    return DistributedDataParallel(model, device_ids=ids, find_unused_parameters=unused)  # (the decoder has no buffers)


def no_sync(model: torch.nn.Module, last: bool):
    """DDP's ``no_sync`` for every part but a batch's last (gradients reduced once per batch)."""
    if last or not hasattr(model, "no_sync"):
        return contextlib.nullcontext()
    return model.no_sync()
