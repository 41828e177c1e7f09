"""The conversions and checks of each field that the schema table points at
(:data:`primspace.data.schema.FIELDS`: ``coerce``, ``normalize``, ``validate``,
``check_stored``).

Each takes one field's value (or the data set being built) and either returns it
converted or raises a :class:`~primspace.utils.errors.DataError` naming the file, the field
and, where it applies, the sample. The table says which field uses which and in what
order they run; the checks shared with the step fields and the source ids live in
:mod:`primspace.data.steps` and :mod:`primspace.data.values`.
"""

from __future__ import annotations

import numpy as np

from primspace.data.images import LazyImages
from primspace.data.values import as_float32, check_finite, check_int32_labels
from primspace.utils.errors import DataError

__all__ = [
    "coerce_motor",
    "coerce_params",
    "coerce_images",
    "coerce_labels",
    "default_names",
    "as_number",
    "as_text",
    "default_label_names",
    "validate_motor",
    "validate_joint_names",
    "validate_images",
    "validate_labels",
    "validate_params",
    "validate_param_names",
    "coerce_scene",
    "validate_scene",
    "validate_scene_names",
    "validate_dt",
    "stored_floating",
    "stored_uint8",
    "stored_strings",
]

# ------------------------------------------------------------------- conversions


def coerce_motor(motor, path) -> np.ndarray:
    return as_float32(motor, "motor", path)


def coerce_params(params, path) -> np.ndarray:
    return as_float32(params, "params", path)


def coerce_scene(scene, path) -> np.ndarray:
    return as_float32(scene, "scene", path)


def coerce_images(images, path):
    if isinstance(images, LazyImages):
        return images
    images = np.asarray(images)
    if images.dtype != np.uint8:
        raise DataError(f"images must be uint8, got {images.dtype}", path=path, field="images")
    return images


def coerce_labels(labels, path):
    labels = np.asarray(labels)
    if labels.size and labels.dtype.kind not in "iu":
        raise DataError(f"labels must be integers, got {labels.dtype}", path=path, field="labels")
    check_int32_labels(labels, path)
    return labels.astype(np.int32)


def default_names(names, ds, *, prefix: str, array: str, ndim: int) -> list[str]:
    """Names as given, else ``prefix0..``, one per entry of the last axis of ``array``."""
    value = getattr(ds, array)
    n = value.shape[-1] if value is not None and value.ndim == ndim else 0
    if names is None or len(names) == 0:
        return [f"{prefix}{i}" for i in range(n)]
    return [str(s) for s in names]


def as_number(value, ds) -> float:
    return float(value)


def as_text(value, ds) -> str:
    return str(value)


def default_label_names(names, ds) -> list[str]:
    """Names as given, else ``"0".."K-1"`` for labels up to K-1."""
    if names is None:
        top = 0
        for values in (ds.labels, ds.step_labels):
            if values is not None and values.size:
                top = max(top, int(values.max()) + 1)
        return [str(i) for i in range(top)]
    return [str(s) for s in names]


# ---------------------------------------------------------------------- checks


def validate_motor(ds) -> None:
    p, m = ds.path, ds.motor
    if m.ndim != 3:
        raise DataError(f"must have shape (N, T, J), got rank {m.ndim} {m.shape}", path=p, field="motor")
    n, t, j = m.shape
    if n < 1:
        raise DataError("holds no samples", path=p, field="motor")
    if t < 2:
        raise DataError(f"sequences need at least 2 time steps, got T={t}", path=p, field="motor")
    if j < 1:
        raise DataError("has no joints (J=0)", path=p, field="motor")
    check_finite(m, "motor", p)


def validate_joint_names(ds) -> None:
    j = ds.motor.shape[2]
    if len(ds.joint_names) != j:
        raise DataError(f"{len(ds.joint_names)} joint names for J={j} joints", path=ds.path, field="joint_names")
    if len(set(ds.joint_names)) != j:
        raise DataError("joint names are not unique", path=ds.path, field="joint_names")


def validate_images(ds) -> None:
    p, (n, t, _) = ds.path, ds.motor.shape
    s = tuple(ds.images.shape)
    if len(s) != 5 or s[4] != 3:
        raise DataError(f"must have shape (N, T, H, W, 3), got {s}", path=p, field="images")
    if s[0] != n:
        raise DataError(f"{s[0]} samples but motor has {n}", path=p, field="images")
    if s[1] != t:
        raise DataError(f"{s[1]} time steps but motor has T={t}", path=p, field="images")
    if ds.images.dtype != np.uint8:
        raise DataError(f"must be uint8, got {ds.images.dtype}", path=p, field="images")


def validate_labels(ds) -> None:
    p, n, lab = ds.path, ds.motor.shape[0], ds.labels
    if lab.shape != (n,):
        raise DataError(f"must have shape ({n},) to match motor, got {lab.shape}", path=p, field="labels")
    k = len(ds.label_names)
    bad = np.flatnonzero((lab < -1) | (lab >= k))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"label {int(lab[i])} out of range [-1, {k - 1}] ({k} label names)", path=p, field="labels", index=i
        )


def _per_sample_matrix(array: str, symbol: str):
    """The check of an optional ``(N, symbol)`` array of finite values (``params``, ``scene``)."""

    def validate(ds) -> None:
        p, n, values = ds.path, ds.motor.shape[0], getattr(ds, array)
        if values.ndim != 2 or values.shape[0] != n:
            raise DataError(f"must have shape ({n}, {symbol}), got {values.shape}", path=p, field=array)
        check_finite(values, array, p)

    return validate


def _column_names(array: str, names: str, symbol: str, what: str):
    """The check that ``names`` names each column of ``array`` (``what``: the columns, in the message)."""

    def validate(ds) -> None:
        n = getattr(ds, array).shape[1]
        given = len(getattr(ds, names))
        if given != n:
            raise DataError(f"{given} names for {symbol}={n} {what}", path=ds.path, field=names)

    return validate


validate_params = _per_sample_matrix("params", "P")
validate_param_names = _column_names("params", "param_names", "P", "params")
validate_scene = _per_sample_matrix("scene", "S")
validate_scene_names = _column_names("scene", "scene_names", "S", "scene values")


def validate_dt(ds) -> None:
    if not np.isfinite(ds.dt) or ds.dt <= 0:
        raise DataError(f"must be a positive number, got {ds.dt}", path=ds.path, field="dt")


def stored_floating(dtype: np.dtype) -> str | None:
    return None if dtype.kind == "f" else f"must be floating point, got {dtype}"


def stored_uint8(dtype: np.dtype) -> str | None:
    return None if dtype == np.uint8 else f"must be uint8, got {dtype}"


def stored_strings(dtype: np.dtype) -> str | None:
    import h5py

    return None if h5py.check_string_dtype(dtype) is not None else f"must be strings, got {dtype}"
