"""Camera frames streamed from the data file while training, not loaded first.

``DataTensors.build`` holds every frame of a data set in memory (the paper preset's 1715
demonstrations take about 1 GB; 100,000 demonstrations at 48x64 and T = 61 take 56 GB).
With streaming (:class:`~primspace.train.TrainConfig` ``stream_frames``) the training
loop hands each batch part's samples and drawn frame steps to a
``torch.utils.data.DataLoader`` and receives their frames, read and decoded from the
HDF5 file by worker processes (``loader_workers``; 0: the training process reads them
between steps). Motor, masks and codes stay in memory.

What keeps the numbers identical to the in-memory path, bit for bit:

- the loop draws the batch order and the frame steps exactly as before (the same
  generators, the same calls, in the same order), the whole epoch's draws before the
  epoch, so the loader knows every batch in advance and its workers read ahead;
- a worker returns the stored ``uint8`` frames of those samples at those steps, the
  bytes the in-memory path gathers (:func:`primspace.train.loss.batch_frames`); the loss
  converts both alike;
- batches come back in the order asked (the loader's ``in_order``).

Workers are forked from a ``forkserver`` (a fresh process that has opened no file) and
open the file themselves (through :class:`~primspace.data.images.LazyImages`, which
pickles only its path and sample index): an HDF5 handle opened by the training process
is never used across a ``fork``. They live as long as the training session
(``persistent_workers``). As with any ``spawn`` or ``forkserver`` start, a script that
trains with loader workers must guard its top level with ``if __name__ == "__main__":``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Iterator

import numpy as np
import torch

from primspace.data import MotionDataset
from primspace.data.images import LazyImages
from primspace.utils.errors import DataError

__all__ = ["FrameReader", "FrameStream", "frames_bytes", "memory_budget", "should_stream"]

#: The share of the device's memory the frames may take when ``frames_memory_gb`` is None.
DEFAULT_BUDGET_FRACTION = 0.5

#: The fewest samples of a loader item when workers read (:meth:`FrameStream.batches`).
CHUNK = 8


def frames_bytes(data: MotionDataset) -> int:
    """The bytes of every frame of ``data`` as ``uint8`` (what loading them takes)."""
    return 0 if data.images is None else int(np.prod(data.images.shape, dtype=np.int64))


def memory_budget(tc, device: torch.device) -> float:
    """Bytes the frames may take in memory: ``tc.frames_memory_gb``, else half of the
    device's memory (the host's RAM on the CPU, the GPU's on CUDA)."""
    if tc.frames_memory_gb is not None:
        return float(tc.frames_memory_gb) * 1e9
    if device.type == "cuda":
        total = torch.cuda.get_device_properties(device).total_memory
    else:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    return DEFAULT_BUDGET_FRACTION * total


def should_stream(tc, data: MotionDataset, use_images: bool, device: torch.device, sharing: int = 1) -> bool:
    """Whether a session streams its frames (``tc.stream_frames``; None: when they would
    not fit :func:`memory_budget`).

    ``sharing``: the processes of one machine that would each load them (data-parallel
    processes on the CPU share the host's memory). Only frames stored in a data file are
    streamed: frames already held in memory (a data set made in memory, or after
    ``load_images``) are used as they are, whatever ``stream_frames`` says (an inference
    inherits its trained run's setting, and may be given such a data set).
    """
    from_file = isinstance(data.images, LazyImages) and data.images.path is not None
    if not use_images or not from_file or tc.stream_frames is False:
        return False
    if tc.stream_frames is None:
        return frames_bytes(data) * (sharing if device.type == "cpu" else 1) > memory_budget(tc, device)
    return True


def _worker_context():
    """The ``forkserver`` start method, its server importing this module first.

    The server is a fresh process that opens no file: workers forked from it start
    without any HDF5 state of the training process, yet without importing torch anew
    each (as ``spawn`` would: about a second per worker and session). Where there is no
    ``forkserver`` (not POSIX), ``spawn``.
    """
    import multiprocessing

    try:
        context = multiprocessing.get_context("forkserver")
    except ValueError:
        return multiprocessing.get_context("spawn")
    context.set_forkserver_preload([__name__])
    return context


class FrameReader(torch.utils.data.Dataset):
    """What a loader worker runs: the frames of one batch part, read from the file.

    A key is ``(rows, steps)``: the part's rows of the data set (int64) and, with
    ``vision_frames``, the drawn steps of each (``(b, K)``; None: every step). The item
    is ``(frames, seconds)``: the ``uint8`` frames ``(b, K or T, H, W, 3)`` and the time
    spent reading and decoding them.

    Samples are read one by one: h5py reads a list of samples from the per-sample gzip
    chunks about 20 times slower per sample than one sample at a time (measured on the
    demo preset's file: 150-180 ms against 5-8 ms), and a shuffled batch is such a list.
    """

    def __init__(self, images: LazyImages) -> None:
        self.images = images

    def __getitem__(self, key: tuple[np.ndarray, np.ndarray | None]):
        rows, steps = key
        start = time.perf_counter()
        out = np.empty(
            (len(rows), self.images.shape[1] if steps is None else steps.shape[1]) + self.images.shape[2:],
            dtype=np.uint8,
        )
        try:
            for j, row in enumerate(rows):  # one sample at a time: see the class docstring
                frames = self.images[int(row)]
                out[j] = frames if steps is None else frames[steps[j]]
        except DataError as exc:  # returned, not raised: the loader would bury its message in a traceback
            return str(exc), 0.0
        return torch.from_numpy(out), time.perf_counter() - start


class _Keys:
    """The loader's sampler: the keys of the batch parts asked for next (set per pass)."""

    def __init__(self) -> None:
        self.keys: list = []

    def __iter__(self):
        return iter(self.keys)

    def __len__(self) -> int:
        return len(self.keys)


class FrameStream:
    """Batch parts' frames from the data file, in the order asked (:class:`FrameReader`).

    Parameters
    ----------
    images : LazyImages
        The frames of the session's samples (a view of the file).
    workers : int
        Loader worker processes (0: read in this process).
    device : torch.device
        Where the frames go (pinned host memory first, for CUDA).

    Attributes
    ----------
    waited, decoded : float
        Seconds the training process waited for frames, and the workers' seconds of
        reading and decoding them, summed since the stream was made.
    samples, nbytes : int
        Samples and frame bytes delivered so far.
    """

    def __init__(self, images: LazyImages, workers: int, device: torch.device) -> None:
        self.device = device
        self._keys = _Keys()
        self.loader = torch.utils.data.DataLoader(
            FrameReader(images),
            batch_size=None,
            sampler=self._keys,
            num_workers=workers,
            persistent_workers=workers > 0,
            multiprocessing_context=_worker_context() if workers > 0 else None,
            pin_memory=device.type == "cuda",
        )
        self.waited = self.decoded = 0.0
        self.samples = self.nbytes = 0

    def batches(self, keys: Iterable[tuple[torch.Tensor, torch.Tensor | None]]) -> Iterator[torch.Tensor]:
        """The frames of each ``(rows, steps)`` in ``keys``, in that order, on the device.

        With workers, each key is read in one chunk per worker (of at least
        :data:`CHUNK` samples), so that they decode a batch together: its wait is about
        one chunk's decoding, and the loader's read-ahead (two items per worker) stays
        two batches deep.
        """
        keys = [(rows.cpu().numpy(), None if steps is None else steps.cpu().numpy()) for rows, steps in keys]
        workers = max(self.loader.num_workers, 1)
        sizes = [max(-(-len(rows) // workers), CHUNK if workers > 1 else len(rows), 1) for rows, _ in keys]
        counts = [len(range(0, max(len(rows), 1), size)) for (rows, _), size in zip(keys, sizes)]
        self._keys.keys = [
            (rows[i : i + size], None if steps is None else steps[i : i + size])
            for (rows, steps), size in zip(keys, sizes)
            for i in range(0, max(len(rows), 1), size)
        ]
        it = iter(self.loader)  # a pass over the keys (persistent workers carry on from the last pass)
        for count in counts:
            start = time.perf_counter()
            pieces = []
            for _ in range(count):
                frames, seconds = next(it)
                if isinstance(frames, str):
                    raise DataError(frames)
                pieces.append(frames.to(self.device, non_blocking=True))
                self.decoded += seconds
            frames = pieces[0] if count == 1 else torch.cat(pieces)
            self.waited += time.perf_counter() - start
            self.samples += frames.shape[0]
            self.nbytes += frames.numel()
            yield frames

    def close(self) -> None:
        """Stop the worker processes."""
        it = getattr(self.loader, "_iterator", None)
        if it is not None and hasattr(it, "_shutdown_workers"):
            it._shutdown_workers()
        self.loader._iterator = None
