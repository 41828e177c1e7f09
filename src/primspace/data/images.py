"""Images read on demand: :class:`LazyImages`, a view of ``(N, T, H, W, 3)`` uint8 frames.

The frames of a data set file are stored one gzip-compressed chunk per sample (see
:mod:`primspace.data.schema`), so a view reads only the samples asked for, and a
subset is a view (an index into the file), never a copy. A chunk that cannot be decoded
is a :class:`~primspace.utils.errors.DataError` naming the file, the field and the sample
(:func:`read_samples`), on every read path.
"""

from __future__ import annotations

import os

import h5py
import numpy as np

from primspace.utils.errors import DataError, first_line

__all__ = ["LazyImages", "read_samples", "as_view", "IMAGE_BLOCK"]

#: Samples per block when images are copied, written or iterated.
IMAGE_BLOCK = 32


class LazyImages:
    """A read-only view of ``(N, T, H, W, 3)`` uint8 images, read on demand.

    The images live either in an HDF5 file (``source`` is its path; each access opens
    the file once per process and reads only the requested samples' chunks) or in a
    NumPy array. ``index`` selects and orders samples of the source without copying.

    Indexing on the first axis returns NumPy arrays: ``view[i]`` is ``(T, H, W, 3)``,
    ``view[a:b]`` and ``view[[i, j]]`` are ``(k, T, H, W, 3)``. ``np.asarray(view)``
    reads everything.

    Raises
    ------
    DataError
        When the file cannot be opened or a sample's stored chunk cannot be decoded
        (corrupted or truncated): the message names the file, the field and the sample
        index in the file (for a :meth:`subset` view, the file's index, not the view's).
    """

    def __init__(
        self,
        source: str | os.PathLike | np.ndarray,
        index: np.ndarray | None = None,
        *,
        dataset_name: str = "images",
    ) -> None:
        self._dataset_name = dataset_name
        self._handle: h5py.File | None = None
        self._handle_pid: int | None = None
        if isinstance(source, np.ndarray):
            self._array: np.ndarray | None = source
            self._path: str | None = None
            base_shape = source.shape
        else:
            self._array = None
            self._path = os.fspath(source)
            base_shape = tuple(self._dataset().shape)
        self._base_len = base_shape[0]
        self._frame_shape = tuple(base_shape[1:])
        self._index = None if index is None else np.asarray(index, dtype=np.int64)

    # -- what it is
    @property
    def path(self) -> str | None:
        """The HDF5 file the images are read from, or None for in-memory images."""
        return self._path

    @property
    def shape(self) -> tuple[int, ...]:
        return (len(self),) + self._frame_shape

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint8)

    @property
    def ndim(self) -> int:
        return 1 + len(self._frame_shape)

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape))

    def __len__(self) -> int:
        return self._base_len if self._index is None else len(self._index)

    def __repr__(self) -> str:
        where = self._path if self._path is not None else "memory"
        return f"LazyImages(shape={self.shape}, source={where!r})"

    # -- pickling: ship the path and index, never an open HDF5 handle
    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_handle"] = None
        state["_handle_pid"] = None
        return state

    def _h5(self) -> h5py.File:
        if self._handle is None or self._handle_pid != os.getpid():
            self._handle = h5py.File(self._path, "r")
            self._handle_pid = os.getpid()
        return self._handle

    def _dataset(self) -> h5py.Dataset:
        try:
            return self._h5()[self._dataset_name]
        except (OSError, KeyError) as exc:
            raise DataError(
                f"cannot be opened ({first_line(exc)})", path=self._path, field=self._dataset_name
            ) from None

    def close(self) -> None:
        """Close the HDF5 handle (it reopens on the next read)."""
        if self._handle is not None and self._handle_pid == os.getpid():
            self._handle.close()
        self._handle = None

    # -- selection
    def _resolve(self, key) -> tuple[np.ndarray, bool]:
        """Map a first-axis key to base indices; the flag says whether the result is one sample."""
        n = len(self)
        if isinstance(key, (int, np.integer)):
            k = int(key)
            if not -n <= k < n:
                raise IndexError(f"sample index {k} out of range for {n} samples")
            local = np.array([k % n])
            single = True
        elif isinstance(key, slice):
            local = np.arange(n)[key]
            single = False
        else:
            arr = np.asarray(key)
            if arr.dtype == bool:
                if arr.shape != (n,):
                    raise IndexError(f"boolean mask of shape {arr.shape} for {n} samples")
                local = np.flatnonzero(arr)
            else:
                local = arr.astype(np.int64).reshape(-1)
                if local.size and (local.min() < -n or local.max() >= n):
                    raise IndexError(f"sample index out of range for {n} samples")
                local = local % n if local.size else local
            single = False
        base = local if self._index is None else self._index[local]
        return base, single

    def subset(self, indices) -> LazyImages:
        """A view of the selected samples (no image data is read or copied)."""
        base, _ = self._resolve(indices)
        view = LazyImages.__new__(LazyImages)
        view.__dict__.update(self.__getstate__())
        view._index = base
        return view

    def _read(self, base: np.ndarray) -> np.ndarray:
        if base.size == 0:
            return np.empty((0,) + self._frame_shape, dtype=np.uint8)
        if self._array is not None:
            return np.asarray(self._array[base], dtype=np.uint8)
        dset = self._dataset()
        lo, hi = int(base.min()), int(base.max())
        if hi - lo + 1 == base.size and np.all(np.diff(base) == 1):
            return read_samples(dset, slice(lo, hi + 1), self._path)  # one contiguous run
        uniq, inverse = np.unique(base, return_inverse=True)
        # each contiguous run as a slice: h5py's point selection of a list is ~20-50x slower
        # per sample on per-sample chunks (150 ms against 3-8 ms per 61-frame motion)
        runs = np.split(uniq, np.flatnonzero(np.diff(uniq) != 1) + 1)
        parts = [read_samples(dset, slice(int(r[0]), int(r[-1]) + 1), self._path) for r in runs]
        return np.concatenate(parts)[inverse.reshape(-1)]

    def __getitem__(self, key):
        rest = ()
        if isinstance(key, tuple):
            key, rest = key[0], key[1:]
        base, single = self._resolve(key)
        out = self._read(base)
        if single:
            out = out[0]
        return out[(slice(None),) * (0 if single else 1) + rest] if rest else out

    def __array__(self, dtype=None, copy=None):
        out = self[:]
        return out if dtype is None else out.astype(dtype)

    def iter_blocks(self, block: int = IMAGE_BLOCK):
        """Yield ``(start, images[start:start+block])`` over all samples."""
        for start in range(0, len(self), block):
            yield start, self[start : start + block]


def as_view(images) -> LazyImages:
    """``images`` as a :class:`LazyImages` view (an in-memory array is wrapped, not copied)."""
    return images if isinstance(images, LazyImages) else LazyImages(images)


def read_samples(dset: h5py.Dataset, rows, path, field_name: str = "images") -> np.ndarray:
    """``dset[rows]`` for a slice or increasing indices; an undecodable sample is a DataError.

    On a read failure (a corrupted chunk, a truncated file) the samples are read one by
    one to name the first that fails, so the message says which sample to look at.
    """
    try:
        return dset[rows]
    except OSError as exc:
        cause = first_line(exc)
    candidates = range(*rows.indices(dset.shape[0])) if isinstance(rows, slice) else rows
    for k in candidates:
        try:
            dset[int(k)]
        except OSError as exc:
            raise DataError(
                f"cannot be read, its stored data is corrupted or truncated ({first_line(exc)})",
                path=path,
                field=field_name,
                index=int(k),
            ) from None
    raise DataError(f"cannot be read, the file may be corrupted ({cause})", path=path, field=field_name) from None
