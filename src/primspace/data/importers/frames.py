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
and rounded to uint8. A frame already ``(H, W)`` is kept bit for bit. Only the distinct
frames that the alignment selects are decoded and resized.

Image fit
---------
A frame of another aspect ratio (robomimic's 84x84 into 48x64) is fitted by ``fit``:

``crop`` (default)
    Keep the aspect ratio: cut the centre region of the target's aspect ratio (the
    larger side trimmed equally on both ends, the odd pixel at the far end), then resize.
    The scene's edges are lost; nothing is distorted.
``pad``
    Keep the aspect ratio and the whole scene: add black bars (zeros) equally on both
    ends of the smaller side to the target's aspect ratio, then resize.
``stretch``
    Resize to ``(H, W)`` directly: the whole scene, distorted.

The choice and the sizes are written into the data set's ``source`` text
(``frames 84x84 -> 48x64 (centre crop)``), which ``primspace info`` shows.

Decoding shows a progress bar (on a terminal) while the frames of every demonstration
are read: :meth:`AlignedFrames.collect`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from primspace.utils.errors import DataError, UserError

__all__ = [
    "DEFAULT_IMAGE_SIZE",
    "IMAGE_FITS",
    "frame_steps",
    "check_frames",
    "resize_frames",
    "fit_box",
    "as_image_size",
    "as_image_fit",
    "AlignedFrames",
]

#: (H, W) of imported frames unless asked otherwise: the simulator's and the decoder's usual size.
DEFAULT_IMAGE_SIZE = (48, 64)
#: How a frame of another aspect ratio is fitted (the first is the default), and how ``source`` says so.
IMAGE_FITS = {"crop": "centre crop", "pad": "padded", "stretch": "stretched"}


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


def fit_box(source: tuple[int, int], size: tuple[int, int], fit: str) -> tuple[int, int, int, int]:
    """The region ``(top, left, height, width)`` of a ``source`` ``(h, w)`` frame that is
    resized to ``size`` ``(H, W)``: the centre crop of the target's aspect ratio (``crop``),
    the frame inside black bars (``pad``: a negative top or left, a region larger than the
    frame) or the whole frame (``stretch``, or the same aspect ratio).

    Examples
    --------
    >>> fit_box((84, 84), (48, 64), "crop")
    (10, 0, 63, 84)
    >>> fit_box((84, 84), (48, 64), "pad")
    (0, -14, 84, 112)
    >>> fit_box((96, 128), (48, 64), "crop")
    (0, 0, 96, 128)
    """
    h, w = source
    height, width = size
    if fit == "stretch" or h * width == w * height:
        return 0, 0, h, w
    wide = w * height > h * width  # the source is wider than the target
    if (fit == "crop") == wide:  # crop a wide frame's width, or pad a tall frame's width
        new_w = max(1, round(h * width / height))
        return 0, (w - new_w) // 2, h, new_w
    new_h = max(1, round(w * height / width))
    return (h - new_h) // 2, 0, new_h, w


def resize_frames(frames: np.ndarray, size: tuple[int, int], fit: str = "crop") -> np.ndarray:
    """``(n, h, w, 3)`` uint8 frames as ``(n, H, W, 3)`` uint8: the region of :func:`fit_box`,
    resized with Pillow's Lanczos filter (a frame already ``(H, W)`` is copied bit for bit)."""
    from PIL import Image

    frames = np.asarray(frames, dtype=np.uint8)
    height, width = size
    if frames.shape[1:3] == (height, width):
        return frames.copy()
    top, left, box_h, box_w = fit_box(frames.shape[1:3], size, fit)
    if top < 0 or left < 0:  # pad: the frame centred in black bars
        padded = np.zeros((frames.shape[0], box_h, box_w, 3), dtype=np.uint8)
        padded[:, -top : -top + frames.shape[1], -left : -left + frames.shape[2]] = frames
        frames, top, left = padded, 0, 0
    frames = frames[:, top : top + box_h, left : left + box_w]
    out = np.empty((frames.shape[0], height, width, 3), dtype=np.uint8)
    for i, frame in enumerate(frames):
        image = Image.fromarray(np.ascontiguousarray(frame))
        out[i] = np.asarray(image.resize((width, height), Image.Resampling.LANCZOS))
    return out


def as_image_fit(fit: str) -> str:
    """``fit`` if it is one of :data:`IMAGE_FITS`; :class:`UserError` otherwise."""
    if fit not in IMAGE_FITS:
        raise UserError(f"image fit {fit!r} is not one of {', '.join(IMAGE_FITS)}")
    return fit


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
    """Each demonstration's frames at the resampled steps, fitted and resized; their source sizes.

    Demonstrations are added with :meth:`add` (nothing is read then) and decoded by
    :meth:`collect`, once, under a progress bar; :meth:`stack` collects if needed. An
    importer whose reads need an open file calls :meth:`collect` before closing it.

    Parameters
    ----------
    length : int
        T, the resampled steps.
    size : (H, W)
        The stored frame size.
    fit : {"crop", "pad", "stretch"}
        How a frame of another aspect ratio is fitted (module docstring).
    """

    def __init__(self, length: int, size: Sequence[int], fit: str = "crop") -> None:
        self.length = int(length)
        self.size = as_image_size(size)
        self.fit = as_image_fit(fit)
        self.frames: list[np.ndarray] = []
        self.source_sizes: list[tuple[int, int]] = []
        self._pending: list[tuple[int, Callable[[np.ndarray], np.ndarray]]] = []

    def add(self, n_frames: int, read: Callable[[np.ndarray], np.ndarray]) -> None:
        """Add one demonstration of ``n_frames`` frames.

        ``read(indices)`` returns the frames at ``indices`` (sorted, distinct) as
        ``(len(indices), h, w, 3)`` uint8; it is called once, by :meth:`collect`.
        """
        self._pending.append((int(n_frames), read))

    def collect(self) -> AlignedFrames:
        """Read, fit and resize the frames of every demonstration added (a progress bar on a terminal)."""
        from primspace.utils.progress import progress_bar

        pending, self._pending = self._pending, []
        with progress_bar(len(pending), "decoding frames") as advance:
            for n_frames, read in pending:
                wanted, where = np.unique(frame_steps(n_frames, self.length), return_inverse=True)
                picked = np.asarray(read(wanted))
                self.source_sizes.append((int(picked.shape[1]), int(picked.shape[2])))
                self.frames.append(resize_frames(picked, self.size, self.fit)[where.reshape(-1)])
                advance()
        return self

    def stack(self) -> np.ndarray:
        """The data set's images, ``(N, T, H, W, 3)`` uint8."""
        return np.stack(self.collect().frames)

    def describe(self) -> str:
        """For the data set's ``source`` text: ``frames 84x84 -> 48x64 (centre crop)`` (each
        source size once; the fit named only where a source size has another aspect ratio)."""
        sizes = list(dict.fromkeys(self.source_sizes))
        shown = ", ".join(f"{h}x{w}" for h, w in sizes[:4]) + (", ..." if len(sizes) > 4 else "")
        height, width = self.size
        other = any(h * width != w * height for h, w in sizes)
        return f"frames {shown} -> {height}x{width}" + (f" ({IMAGE_FITS[self.fit]})" if other else "")
