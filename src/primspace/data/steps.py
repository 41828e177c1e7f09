"""Demonstrations of different lengths made of several primitives: the step fields.

``lengths`` (N,) gives each sample's valid steps; ``step_labels`` and ``step_segments``
(N, T) give the primitive and the segment index of every valid step, -1 exactly at the
padding (docs/data.md). The schema table (:mod:`primspace.data.schema`) converts and
checks them with the functions here; :func:`valid_steps` is the mask that training and
segmentation use.
"""

from __future__ import annotations

import numpy as np

from primspace.utils.errors import DataError

__all__ = [
    "STEP_FIELDS",
    "valid_steps",
    "coerce_steps",
    "validate_lengths",
    "validate_step_labels",
    "validate_step_segments",
]


def valid_steps(lengths, length: int) -> np.ndarray:
    """(N, T) bool: step ``t`` of sample ``i`` is valid when ``t < lengths[i]``."""
    return np.arange(int(length))[None, :] < np.asarray(lengths)[:, None]


def coerce_steps(name: str, value, path) -> np.ndarray:
    """An integer array of the step fields (``lengths``, ``step_labels``, ``step_segments``) as int32."""
    value = np.asarray(value)
    if value.size and value.dtype.kind not in "iu":
        raise DataError(f"must be integers, got {value.dtype}", path=path, field=name)
    if value.size and (value.min() < np.iinfo(np.int32).min or value.max() > np.iinfo(np.int32).max):
        raise DataError("values do not fit in int32", path=path, field=name)
    return value.astype(np.int32)


STEP_FIELDS = ("lengths", "step_labels", "step_segments")


def validate_lengths(ds) -> None:
    p, (n, t, _) = ds.path, ds.motor.shape
    absent = [name for name in STEP_FIELDS if getattr(ds, name) is None]
    if absent:
        raise DataError(f"given without {', '.join(absent)} (the step fields go together)", path=p, field="lengths")
    if ds.lengths.shape != (n,):
        raise DataError(f"must have shape ({n},) to match motor, got {ds.lengths.shape}", path=p, field="lengths")
    bad = np.flatnonzero((ds.lengths < 2) | (ds.lengths > t))
    if bad.size:
        i = int(bad[0])
        raise DataError(f"length {int(ds.lengths[i])} out of range [2, T={t}]", path=p, field="lengths", index=i)


def _step_shape(ds, name: str) -> np.ndarray:
    """The (N, T) array ``name`` after its shape check; -1 exactly at the padding steps."""
    p, (n, t, _), value = ds.path, ds.motor.shape, getattr(ds, name)
    if ds.lengths is None:
        raise DataError("given without lengths (the step fields go together)", path=p, field=name)
    if value.shape != (n, t):
        raise DataError(f"must have shape ({n}, {t}) to match motor, got {value.shape}", path=p, field=name)
    valid = valid_steps(ds.lengths, t)
    wrong = np.flatnonzero(((value == -1) == valid).any(axis=1))
    if wrong.size:
        i = int(wrong[0])
        step = int(np.flatnonzero((value[i] == -1) == valid[i])[0])
        raise DataError(
            f"step {step}: -1 must mark exactly the steps from lengths[{i}] = {int(ds.lengths[i])} on",
            path=p,
            field=name,
            index=i,
        )
    return valid


def validate_step_labels(ds) -> None:
    valid = _step_shape(ds, "step_labels")
    k = len(ds.label_names)
    bad = np.flatnonzero((valid & ((ds.step_labels < 0) | (ds.step_labels >= k))).any(axis=1))
    if bad.size:
        i = int(bad[0])
        value = int(ds.step_labels[i][valid[i] & ((ds.step_labels[i] < 0) | (ds.step_labels[i] >= k))][0])
        raise DataError(
            f"label {value} out of range [0, {k - 1}] ({k} label names)", path=ds.path, field="step_labels", index=i
        )


def validate_step_segments(ds) -> None:
    valid = _step_shape(ds, "step_segments")
    seg = ds.step_segments
    steps = np.diff(seg, axis=1)
    jumps = valid[:, 1:] & ~np.isin(steps, (0, 1))
    bad = np.flatnonzero((seg[:, 0] != 0) | jumps.any(axis=1))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            "segment indices must start at 0 and grow by 0 or 1 per step", path=ds.path, field="step_segments", index=i
        )
