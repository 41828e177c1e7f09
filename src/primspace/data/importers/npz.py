"""Import a NumPy ``.npz`` archive of demonstrations, with or without camera frames.

Joints, in one of these layouts:

* ``motor`` (or ``joints``) of shape ``(N, T0, J)`` (all sequences the same length);
* ``motor`` (or ``joints``) of shape ``(sum T_i, J)`` with ``lengths`` ``(N,)``:
  sequences back to back;
* one array per demonstration, ``(T_i, J)`` each: ``arr_0, arr_1, ...`` as written by
  ``np.savez(f, *sequences)``, or ``motor_0, motor_1, ...`` / ``joints_0, joints_1, ...``
  (numbered 0 .. N-1, in numeric order).

Frames (optional), uint8 RGB, one per joint step, in the same layouts:

* ``images`` ``(N, T0, H, W, 3)``; or ``images`` ``(sum T_i, H, W, 3)`` with ``lengths``;
* ``images_0, images_1, ...`` each ``(T_i, H_i, W_i, 3)`` (numbered 0 .. N-1).

Frames are aligned with the resampled joints and resized as
:mod:`primspace.data.importers.frames` says (nearest recorded frame in normalised time;
Lanczos resize to ``image_size``).

Optional: ``labels`` ``(N,)`` (integers, ``-1`` unknown, or strings), ``label_names``,
``joint_names``, ``params`` ``(N, P)``, ``param_names``, ``dt`` (seconds per input step):
the keys are the data set's field names (:data:`primspace.data.schema.FIELDS`).
"""

from __future__ import annotations

import os
import re
import zipfile
import zlib
from pathlib import Path

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import (
    natural_key, opt_names, parse_labels, printable, resample_located, resampled_dt,
)
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames, check_frames
from primspace.data.schema import ATTRIBUTES
from primspace.errors import DataError, first_line

__all__ = ["import_npz"]

_STACKED = ("motor", "joints")  # the joints of every demonstration in one array
_PER_DEMO = ("motor", "joints")  # prefixes of one array per demonstration (besides arr_)


def import_npz(path: str | os.PathLike, length: int, image_size=DEFAULT_IMAGE_SIZE) -> MotionDataset:
    """Read variable-length sequences (and frames) from an ``.npz`` archive (module docstring).

    Parameters
    ----------
    path : path-like
        The archive.
    length : int
        T, the steps to resample each sequence to.
    image_size : (H, W)
        Size of the stored frames, when the archive has any.

    Raises
    ------
    DataError
        Naming the file, the field (the archive's key) and the sample.
    """
    path = Path(path)
    data = _read_archive(path)
    try:
        sequences = npz_sequences(data)
        n = len(sequences)
        motor = resample_located(sequences, length)
        frames = _npz_frames(data, sequences, length, image_size)
        names = {a.name: opt_names(data.get(a.name)) for a in ATTRIBUTES if a.owner is not None}
        labels, names["label_names"] = parse_labels(data.get("labels"), names["label_names"], n)
        source = f"npz:{path.name}" + ("" if frames is None else f"; {frames.describe()}")
        return MotionDataset(
            motor=motor,
            images=None if frames is None else frames.stack(),
            labels=labels,
            params=data.get("params"),
            **names,
            dt=resampled_dt(_npz_dt(data), [len(s) for s in sequences], length),
            source=source,
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
        raise DataError(f"not a readable .npz archive: it is {what} (an npz archive is a zip file of .npy "
                        "arrays, as np.savez writes)", path=path)
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
    except ValueError as exc:
        if "allow_pickle" not in str(exc):  # a damaged .npy header
            raise DataError(f"is not a readable .npy array ({first_line(exc)})", path=path, field=field) from None
        raise DataError(  # object arrays need pickle, which we never enable
            f"holds Python objects ({first_line(exc)}); save each sequence as its own array "
            "(np.savez(f, *sequences)) or use 'motor' with 'lengths'",
            path=path, field=field,
        ) from None
    # a damaged zip: bad deflate data (zlib.error), a version or method field it cannot read
    except (OSError, zipfile.BadZipFile, EOFError, zlib.error, NotImplementedError) as exc:
        raise DataError(f"cannot be read, the archive may be truncated or damaged ({first_line(exc)})", path=path,
                        field=field) from None
    except MemoryError:  # a header that declares more than this machine holds
        raise DataError("declares an array too large to read into memory", path=path, field=field) from None
    if not isinstance(value, np.ndarray):  # numpy gives a member that is not a .npy file as bytes
        raise DataError("is not a .npy array (np.savez writes only those)", path=path, field=field)
    return value


def npz_sequences(data: dict) -> list[np.ndarray]:
    """The joint sequences of an archive's arrays ``data``, one per demonstration."""
    stacked = [k for k in _STACKED if k in data]
    if len(stacked) > 1:
        raise DataError("holds both 'motor' and 'joints'; keep one", field="joints")
    if stacked:
        return _split(data[stacked[0]], data, stacked[0], ("(N, T, J)", "(sum T_i, J)"))
    keys = sorted((k for k in data if k.startswith("arr_")), key=lambda k: int(k[4:]) if k[4:].isdigit() else -1)
    per_demo = {p: _numbered(data, p) for p in _PER_DEMO}
    layouts = [name for name, found in (("arr", keys), *per_demo.items()) if found]
    if len(layouts) > 1:
        raise DataError(f"holds per-demonstration arrays named {' and '.join(name + '_0' for name in layouts)}; keep one")
    for prefix, found in per_demo.items():
        if found:
            return [data[k] for k in _check_numbered(found, len(found), prefix)]
    if not keys:
        raise DataError(
            "no 'motor' array (nor 'joints'), and no 'arr_0', 'arr_1', ... sequences "
            "(nor 'motor_0' / 'joints_0', ...)",
            field="motor",
        )
    return [data[k] for k in keys]


def _split(values: np.ndarray, data: dict, name: str, shapes: tuple[str, str]) -> list[np.ndarray]:
    """A stacked array ``name`` of shape ``shapes[0]``, or one of shape ``shapes[1]`` split
    by ``lengths``, as a list of one array per demonstration."""
    stacked, concatenated = shapes
    rank = stacked.count(",") + 1
    if "lengths" not in data:
        if values.ndim != rank:
            raise DataError(f"must be {stacked}, or {concatenated} with 'lengths'; got shape {values.shape}", field=name)
        return list(values)
    lengths = np.asarray(data["lengths"]).reshape(-1)
    if lengths.dtype.kind not in "iu":
        raise DataError(f"must be integers, got {lengths.dtype}", field="lengths")
    if values.ndim != rank - 1:
        raise DataError(f"with 'lengths', must be {concatenated}, got shape {values.shape}", field=name)
    if lengths.sum() != values.shape[0]:
        raise DataError(f"lengths sum to {int(lengths.sum())} but {name} has {values.shape[0]} rows", field="lengths")
    for i, t in enumerate(lengths):
        if t < 1:
            raise DataError(f"has length {int(t)}", field=name, index=i)
    return list(np.split(values, np.cumsum(lengths)[:-1]))


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
                field=f"{prefix}_{i}", index=i,
            )
    if len(keys) > n:
        raise DataError(f"has no demonstration: there are {n} (0 .. {n - 1})", field=keys[n], index=n)
    return keys


def _npz_frames(data: dict, sequences: list, length: int, image_size) -> AlignedFrames | None:
    """The archive's frames at the resampled steps, or None if it has none."""
    per_demo = _numbered(data, "images")
    if "images" in data and per_demo:
        raise DataError(f"holds both 'images' and per-demonstration '{per_demo[0]}', ...; keep one", field="images")
    n = len(sequences)
    if "images" in data:
        frames, fields = _split(data["images"], data, "images", ("(N, T, H, W, 3)", "(sum T_i, H, W, 3)")), ["images"] * n
        if len(frames) != n:
            raise DataError(f"holds {len(frames)} demonstrations, the joints {n}", field="images")
    elif per_demo:
        fields = _check_numbered(per_demo, n, "images")
        frames = [data[k] for k in fields]
    else:
        return None
    aligned = AlignedFrames(length, image_size)
    for i, (seq, frame_array, name) in enumerate(zip(sequences, frames, fields)):
        check_frames(frame_array, len(seq), field=name, index=i)
        aligned.add(len(seq), lambda idx, a=frame_array: a[idx])
    return aligned


def _npz_dt(data: dict) -> float:
    if "dt" not in data:
        return 1.0
    dt = np.asarray(data["dt"]).reshape(-1)
    if dt.size != 1 or dt.dtype.kind not in "fiu":
        raise DataError(f"must be one positive number, got {dt.size} value(s) of type {dt.dtype}", field="dt")
    return float(dt[0])
