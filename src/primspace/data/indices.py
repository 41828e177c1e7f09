"""Sample indices: one check for every list of samples, and index files.

:func:`check_indices` is the one check of a selection of samples (integers, one
dimension, each sample at most once, each in range, not empty); its errors say where
the indices came from. :meth:`MotionDataset.subset <primspace.data.MotionDataset.subset>`
and :func:`read_indices` (``--indices FILE``) use it.

Examples
--------
>>> check_indices([3, 0, 2], 5)
array([3, 0, 2])
>>> check_indices([3, 3], 5)
Traceback (most recent call last):
...
primspace.utils.errors.UserError: sample indices list a sample more than once
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from primspace.utils.errors import DataError, UserError

__all__ = ["check_indices", "mask_indices", "read_indices"]


def check_indices(
    indices,
    n_samples: int | None,
    *,
    source: str | os.PathLike | None = None,
    data_path: str | os.PathLike | None = None,
    unique: bool = True,
) -> np.ndarray:
    """Check a selection of samples; return it as a 1-d int64 array, in the given order.

    Parameters
    ----------
    indices : array-like of int
        Sample indices, one dimension.
    n_samples : int or None
        The number of samples they select from; each index must be in
        ``[0, n_samples)``. None: no range check (the data set is not known yet).
    source : path-like, optional
        The index file they were read from. Given: errors are
        :class:`~primspace.utils.errors.DataError` naming that file and field ``indices``;
        else :class:`~primspace.utils.errors.UserError` (a Python argument).
    data_path : path-like, optional
        The data set file the samples belong to, named when an index is out of range.
    unique : bool, default True
        Refuse a sample listed twice (False: a selection may repeat samples, as
        :meth:`MotionDataset.subset` allows).

    Returns
    -------
    ndarray of int64, shape (k,)

    Raises
    ------
    UserError
        For indices given as an argument: not integers (``sample indices must be
        integers, got float64``), not 1-d, a sample twice, out of range (``sample
        index 7 out of range for 5 samples``), empty (``an empty selection of samples``).
    DataError
        For indices read from ``source``: ``must be a non-empty list of integers``,
        ``lists a sample more than once``, ``sample 7 is out of range for the 5 samples
        of data.h5``, each prefixed with the file and ``field 'indices'``.
    """
    arr = np.asarray(indices)
    if source is not None:
        return _check_from_file(arr, n_samples, source, data_path, unique)
    if arr.size and arr.dtype.kind not in "iu":
        raise UserError(f"sample indices must be integers, got {arr.dtype}")
    if arr.ndim != 1:
        raise UserError("sample indices must be a 1-d list of integers")
    arr = arr.astype(np.int64)
    if unique and len(np.unique(arr)) != arr.size:
        raise UserError("sample indices list a sample more than once")
    if n_samples is not None and arr.size and (arr.min() < 0 or arr.max() >= n_samples):
        bad = int(arr[(arr < 0) | (arr >= n_samples)][0])
        raise UserError(f"sample index {bad} out of range for {n_samples} samples")
    if arr.size == 0:
        raise UserError("an empty selection of samples")
    return arr


def _check_from_file(arr: np.ndarray, n_samples, source, data_path, unique: bool) -> np.ndarray:
    """:func:`check_indices` for indices read from the file ``source`` (DataError)."""
    if arr.ndim != 1 or arr.size == 0 or arr.dtype.kind not in "iu":
        raise DataError("must be a non-empty list of integers", path=source, field="indices")
    if unique and len(np.unique(arr)) != arr.size:
        raise DataError("lists a sample more than once", path=source, field="indices")
    if n_samples is not None:
        bad = arr[(arr < 0) | (arr >= n_samples)]  # before the cast: a uint64 never wraps
        if bad.size:
            where = f" of {data_path}" if data_path is not None else ""
            raise DataError(
                f"sample {int(bad[0])} is out of range for the {n_samples} samples{where}",
                path=source,
                field="indices",
            )
    return arr.astype(np.int64)


def mask_indices(mask, n_samples: int) -> np.ndarray:
    """The samples a boolean mask of ``n_samples`` entries selects, in order.

    Raises
    ------
    UserError
        If the mask does not have shape ``(n_samples,)``.
    """
    mask = np.asarray(mask)
    if mask.shape != (n_samples,):
        raise UserError(f"boolean mask of shape {mask.shape} for {n_samples} samples")
    return np.flatnonzero(mask)


def _whole(token: str) -> int:
    """A text index: digits only, with an optional sign (``0_1`` and ``1e3`` are not indices)."""
    if not re.fullmatch(r"[+-]?[0-9]+", token):
        raise ValueError(f"{token!r} is not a whole number")
    value = int(token)
    if abs(value) >= 2**63:
        raise OverflowError(f"{token} is beyond 64-bit integers")
    return value


def read_indices(path: str | os.PathLike, dataset=None) -> np.ndarray:
    """Sample indices from a ``.npy`` file or a text file (integers separated by
    whitespace or commas; ``#`` starts a comment); with ``dataset``, each must be one of
    its samples (the error names the index file and the data file).

    Parameters
    ----------
    path : path-like
        The index file (``.npy``, any case, else text).
    dataset : MotionDataset, optional
        The data set the indices select from (range check).

    Returns
    -------
    ndarray of int64, shape (k,)

    Raises
    ------
    DataError
        Naming the index file and field ``indices``: missing, unreadable, not a
        non-empty 1-d list of integers, a sample listed twice, a sample out of range.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", path=path, field="indices")
    try:
        if path.suffix.lower() == ".npy":
            arr = np.load(path, allow_pickle=False)
        else:
            text = path.read_text(encoding="utf-8")
            tokens = [t for line in text.splitlines() for t in line.split("#", 1)[0].replace(",", " ").split()]
            arr = np.array([_whole(t) for t in tokens], dtype=np.int64)
    except (ValueError, OverflowError, OSError, UnicodeDecodeError) as exc:
        raise DataError(
            f"cannot read sample indices ({str(exc).splitlines()[0]})", path=path, field="indices"
        ) from None
    if dataset is None:
        return check_indices(arr, None, source=path)
    return check_indices(arr, len(dataset), source=path, data_path=dataset.path)
