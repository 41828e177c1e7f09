"""Camera frames of imported demonstrations: checked, aligned with the resampled joints, resized.

Alignment rule
--------------
The joints of a demonstration with ``T_i`` steps are resampled to ``T`` steps
(:func:`primspace.data.resample`), which places source step ``i`` at normalised time
``i / (T_i - 1)`` and output step ``k`` at ``k / (T - 1)``. A demonstration has one frame
per joint step (checked), frame ``i`` taken at the time of step ``i``. Output step ``k``
gets the recorded frame nearest to its time:

    i_k = floor(k (T_i - 1) / (T - 1) + 1/2)        (a tie goes to the later frame)

computed in integers, so it is exact. Frames are never blended: every stored frame is a
recorded one (resized); the first and last output steps get the first and last frames;
when ``T > T_i`` a frame repeats, when ``T < T_i`` frames are skipped.

Resizing
--------
Each selected frame is resized to ``(H, W)`` (default 48x64, the decoder's usual frame
size) with Pillow's Lanczos filter, which low-pass filters when shrinking (no aliasing),
and rounded to uint8. A frame of another aspect ratio is stretched, not cropped (nothing
of the scene is lost). A frame already ``(H, W)`` is kept bit for bit. Only the distinct
frames that the alignment selects are decoded and resized.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from primspace.errors import DataError, UserError

__all__ = ["DEFAULT_IMAGE_SIZE", "frame_steps", "check_frames", "resize_frames", "as_image_size", "AlignedFrames"]

#: (H, W) of imported frames unless asked otherwise: the simulator's and the decoder's usual size.
DEFAULT_IMAGE_SIZE = (48, 64)


def frame_steps(n_frames: int, length: int) -> np.ndarray:
    """For each of ``length`` resampled steps, the index of the nearest of ``n_frames`` frames.

    Examples
    --------
    >>> frame_steps(5, 3).tolist()
    [0, 2, 4]
    >>> frame_steps(3, 5).tolist()
    [0, 1, 1, 2, 2]
    """
    k = np.arange(int(length), dtype=np.int64)
    span = int(n_frames) - 1
    if length < 2 or span <= 0:
        return np.zeros(int(length), dtype=np.int64)
    return (2 * k * span + (length - 1)) // (2 * (length - 1))


def check_frames(frames, n_steps: int, *, path=None, field: str, index: int) -> None:
    """Refuse frames that are not ``(n_steps, H, W, 3)`` uint8, without reading them.

    ``frames`` is anything with ``shape`` and ``dtype`` (an array, an ``h5py.Dataset``).

    Raises
    ------
    DataError
        Naming the file, the field (the source's key) and the demonstration's index.
    """
    shape, dtype = tuple(frames.shape), np.dtype(frames.dtype)

    def fail(message: str) -> DataError:
        return DataError(message, path=path, field=field, index=index)

    if len(shape) != 4:
        raise fail(f"frames must be (T_i, H, W, 3), got rank {len(shape)} {shape}")
    if shape[3] != 3:
        raise fail(f"frames must have 3 colour channels (RGB), got {shape[3]} in shape {shape}")
    if dtype != np.uint8:
        raise fail(f"frames must be uint8, got {dtype}")
    if shape[0] != n_steps:
        raise fail(f"{shape[0]} frames for {n_steps} joint steps (one frame per step is needed)")
    if shape[1] < 1 or shape[2] < 1:
        raise fail(f"frames are empty, shape {shape}")


def resize_frames(frames: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``(n, h, w, 3)`` uint8 frames as ``(n, H, W, 3)`` uint8: Pillow's Lanczos filter."""
    from PIL import Image

    frames = np.asarray(frames, dtype=np.uint8)
    height, width = size
    if frames.shape[1:3] == (height, width):
        return frames.copy()
    out = np.empty((frames.shape[0], height, width, 3), dtype=np.uint8)
    for i, frame in enumerate(frames):
        image = Image.fromarray(np.ascontiguousarray(frame))
        out[i] = np.asarray(image.resize((width, height), Image.Resampling.LANCZOS))
    return out


def as_image_size(size: Sequence[int]) -> tuple[int, int]:
    """``(H, W)`` as two positive ints; :class:`UserError` otherwise."""
    try:
        height, width = (int(s) for s in size)
        ok = all(int(s) == s for s in size)
    except (TypeError, ValueError):
        height = width = 0
        ok = False
    if not ok or height < 1 or width < 1:
        raise UserError(f"image_size must be two positive whole numbers (H, W), got {size!r}")
    return height, width


class AlignedFrames:
    """Each demonstration's frames at the resampled steps, resized; their source sizes.

    Parameters
    ----------
    length : int
        T, the resampled steps.
    size : (H, W)
        The stored frame size.
    """

    def __init__(self, length: int, size: Sequence[int]) -> None:
        self.length = int(length)
        self.size = as_image_size(size)
        self.frames: list[np.ndarray] = []
        self.source_sizes: list[tuple[int, int]] = []

    def add(self, n_frames: int, read: Callable[[np.ndarray], np.ndarray]) -> None:
        """Add one demonstration of ``n_frames`` frames.

        ``read(indices)`` returns the frames at ``indices`` (sorted, distinct) as
        ``(len(indices), h, w, 3)`` uint8; it is called once.
        """
        wanted, where = np.unique(frame_steps(n_frames, self.length), return_inverse=True)
        picked = np.asarray(read(wanted))
        self.source_sizes.append((int(picked.shape[1]), int(picked.shape[2])))
        self.frames.append(resize_frames(picked, self.size)[where.reshape(-1)])

    def stack(self) -> np.ndarray:
        """The data set's images, ``(N, T, H, W, 3)`` uint8."""
        return np.stack(self.frames)

    def describe(self) -> str:
        """For the data set's ``source`` text: ``frames 84x84 -> 48x64`` (each source size once)."""
        sizes = list(dict.fromkeys(self.source_sizes))
        shown = ", ".join(f"{h}x{w}" for h, w in sizes[:4]) + (", ..." if len(sizes) > 4 else "")
        return f"frames {shown} -> {self.size[0]}x{self.size[1]}"
