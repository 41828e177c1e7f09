"""Import a folder of padded NumPy arrays (EIPL-style lab data): ``joints.npy`` and friends.

The layout::

    demos/
        joints.npy    (N, Tmax, J)        numbers, each sample padded to Tmax   required
        images.npy    (N, Tmax, H, W, 3)  uint8 RGB, one frame per joint step   optional
        lengths.npy   (N,)                integers 2 .. Tmax, the valid steps   optional
        labels.npy    (N,)                integers (-1 unknown) or strings      optional

Nothing else in the folder is read (``primspace import demos/ --format npy``; a folder
holding ``joints.npy`` is guessed to be one: :func:`looks_like_npy_folder`).

Padding
-------
With ``lengths.npy``, sample ``i`` is its first ``lengths[i]`` steps. Without it, the
trailing steps of a sample that repeat its last value **exactly** (all joints; the frames
do not decide) are padding: sample ``i`` keeps the smallest ``L`` steps such that every
later step equals step ``L - 1``, at least 2. A demonstration that genuinely holds still
at its end is therefore trimmed to its last moving step + 1; ``keep_padding=True``
(``--keep-padding``) keeps all ``Tmax`` steps of every sample instead
(:mod:`~primspace.data.importers.padding`). The frames of the trimmed steps are dropped
with them. The data set's ``source`` text says how many samples were trimmed
(``npy:demos images=images.npy; frames 64x64 -> 48x64 (centre crop); padding trimmed
in 3 of 5 samples``).

The rest as in the other importers: each sample resampled to ``length`` steps; frames
aligned with the resampled joints, fitted (``image_fit``) and resized
(:mod:`~primspace.data.importers.frames`); ``dt`` is 1 (unknown); joint names ``j0, ...``;
string labels become label names (sorted). Each sample's ``source_ids`` entry is
``npy:<folder name>:<i>``.

The arrays are opened as memory maps, without pickle (``np.load(mmap_mode="r",
allow_pickle=False)``): only the frames the alignment selects are read. An object array, a
file that is not a ``.npy`` array, a wrong rank or type, and frames whose count or steps
differ from the joints' are refused with one line naming the file, the array and, where it
applies, the sample.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from tokenize import TokenError

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import check_fits_memory, demonstrations, parse_labels, printable
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames, as_image_fit
from primspace.data.importers.padding import checked_lengths, padded_lengths, padding_note
from primspace.utils.errors import DataError, first_line

__all__ = ["import_npy_folder", "looks_like_npy_folder", "checked_text", "NPY_FILES"]

#: The arrays the folder may hold (``<name>.npy``); only ``joints`` is required.
NPY_FILES = ("joints", "images", "lengths", "labels")
_NPY_MAGIC = b"\x93NUMPY"


def import_npy_folder(
    path: str | os.PathLike,
    length: int,
    *,
    image_size=DEFAULT_IMAGE_SIZE,
    image_fit: str = "crop",
    keep_padding: bool = False,
) -> MotionDataset:
    """Read padded joints (and frames, lengths, labels) from a folder of ``.npy`` files (module docstring).

    Parameters
    ----------
    path : path-like
        The folder holding ``joints.npy``.
    length : int
        T, the steps to resample each sample to.
    image_size : (H, W)
        Size of the stored frames, when the folder has ``images.npy``.
    image_fit : {"crop", "pad", "stretch"}
        How a frame of another aspect ratio is fitted (:mod:`~primspace.data.importers.frames`).
    keep_padding : bool, default False
        Keep the trailing steps that repeat each sample's last value (ignored with ``lengths.npy``).

    Raises
    ------
    DataError
        Naming the file, the array (``joints``, ``images`` ...) and the sample.
    """
    root = Path(path)
    image_fit = as_image_fit(image_fit)
    if not root.is_dir():
        raise DataError(
            "no such folder" if not root.exists() else "is not a folder (a folder holding joints.npy is needed)",
            path=root,
        )
    joints = _joints(root)
    n, t_max = joints.shape[:2]
    images = _images(root, n, t_max)
    lengths, note = _lengths(root, joints, keep_padding)
    labels = _load(root, "labels")
    labels, label_names = (None, None) if labels is None else _labels(root, labels, n)
    sequences = [np.asarray(joints[i, :t]) for i, t in enumerate(lengths)]
    frames = None
    if images is not None:
        frames = AlignedFrames(length, image_size, image_fit)
        for i, t in enumerate(lengths):
            frames.add(int(t), lambda idx, i=i: _read_frames(root, images, i, idx))
    name = root.resolve().name
    try:
        ds = demonstrations(
            sequences,
            length,
            frames,
            source=f"npy:{name}",
            images="images.npy",
            dt_in=1.0,
            where=root,
            labels=labels,
            label_names=label_names,
            source_ids=[f"npy:{printable(name)}:{i}" for i in range(n)],
        )
        ds.source += note
        return ds
    except DataError as exc:  # name the file and array the field came from
        array = {"motor": "joints", "labels": "labels", "images": "images"}.get(exc.field)
        if array is None:
            raise
        raise DataError(exc.reason, path=root / f"{array}.npy", field=array, index=exc.index) from None


def looks_like_npy_folder(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a folder holding ``joints.npy`` (for guessing the format)."""
    path = Path(path)
    return path.is_dir() and (path / "joints.npy").is_file()


def _load(root: Path, name: str, required: bool = False):
    """``<root>/<name>.npy`` as a read-only memory map (None if absent and not ``required``)."""
    file = root / f"{name}.npy"
    if not file.exists():
        if not required:
            return None
        try:
            there = ", ".join(sorted(printable(p.name) for p in root.iterdir())[:12]) or "nothing"
        except OSError:
            there = "(cannot be listed)"
        raise DataError(
            f"no {name}.npy in the folder (an npy folder holds joints.npy (N, Tmax, J), and optionally "
            f"{', '.join(f + '.npy' for f in NPY_FILES[1:])}); it has: {there}",
            path=root,
            field=name,
        )
    if not file.is_file():
        raise DataError("is not a file", path=file, field=name)
    try:
        with open(file, "rb") as fh:
            magic = fh.read(len(_NPY_MAGIC))
    except OSError as exc:
        raise DataError(f"cannot be read ({first_line(exc)})", path=file, field=name) from None
    if magic != _NPY_MAGIC:
        what = "an .npz archive" if magic.startswith(b"PK") else "not a .npy array"
        raise DataError(f"is {what} (np.save writes a .npy array)", path=file, field=name)
    try:
        return np.load(file, mmap_mode="r", allow_pickle=False)
    except (ValueError, SyntaxError, TokenError, TypeError, OverflowError) as exc:  # a damaged header
        raise DataError(_unreadable(exc), path=file, field=name) from None
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(
            f"cannot be read, the file may be truncated or damaged ({first_line(exc)})", path=file, field=name
        ) from None
    except MemoryError:
        raise DataError("declares an array too large to read into memory", path=file, field=name) from None


def _unreadable(exc: Exception) -> str:
    """Why ``np.load`` could not open a ``.npy`` file, for the message."""
    text = str(exc).lower()
    if "object" in text:
        return "holds Python objects (an object array needs pickle, which is never enabled; save numbers or strings)"
    if "mmap length" in text:
        return "cannot be read, the file is shorter than the array its header declares (truncated or damaged)"
    return f"is not a readable .npy array ({first_line(exc)})"


def _joints(root: Path) -> np.ndarray:
    """``joints.npy``: ``(N, Tmax, J)`` numbers, N and Tmax at least 1, small enough to read."""
    joints, file = _load(root, "joints", required=True), root / "joints.npy"
    if joints.ndim != 3 or joints.dtype.kind not in "fiu":
        raise DataError(f"must be (N, Tmax, J) numbers, got {joints.dtype} {joints.shape}", path=file, field="joints")
    if joints.shape[0] == 0 or joints.shape[1] == 0:
        raise DataError(f"holds no samples or no steps, shape {joints.shape}", path=file, field="joints")
    check_fits_memory(joints.nbytes, f"joints.npy {joints.shape} {joints.dtype}", path=file, field="joints")
    return joints


def _images(root: Path, n: int, t_max: int):
    """``images.npy``, ``(N, Tmax, H, W, 3)`` uint8 matching the joints (None if absent); not read here."""
    images, file = _load(root, "images"), root / "images.npy"
    if images is None:
        return None

    def fail(why: str, index: int | None = None) -> DataError:
        return DataError(why, path=file, field="images", index=index)

    if images.ndim != 5 or images.shape[4] != 3:
        raise fail(f"must be (N, Tmax, H, W, 3) RGB frames, got shape {images.shape}")
    if images.dtype != np.uint8:
        raise fail(f"frames must be uint8, got {images.dtype}")
    if images.shape[0] != n:
        raise fail(
            f"holds the frames of {images.shape[0]} samples, joints.npy {n} samples (one frame per "
            "joint step is needed)",
            min(images.shape[0], n),
        )  # the first sample without a partner
    if images.shape[1] != t_max:
        raise fail(f"holds {images.shape[1]} frames per sample for {t_max} joint steps (one frame per step is needed)")
    if images.shape[2] < 1 or images.shape[3] < 1:
        raise fail(f"frames are empty, shape {images.shape}")
    return images


def _lengths(root: Path, joints: np.ndarray, keep_padding: bool) -> tuple[np.ndarray, str]:
    """Each sample's valid steps: ``lengths.npy`` (checked), else the padding rule; and the source note."""
    n, t_max = joints.shape[:2]
    given = _load(root, "lengths")
    if given is not None:
        return checked_lengths(np.asarray(given), n, t_max, path=root / "lengths.npy"), ""
    if keep_padding:
        return np.full(n, t_max, dtype=np.int64), ""
    lengths = padded_lengths(joints)
    return lengths, padding_note(lengths, t_max)


def _labels(root: Path, labels, n: int):
    """``labels.npy`` as label indices and names (:func:`parse_labels`), located at its file."""
    file = root / "labels.npy"
    if labels.ndim != 1:
        raise DataError(f"must be one label per sample, shape ({n},), got {labels.shape}", path=file, field="labels")
    check_fits_memory(labels.nbytes, f"labels.npy {labels.shape} {labels.dtype}", path=file, field="labels")
    labels = checked_text(labels, path=file, field="labels") if labels.dtype.kind in "SU" else np.asarray(labels)
    try:
        return parse_labels(labels, None, n)
    except DataError as exc:
        raise exc.located(path=file) from None


def checked_text(values, *, path=None, field: str | None = None) -> np.ndarray:
    """Strings read from a file (``S`` bytes or ``U`` text) as a ``U`` array of valid Unicode:
    bytes decoded as UTF-8; a code point that is no character (beyond U+10FFFF, a surrogate),
    which a damaged file can hold and which would fail later (sorting, saving as UTF-8),
    refused naming the element (as ``index``)."""
    values = np.asarray(values)
    flat = values.reshape(-1)
    if flat.dtype.kind == "S":
        out = []
        for i, v in enumerate(flat.tolist()):
            try:
                out.append(v.decode("utf-8"))
            except UnicodeDecodeError as exc:
                raise DataError(f"is not UTF-8 text ({first_line(exc)})", path=path, field=field, index=i) from None
        return np.array(out, dtype=str).reshape(values.shape)
    if flat.dtype.itemsize:
        order = flat.dtype.byteorder if flat.dtype.byteorder in "<>" else "="
        codes = np.frombuffer(np.ascontiguousarray(flat).tobytes(), dtype=np.dtype(order + "u4"))
        codes = codes.reshape(len(flat), -1)
        bad = np.flatnonzero(((codes > 0x10FFFF) | ((codes >= 0xD800) & (codes <= 0xDFFF))).any(axis=1))
        if bad.size:
            raise DataError(
                "is not valid Unicode text (a code point that is no character)",
                path=path,
                field=field,
                index=int(bad[0]),
            )
    return np.asarray(values, dtype=str)


def _read_frames(root: Path, images, index: int, indices: np.ndarray) -> np.ndarray:
    """The frames at ``indices`` of sample ``index`` (only those are read from the file)."""
    try:
        return np.asarray(images[index, indices])
    except (OSError, ValueError) as exc:
        raise DataError(
            f"cannot be read ({first_line(exc)})", path=root / "images.npy", field="images", index=index
        ) from None
