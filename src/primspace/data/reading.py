"""Reading a data set's HDF5 file: :func:`read_fields` (the :class:`MotionDataset`
arguments it holds, checked). The mark of the program that wrote it is read by
:func:`primspace.utils.outputs.file_writer`.

Which nodes and attributes a file has, their types and how attributes are encoded come
from the schema table (:data:`primspace.data.schema.FIELDS`); writing and merging are
:mod:`primspace.data.storage`'s. Every error names the file, the field and, when it
applies, the sample.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from primspace.data.images import LazyImages
from primspace.data.schema import ARRAYS, ATTRIBUTES, SCHEMA_VERSION, Field
from primspace.utils.errors import DataError, first_line

__all__ = ["read_fields"]

#: Arrays held in memory (contiguous), then those read on demand (chunked per sample).
_EAGER = tuple(f for f in ARRAYS if not f.lazy)
_LAZY = tuple(f for f in ARRAYS if f.lazy)


def read_fields(path: str | os.PathLike) -> dict:
    """Read and check a data set file: the :class:`MotionDataset` arguments it holds.

    Arrays held in memory are read; arrays read on demand (images) become
    :class:`LazyImages` views of the file. An attribute the file lacks gets the
    schema's default; names stored empty are None (the constructor's defaults).

    Raises
    ------
    DataError
        If the file is missing, not HDF5, truncated, newer than this schema, or a node
        is missing, not an array or of the wrong type (naming the file and the field).
    """
    path = Path(path)
    if not path.exists():
        raise DataError("no such file", path=path)
    if path.is_dir():
        raise DataError("is a directory, not an HDF5 data set file", path=path)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise DataError(f"not a readable HDF5 file ({first_line(exc)})", path=path) from None
    try:
        with f:
            for attr in ATTRIBUTES:
                if attr.codec == "version":
                    _check_version(f, attr, path)
            values = {a.name: _read_eager(f, a, path) for a in _EAGER}
            on_disk = [a for a in _LAZY if _has_lazy(f, a, path)]
            values.update({a.name: _read_attribute(f, a, path) for a in ATTRIBUTES if a.in_memory})
    except DataError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise DataError(f"cannot read the file ({first_line(exc)})", path=path) from None
    for a in _LAZY:
        values[a.name] = None
    for a in on_disk:
        try:
            values[a.name] = LazyImages(path, dataset_name=a.name)
        except OSError as exc:
            raise DataError(f"cannot read ({first_line(exc)})", path=path, field=a.name) from None
    return values


def _check_version(f: h5py.File, attr: Field, path) -> None:
    version = _attr_number(f, attr.name, None, path)
    if version is not None and not (np.isfinite(version) and version == int(version) and version >= 1):
        raise DataError(f"must be a positive integer, got {version:g}", path=path, field=attr.name)
    if version is not None and int(version) > SCHEMA_VERSION:
        raise DataError(
            f"schema version {int(version)} is newer than this primspace reads ({SCHEMA_VERSION})",
            path=path,
            field=attr.name,
        )


def _read_eager(f: h5py.File, array: Field, path) -> np.ndarray | None:
    """An array read into memory, None when an optional one is absent."""
    if array.name not in f:
        if array.required:
            raise DataError(array.missing, path=path, field=array.name)
        return None
    value = _read_array(f, array.name, path)
    reason = array.check_stored(value.dtype) if array.check_stored is not None else None
    if reason is not None:
        raise DataError(reason, path=path, field=array.name)
    return value


def _has_lazy(f: h5py.File, array: Field, path) -> bool:
    """Whether the file holds an array read on demand (checked, not read)."""
    if array.name not in f:
        return False
    node = f[array.name]
    if not isinstance(node, h5py.Dataset):
        raise DataError("is not an array", path=path, field=array.name)
    reason = array.check_stored(node.dtype) if array.check_stored is not None else None
    if reason is not None:
        raise DataError(reason, path=path, field=array.name)
    return True


def _read_attribute(f: h5py.File, attr: Field, path):
    if attr.codec == "strings":
        return _str_list(f.attrs.get(attr.name)) or None
    if attr.codec == "number":
        return _attr_number(f, attr.name, attr.default, path)
    return _as_str(f.attrs.get(attr.name, attr.default))


def _read_array(f: h5py.File, name: str, path) -> np.ndarray:
    node = f[name]
    if not isinstance(node, h5py.Dataset):
        raise DataError("is not an array", path=path, field=name)
    try:
        return node[()]
    except (OSError, ValueError) as exc:
        why = "the file may be truncated"
        if node.fletcher32:  # schema 2: a flipped byte fails the checksum
            why = "its checksum does not match: the stored data is corrupted"
        raise DataError(f"cannot be read, {why} ({first_line(exc)})", path=path, field=name) from None


def _attr_number(f: h5py.File, name: str, default, path):
    """A file attribute holding one number, as float; anything else names the attribute."""
    if name not in f.attrs:
        return default
    try:
        value = np.asarray(f.attrs[name])
    except (OSError, TypeError, ValueError) as exc:
        raise DataError(f"cannot be read ({first_line(exc)})", path=path, field=name) from None
    if value.size != 1 or value.dtype.kind not in "fiu":
        raise DataError(f"must be one number, got {value.size} value(s) of type {value.dtype}", path=path, field=name)
    return float(value.reshape(-1)[0])


def _as_str(v) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def _str_list(v) -> list[str]:
    if v is None:
        return []
    if isinstance(v, (str, bytes)):
        return [_as_str(v)]
    return [_as_str(s) for s in np.asarray(v).reshape(-1)]
