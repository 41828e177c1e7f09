"""Checks on the values of a data set, before they are stored: finite, within float32,
labels within int32, source ids one line of text each. Each failure is a
:class:`~primspace.utils.errors.DataError` naming the file, the field, the sample and the
position inside it (step and joint, or column).

The float32 check runs *before* the cast: casting 1e39 to float32 gives inf, which the
finiteness check would then call "NaN or inf" instead of naming the value as too large.
"""

from __future__ import annotations

import numpy as np

from primspace.utils.errors import DataError

__all__ = [
    "FLOAT32_MAX",
    "MAX_SOURCE_ID",
    "float32_overflow",
    "too_large",
    "as_float32",
    "check_finite",
    "check_int32_labels",
    "coerce_source_ids",
    "validate_source_ids",
]

FLOAT32_MAX = float(np.finfo(np.float32).max)
#: The longest source id kept (characters): a file name, a demo key and an episode index
#: fit many times over; a longer one is damage or a misuse of the field.
MAX_SOURCE_ID = 1000


def _position(pos: tuple[int, ...], ndim: int) -> str:
    """`` (step s, joint j)`` for a sample of (T, J) values, `` (column c)`` for a row."""
    if ndim == 3:
        return f" (step {pos[1]}, joint {pos[2]})"
    if ndim == 2:
        return f" (column {pos[1]})"
    return ""


def float32_overflow(arr: np.ndarray) -> tuple[tuple[int, ...], float] | None:
    """The position and value of the first finite value that float32 cannot hold, or None.

    Float16/32 always fit, and so does every integer up to 64 bits (|x| < 2e19, far
    below float32's 3.4e38); NaN and inf are left to :func:`check_finite`.
    """
    if arr.dtype.kind != "f" or arr.dtype.itemsize <= 4:
        return None
    with np.errstate(invalid="ignore", over="ignore"):
        bad = np.isfinite(arr) & (np.abs(arr) > FLOAT32_MAX)
    if not bad.any():
        return None
    pos = tuple(int(k) for k in np.argwhere(bad)[0])
    return pos, arr[pos]


def too_large(value) -> str:
    """The message for a value beyond float32."""
    text = np.format_float_scientific(value, precision=6, trim="-")
    return f"value {text} exceeds the float32 range (magnitude at most {FLOAT32_MAX:.6g})"


def as_float32(x, field_name: str, path, index: int | None = None) -> np.ndarray:
    """``x`` as float32 numbers, refusing non-numbers and values float32 cannot hold.

    ``x`` is a whole field (``(N, T, J)`` or ``(N, P)``: the first axis is the sample) or,
    with ``index``, one sample (``(T, J)``).
    """
    arr = np.asarray(x)
    if arr.dtype.kind not in "fiu" or arr.dtype == bool:
        raise DataError(f"must be numbers, got {arr.dtype}", path=path, field=field_name, index=index)
    hit = float32_overflow(arr)
    if hit is not None:
        pos, value = hit
        if index is None:
            sample, where = (pos[0] if arr.ndim else None), _position(pos, arr.ndim)
        else:
            sample, where = index, _position((index, *pos), arr.ndim + 1)
        raise DataError(too_large(value) + where, path=path, field=field_name, index=sample)
    return arr.astype(np.float32, copy=False)


def check_finite(arr: np.ndarray, field_name: str, path) -> None:
    """Refuse NaN or inf, naming the first sample (and step and joint)."""
    finite = np.isfinite(arr)
    if not finite.all():
        bad = tuple(int(k) for k in np.argwhere(~finite)[0])
        where = _position(bad, arr.ndim) if arr.ndim == 3 else ""
        raise DataError(f"contains NaN or inf{where}", path=path, field=field_name, index=bad[0])


def check_int32_labels(labels: np.ndarray, path) -> None:
    """Refuse labels that a cast to int32 would wrap around (onto valid labels, silently)."""
    if labels.dtype.kind not in "iu" or np.can_cast(labels.dtype, np.int32):
        return
    info = np.iinfo(np.int32)
    bad = np.argwhere((labels < info.min) | (labels > info.max))
    if bad.size:
        pos = tuple(int(k) for k in bad[0])
        raise DataError(
            f"label {int(labels[pos])} is not a primitive index (it does not fit in int32)",
            path=path,
            field="labels",
            index=pos[0] if labels.ndim == 1 else None,
        )


def coerce_source_ids(ids, path) -> np.ndarray:
    """Source ids as an object array of ``str`` (bytes read from a file decoded as UTF-8)."""
    values = np.asarray(ids, dtype=object).reshape(-1) if np.ndim(ids) else np.asarray([ids], dtype=object)
    out = np.empty(values.shape, dtype=object)
    for i, v in enumerate(values):
        if isinstance(v, bytes):
            v = v.decode("utf-8", "backslashreplace")
        if not isinstance(v, str):
            raise DataError(f"must be strings, got {type(v).__name__}", path=path, field="source_ids", index=i)
        out[i] = v
    return out


def validate_source_ids(ds) -> None:
    """One source id per sample, each one line of at most :data:`MAX_SOURCE_ID` characters."""
    p, n, ids = ds.path, ds.motor.shape[0], ds.source_ids
    if ids.shape != (n,):
        raise DataError(f"must have shape ({n},) to match motor, got {ids.shape}", path=p, field="source_ids")
    for i, v in enumerate(ids):
        if len(v) > MAX_SOURCE_ID or not v.isprintable():
            why = (
                f"is {len(v):,} characters long (at most {MAX_SOURCE_ID})"
                if len(v) > MAX_SOURCE_ID
                else "holds a control character (a source id is one line of text)"
            )
            raise DataError(why, path=p, field="source_ids", index=i)
