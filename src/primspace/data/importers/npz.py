"""Import a NumPy ``.npz`` archive of demonstrations, with or without camera frames.

Joints, in one of these layouts:

* ``motor`` (or ``joints``) of shape ``(N, T0, J)``: stacked, each sample ``T0`` steps,
  or padded to ``T0`` (below);
* ``motor`` (or ``joints``) of shape ``(sum T_i, J)`` with ``lengths`` ``(N,)``:
  sequences back to back;
* one array per demonstration, ``(T_i, J)`` each: ``arr_0, arr_1, ...`` as written by
  ``np.savez(f, *sequences)``, or ``motor_0, motor_1, ...`` / ``joints_0, joints_1, ...``
  (numbered 0 .. N-1, in numeric order).

Padding (stacked ``(N, T0, J)`` only): with ``lengths`` ``(N,)`` beside it, sample ``i``
is its first ``lengths[i]`` steps (integers, ``2 .. T0``); without, the trailing steps of a
sample that repeat its last value exactly are padding and are trimmed (the first step of
the hold is kept, at least 2 steps; :mod:`~primspace.data.importers.padding`), unless
``keep_padding`` (``--keep-padding``). A stacked archive without exact repeats at the end
imports as before; one with them is now trimmed, and its ``source`` text says in how many
samples (``npz:demos.npz; padding trimmed in 3 of 5 samples``). ``lengths`` beside a
``(sum T_i, J)`` array keeps its meaning (the concatenated layout); the rank tells which.

Frames (optional), uint8 RGB, one per joint step, in the same layouts:

* ``images`` ``(N, T0, H, W, 3)`` (``T0`` frames per sample, padded as the joints: a
  sample's trimmed steps drop their frames); or ``images`` ``(sum T_i, H, W, 3)`` with
  ``lengths``;
* ``images_0, images_1, ...`` each ``(T_i, H_i, W_i, 3)`` (numbered 0 .. N-1).

Frames are aligned with the resampled joints, fitted (``image_fit``) and resized as
:mod:`primspace.data.importers.frames` says (nearest recorded frame in normalised time;
Lanczos resize to ``image_size``).

Optional: ``labels`` ``(N,)`` (integers, ``-1`` unknown, or strings), ``label_names``,
``joint_names``, ``params`` ``(N, P)``, ``param_names``, ``dt`` (seconds per input step):
the keys are the data set's field names (:data:`primspace.data.schema.FIELDS`).

Each sample's ``source_ids`` entry is ``npz:<file name>:<i>`` (its index in a stacked or
concatenated array) or ``npz:<file name>:<key>`` (``arr_3``, ``motor_3``, ``joints_3``).
"""

from __future__ import annotations

import os
import re
import zipfile
import zlib
from pathlib import Path
from tokenize import TokenError
from typing import NamedTuple

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import (
    natural_key,
    opt_names,
    parse_labels,
    printable,
    resample_located,
    resampled_dt,
)
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames, as_image_fit, check_frames
from primspace.data.importers.npy_folder import checked_text
from primspace.data.importers.padding import checked_lengths, padded_lengths, padding_note
from primspace.data.schema import ATTRIBUTES
from primspace.utils.errors import DataError, first_line

__all__ = ["import_npz", "npz_sequences", "NpzJoints"]

_STACKED = ("motor", "joints")  # the joints of every demonstration in one array
_PER_DEMO = ("motor", "joints")  # prefixes of one array per demonstration (besides arr_)


def import_npz(
    path: str | os.PathLike,
    length: int,
    image_size=DEFAULT_IMAGE_SIZE,
    *,
    image_fit: str = "crop",
    keep_padding: bool = False,
) -> MotionDataset:
    """Read variable-length sequences (and frames) from an ``.npz`` archive (module docstring).

    Parameters
    ----------
    path : path-like
        The archive.
    length : int
        T, the steps to resample each sequence to.
    image_size : (H, W)
        Size of the stored frames, when the archive has any.
    image_fit : {"crop", "pad", "stretch"}
        How a frame of another aspect ratio is fitted (:mod:`~primspace.data.importers.frames`).
    keep_padding : bool, default False
        Keep the trailing steps of a stacked ``(N, T0, J)`` array that repeat its last
        value; by default they are taken as padding and trimmed
        (:mod:`~primspace.data.importers.padding`).

    Raises
    ------
    DataError
        Naming the file, the field (the archive's key) and the sample.
    """
    path = Path(path)
    image_fit = as_image_fit(image_fit)
    data = _read_archive(path)
    try:
        joints = npz_sequences(data, keep_padding=keep_padding)
        sequences, n = joints.sequences, len(joints.sequences)
        motor = resample_located(sequences, length)
        frames = _npz_frames(data, joints, length, image_size, image_fit)
        names = {a.name: opt_names(data.get(a.name)) for a in ATTRIBUTES if a.owner is not None}
        labels, names["label_names"] = parse_labels(data.get("labels"), names["label_names"], n)
        source = f"npz:{path.name}" + ("" if frames is None else f"; {frames.collect().describe()}") + joints.note
        return MotionDataset(
            motor=motor,
            images=None if frames is None else frames.stack(),
            labels=labels,
            params=data.get("params"),
            **names,
            dt=resampled_dt(_npz_dt(data), [len(s) for s in sequences], length),
            source=source,
            source_ids=[f"npz:{printable(path.name)}:{key}" for key in joints.ids],
        )
    except DataError as exc:
        raise exc.located(path=path) from None


_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a zip file's first bytes (the second: empty)


def _read_archive(path: Path) -> dict:
    if not path.is_file():
        raise DataError("no such file", path=path)
    with open(path, "rb") as fh:
        magic = fh.read(6)
    if not magic.startswith(_ZIP_MAGIC):
        what = "a single .npy array, not a zip file" if magic == b"\x93NUMPY" else "not a zip file"
        raise DataError(
            f"not a readable .npz archive: it is {what} (an npz archive is a zip file of .npy "
            "arrays, as np.savez writes)",
            path=path,
        )
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, zlib.error, NotImplementedError) as exc:
        raise DataError(f"not a readable .npz archive ({first_line(exc)})", path=path) from None
    with archive:
        return {key: _member(archive, key, path) for key in archive.files}


def _member(archive, key: str, path: Path) -> np.ndarray:
    """The array ``key`` of an open archive; a damaged or non-array member names its key."""
    field = printable(key)
    try:
        value = archive[key]
    except (ValueError, SyntaxError, TokenError, TypeError, OverflowError) as exc:
        if "allow_pickle" not in str(exc):  # a damaged .npy header (numpy tokenizes an old-style one)
            raise DataError(f"is not a readable .npy array ({first_line(exc)})", path=path, field=field) from None
        raise DataError(  # object arrays need pickle, which we never enable
            f"holds Python objects ({first_line(exc)}); save each sequence as its own array "
            "(np.savez(f, *sequences)) or use 'motor' with 'lengths'",
            path=path,
            field=field,
        ) from None
    # a damaged zip: bad deflate data (zlib.error), a version or method field it cannot read, an
    # encryption flag (RuntimeError: a password is required)
    except (OSError, zipfile.BadZipFile, EOFError, zlib.error, NotImplementedError, RuntimeError) as exc:
        raise DataError(
            f"cannot be read, the archive may be truncated or damaged ({first_line(exc)})", path=path, field=field
        ) from None
    except MemoryError:  # a header that declares more than this machine holds
        raise DataError("declares an array too large to read into memory", path=path, field=field) from None
    if not isinstance(value, np.ndarray):  # numpy gives a member that is not a .npy file as bytes
        raise DataError("is not a .npy array (np.savez writes only those)", path=path, field=field)
    return checked_text(value, path=path, field=field) if value.dtype.kind in "SU" else value


class NpzJoints(NamedTuple):
    """The joints of an archive: :func:`npz_sequences`."""

    sequences: list[np.ndarray]  # one (T_i, J) per demonstration, padding trimmed
    ids: list[str]  # each one's place in the archive: its index, or its key (``arr_3``)
    padded_steps: int | None  # T0 of a stacked (N, T0, J) array (before trimming), else None
    note: str  # for the data set's source text: '; padding trimmed in 3 of 5 samples' or ''


def npz_sequences(data: dict, *, keep_padding: bool = False) -> NpzJoints:
    """The joint sequences of an archive's arrays ``data``, one per demonstration (module docstring)."""
    stacked = [k for k in _STACKED if k in data]
    if len(stacked) > 1:
        raise DataError("holds both 'motor' and 'joints'; keep one", field="joints")
    if stacked:
        return _stacked_joints(data, stacked[0], keep_padding)
    keys = _numbered(data, "arr")
    per_demo = {p: _numbered(data, p) for p in _PER_DEMO}
    layouts = [name for name, found in (("arr", keys), *per_demo.items()) if found]
    if len(layouts) > 1:
        named = " and ".join(name + "_0" for name in layouts)
        raise DataError(f"holds per-demonstration arrays named {named}; keep one")
    keys = _check_numbered(keys, len(keys), "arr")  # a gap would pair joints with another sample's frames
    for prefix, found in per_demo.items():
        if found:
            keys = _check_numbered(found, len(found), prefix)
    if not keys:
        raise DataError(
            "no 'motor' array (nor 'joints'), and no 'arr_0', 'arr_1', ... sequences (nor 'motor_0' / 'joints_0', ...)",
            field="motor",
        )
    return NpzJoints([data[k] for k in keys], [printable(k) for k in keys], None, "")


def _stacked_joints(data: dict, name: str, keep_padding: bool) -> NpzJoints:
    """The joints of ``motor`` (or ``joints``): stacked ``(N, T0, J)``, its padding trimmed (to
    ``lengths`` where given, else by :func:`padded_lengths` unless ``keep_padding``); or
    ``(sum T_i, J)`` split by ``lengths``."""
    values = data[name]
    parts, stacked = _split(values, data, name, ("(N, T, J)", "(sum T_i, J)"))
    ids = [str(i) for i in range(len(parts))]
    if not stacked:
        return NpzJoints(parts, ids, None, "")
    t_max, note = values.shape[1], ""
    if "lengths" in data:
        lengths = checked_lengths(np.asarray(data["lengths"]).reshape(-1), len(parts), t_max)
    elif keep_padding:
        return NpzJoints(parts, ids, t_max, "")
    else:
        lengths = padded_lengths(values)
        note = padding_note(lengths, t_max)
    return NpzJoints([p[:t] for p, t in zip(parts, lengths)], ids, t_max, note)


def _split(values: np.ndarray, data: dict, name: str, shapes: tuple[str, str]) -> tuple[list[np.ndarray], bool]:
    """A stacked array ``name`` of shape ``shapes[0]``, or one of shape ``shapes[1]`` split
    by ``lengths``, as a list of one array per demonstration; and whether it was stacked."""
    stacked, concatenated = shapes
    rank = stacked.count(",") + 1
    if values.ndim == rank:  # stacked; 'lengths', if any, are the valid steps of each sample
        return list(values), True
    if "lengths" not in data:
        raise DataError(f"must be {stacked}, or {concatenated} with 'lengths'; got shape {values.shape}", field=name)
    lengths = np.asarray(data["lengths"]).reshape(-1)
    if lengths.dtype.kind not in "iu":
        raise DataError(f"must be integers, got {lengths.dtype}", field="lengths")
    if values.ndim != rank - 1:
        raise DataError(
            f"must be {stacked} (padded), or {concatenated} with 'lengths'; got shape {values.shape}", field=name
        )
    if lengths.sum() != values.shape[0]:
        raise DataError(f"lengths sum to {int(lengths.sum())} but {name} has {values.shape[0]} rows", field="lengths")
    for i, t in enumerate(lengths):
        if t < 1:
            raise DataError(f"has length {int(t)}", field=name, index=i)
    return list(np.split(values, np.cumsum(lengths)[:-1])), False


def _numbered(data: dict, prefix: str) -> list[str]:
    """Keys ``prefix_<n>`` of ``data``, in numeric order."""
    pattern = re.compile(rf"{re.escape(prefix)}_\d+")
    return sorted((k for k in data if pattern.fullmatch(k)), key=lambda k: natural_key(k, prefix))


def _check_numbered(keys: list[str], n: int, prefix: str) -> list[str]:
    """``keys`` must be ``prefix_0 .. prefix_{n-1}``: one per demonstration."""
    for i in range(n):
        if i >= len(keys) or keys[i] != f"{prefix}_{i}":
            raise DataError(
                f"missing: per-demonstration arrays must be numbered {prefix}_0 .. {prefix}_{n - 1} "
                f"(found {', '.join(keys[:6])}{', ...' if len(keys) > 6 else ''})",
                field=f"{prefix}_{i}",
                index=i,
            )
    if len(keys) > n:
        raise DataError(f"has no demonstration: there are {n} (0 .. {n - 1})", field=keys[n], index=n)
    return keys


def _npz_frames(data: dict, joints: NpzJoints, length: int, image_size, image_fit: str) -> AlignedFrames | None:
    """The archive's frames at the resampled steps, or None if it has none. Stacked frames
    ``(N, T0, ...)`` hold ``T0`` per sample; a sample's trimmed padding drops its last ones."""
    per_demo = _numbered(data, "images")
    if "images" in data and per_demo:
        raise DataError(f"holds both 'images' and per-demonstration '{per_demo[0]}', ...; keep one", field="images")
    sequences = joints.sequences
    n, stacked = len(sequences), False
    if "images" in data:
        frames, stacked = _split(data["images"], data, "images", ("(N, T, H, W, 3)", "(sum T_i, H, W, 3)"))
        fields = ["images"] * n
        if len(frames) != n:
            raise DataError(f"holds {len(frames)} demonstrations, the joints {n}", field="images")
    elif per_demo:
        fields = _check_numbered(per_demo, n, "images")
        frames = [data[k] for k in fields]
    else:
        return None
    aligned = AlignedFrames(length, image_size, image_fit)
    for i, (seq, frame_array, name) in enumerate(zip(sequences, frames, fields)):
        stored = joints.padded_steps if stacked and joints.padded_steps is not None else len(seq)
        check_frames(frame_array, stored, field=name, index=i)
        aligned.add(len(seq), lambda idx, a=frame_array: a[idx])
    return aligned


def _npz_dt(data: dict) -> float:
    if "dt" not in data:
        return 1.0
    dt = np.asarray(data["dt"]).reshape(-1)
    if dt.size != 1 or dt.dtype.kind not in "fiu":
        raise DataError(f"must be one positive number, got {dt.size} value(s) of type {dt.dtype}", field="dt")
    return float(dt[0])
