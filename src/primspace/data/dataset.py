"""`MotionDataset`: demonstrations of fixed length T, and its HDF5 file.

One file holds one data set. Arrays are batch-first, ``(n, T, J)``:

=========  =======================================  ===================  ========
node       type                                     shape                required
=========  =======================================  ===================  ========
motor      float32, joint values in physical units  (N, T, J)           yes
images     uint8, one compressed chunk per sample   (N, T, H, W, 3)      no
labels     int32, primitive index, -1 = unknown     (N,)                 no
params     float32, generative factors              (N, P)               no
=========  =======================================  ===================  ========

File attributes: ``schema_version``, ``joint_names``, ``label_names``, ``param_names``,
``dt`` (seconds between steps) and ``source`` (free text: where the data came from).

Images are read lazily: :class:`LazyImages` reads only the samples asked for, so a
gigabyte image set is never loaded twice, and :meth:`MotionDataset.subset` selects
train/eval samples without copying images.

Every check names the file, the field and the sample index, e.g.
``demo.h5, field 'motor', sample 12: contains NaN or inf``. Values too large for
float32 are refused before the cast (named as too large, not as the inf the cast would
make), and an image chunk that cannot be decoded (a corrupted or truncated file) is a
:class:`~primspace.errors.DataError` naming the file, field ``images`` and the sample,
on every read path: :class:`LazyImages` indexing, :meth:`MotionDataset.load_images`,
:meth:`MotionDataset.save` and :meth:`DatasetWriter.copy_from`.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import h5py
import numpy as np

from primspace.errors import DataError, UserError, first_line
from primspace.data.values import as_float32, check_finite, check_int32_labels
from primspace.files import atomic_path

__all__ = ["MotionDataset", "LazyImages", "DatasetWriter", "SCHEMA_VERSION"]

#: Version of the HDF5 layout written by :meth:`MotionDataset.save`.
SCHEMA_VERSION = 1

_IMAGE_WRITE_BLOCK = 32  # samples per write when copying images into a file


# ----------------------------------------------------------------------------- images


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

    def subset(self, indices) -> "LazyImages":
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
            return _read_samples(dset, slice(lo, hi + 1), self._path)  # one contiguous run
        uniq, inverse = np.unique(base, return_inverse=True)
        return _read_samples(dset, uniq, self._path)[inverse]  # h5py needs increasing indices

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

    def iter_blocks(self, block: int = _IMAGE_WRITE_BLOCK):
        """Yield ``(start, images[start:start+block])`` over all samples."""
        for start in range(0, len(self), block):
            yield start, self[start : start + block]


# ---------------------------------------------------------------------------- dataset


@dataclass(eq=False)
class MotionDataset:
    """Demonstrations as fixed-length joint sequences, with optional images, labels, params.

    Parameters
    ----------
    motor : array-like, shape (N, T, J)
        Joint values in physical units (stored as float32).
    images : array-like or LazyImages, shape (N, T, H, W, 3), uint8, optional
        Camera frames, one per time step.
    labels : array-like of int, shape (N,), optional
        Primitive index per sample, ``-1`` for unknown.
    params : array-like, shape (N, P), optional
        Generative factors (block x, y, size ...).
    joint_names, label_names, param_names : list of str, optional
        Names; defaults are ``j0..``, ``0..`` (one per label value), ``p0..``.
    dt : float, default 1.0
        Seconds between time steps.
    source : str
        Where the data came from (free text, kept in the file).

    Raises
    ------
    DataError
        If any field is malformed; the message names the field and sample index.

    Examples
    --------
    >>> import numpy as np
    >>> ds = MotionDataset(np.zeros((4, 10, 2)), labels=[0, 0, 1, -1])
    >>> len(ds), ds.length, ds.n_joints, ds.label_names
    (4, 10, 2, ['0', '1'])
    """

    motor: np.ndarray
    images: Any = None
    labels: np.ndarray | None = None
    params: np.ndarray | None = None
    joint_names: list[str] | None = None
    label_names: list[str] | None = None
    param_names: list[str] | None = None
    dt: float = 1.0
    source: str = ""
    path: Path | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.motor = as_float32(self.motor, "motor", self.path)
        if self.images is not None and not isinstance(self.images, LazyImages):
            images = np.asarray(self.images)
            if images.dtype != np.uint8:
                raise DataError(f"images must be uint8, got {images.dtype}", path=self.path, field="images")
            self.images = images
        if self.labels is not None:
            labels = np.asarray(self.labels)
            if labels.size and labels.dtype.kind not in "iu":
                raise DataError(f"labels must be integers, got {labels.dtype}", path=self.path, field="labels")
            check_int32_labels(labels, self.path)
            self.labels = labels.astype(np.int32)
        if self.params is not None:
            self.params = as_float32(self.params, "params", self.path)
        n_joints = self.motor.shape[-1] if self.motor.ndim == 3 else 0
        self.joint_names = _names(self.joint_names, n_joints, "j")
        if self.label_names is None:
            top = int(self.labels.max()) + 1 if self.labels is not None and self.labels.size else 0
            self.label_names = [str(i) for i in range(max(top, 0))]
        else:
            self.label_names = [str(s) for s in self.label_names]
        n_params = self.params.shape[-1] if self.params is not None and self.params.ndim == 2 else 0
        self.param_names = _names(self.param_names, n_params, "p")
        self.dt = float(self.dt)
        self.source = str(self.source)
        self.validate()

    # ----------------------------------------------------------------- shape summary
    def __len__(self) -> int:
        return self.motor.shape[0]

    @property
    def n_samples(self) -> int:
        return self.motor.shape[0]

    @property
    def length(self) -> int:
        """T, the number of time steps."""
        return self.motor.shape[1]

    @property
    def n_joints(self) -> int:
        """J, the number of joint values per step."""
        return self.motor.shape[2]

    @property
    def has_images(self) -> bool:
        return self.images is not None

    @property
    def image_size(self) -> tuple[int, int] | None:
        """(H, W) of the frames, or None."""
        return None if self.images is None else tuple(self.images.shape[2:4])

    @property
    def has_labels(self) -> bool:
        return self.labels is not None

    # -------------------------------------------------------------------- validation
    def validate(self) -> None:
        """Check every field; raise :class:`DataError` naming file, field and sample."""
        p = self.path
        m = self.motor
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
        if len(self.joint_names) != j:
            raise DataError(f"{len(self.joint_names)} joint names for J={j} joints", path=p, field="joint_names")
        if len(set(self.joint_names)) != j:
            raise DataError("joint names are not unique", path=p, field="joint_names")
        if self.images is not None:
            s = tuple(self.images.shape)
            if len(s) != 5 or s[4] != 3:
                raise DataError(f"must have shape (N, T, H, W, 3), got {s}", path=p, field="images")
            if s[0] != n:
                raise DataError(f"{s[0]} samples but motor has {n}", path=p, field="images")
            if s[1] != t:
                raise DataError(f"{s[1]} time steps but motor has T={t}", path=p, field="images")
            if self.images.dtype != np.uint8:
                raise DataError(f"must be uint8, got {self.images.dtype}", path=p, field="images")
        if self.labels is not None:
            lab = self.labels
            if lab.shape != (n,):
                raise DataError(f"must have shape ({n},) to match motor, got {lab.shape}", path=p, field="labels")
            k = len(self.label_names)
            bad = np.flatnonzero((lab < -1) | (lab >= k))
            if bad.size:
                i = int(bad[0])
                raise DataError(
                    f"label {int(lab[i])} out of range [-1, {k - 1}] ({k} label names)",
                    path=p, field="labels", index=i,
                )
        if self.params is not None:
            pr = self.params
            if pr.ndim != 2 or pr.shape[0] != n:
                raise DataError(f"must have shape ({n}, P), got {pr.shape}", path=p, field="params")
            check_finite(pr, "params", p)
            if len(self.param_names) != pr.shape[1]:
                raise DataError(
                    f"{len(self.param_names)} names for P={pr.shape[1]} params", path=p, field="param_names"
                )
        if not np.isfinite(self.dt) or self.dt <= 0:
            raise DataError(f"must be a positive number, got {self.dt}", path=p, field="dt")

    # ----------------------------------------------------------------------- subsets
    def subset(self, indices) -> "MotionDataset":
        """The samples at ``indices`` (ints or a boolean mask), in that order.

        Motor, labels and params are copied (they are small); images stay a lazy view
        of the same file or array, so no image data is read or copied.
        """
        idx = np.asarray(indices)
        if idx.dtype == bool:
            if idx.shape != (len(self),):
                raise UserError(f"boolean mask of shape {idx.shape} for {len(self)} samples")
            idx = np.flatnonzero(idx)
        elif idx.size and idx.dtype.kind not in "iu":
            raise UserError(f"sample indices must be integers, got {idx.dtype}")
        idx = idx.astype(np.int64).reshape(-1)
        if idx.size and (idx.min() < 0 or idx.max() >= len(self)):
            bad = int(idx[(idx < 0) | (idx >= len(self))][0])
            raise UserError(f"sample index {bad} out of range for {len(self)} samples")
        if idx.size == 0:
            raise UserError("an empty selection of samples")
        images = None
        if self.images is not None:
            base = self.images if isinstance(self.images, LazyImages) else LazyImages(self.images)
            images = base.subset(idx)
        return MotionDataset(
            motor=self.motor[idx],
            images=images,
            labels=None if self.labels is None else self.labels[idx],
            params=None if self.params is None else self.params[idx],
            joint_names=list(self.joint_names),
            label_names=list(self.label_names),
            param_names=list(self.param_names),
            dt=self.dt,
            source=self.source,
            path=self.path,
        )

    def without_images(self) -> "MotionDataset":
        """The same samples with the images dropped."""
        return MotionDataset(
            motor=self.motor, labels=self.labels, params=self.params,
            joint_names=list(self.joint_names), label_names=list(self.label_names),
            param_names=list(self.param_names), dt=self.dt, source=self.source, path=self.path,
        )

    # ---------------------------------------------------------------------------- io
    def save(self, path: str | os.PathLike, overwrite: bool = False, compression_level: int = 4) -> Path:
        """Write the data set to an HDF5 file, atomically.

        Images are written in blocks of samples, one gzip-compressed chunk per sample,
        so saving a lazily-read image set never holds it all in memory.

        Raises
        ------
        OutputExistsError
            If ``path`` exists and ``overwrite`` is false.
        """
        path = Path(path)
        with DatasetWriter(
            path,
            n_samples=len(self),
            length=self.length,
            joint_names=self.joint_names,
            image_size=self.image_size,
            label_names=self.label_names,
            param_names=self.param_names,
            with_labels=self.labels is not None,
            with_params=self.params is not None,
            dt=self.dt,
            source=self.source,
            overwrite=overwrite,
            compression_level=compression_level,
        ) as writer:
            view = None
            if self.images is not None:
                view = self.images if isinstance(self.images, LazyImages) else LazyImages(self.images)
            for start in range(0, len(self), _IMAGE_WRITE_BLOCK):
                stop = min(start + _IMAGE_WRITE_BLOCK, len(self))
                writer.write(
                    start,
                    motor=self.motor[start:stop],
                    images=None if view is None else view[start:stop],
                    labels=None if self.labels is None else self.labels[start:stop],
                    params=None if self.params is None else self.params[start:stop],
                )
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "MotionDataset":
        """Read and validate a data set file; images stay on disk until accessed.

        Raises
        ------
        DataError
            If the file is missing, not HDF5, truncated, or any field is invalid.
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
                version = _attr_number(f, "schema_version", None, path)
                if version is not None and not (np.isfinite(version) and version == int(version) and version >= 1):
                    raise DataError(f"must be a positive integer, got {version:g}", path=path, field="schema_version")
                if version is not None and int(version) > SCHEMA_VERSION:
                    raise DataError(
                        f"schema version {int(version)} is newer than this primspace reads ({SCHEMA_VERSION})",
                        path=path, field="schema_version",
                    )
                if "motor" not in f:
                    raise DataError("missing (every data set needs joint values)", path=path, field="motor")
                motor = _read_array(f, "motor", path)
                if motor.dtype.kind != "f":
                    raise DataError(f"must be floating point, got {motor.dtype}", path=path, field="motor")
                labels = _read_array(f, "labels", path) if "labels" in f else None
                params = _read_array(f, "params", path) if "params" in f else None
                has_images = "images" in f
                if has_images:
                    im = f["images"]
                    if not isinstance(im, h5py.Dataset):
                        raise DataError("is not an array", path=path, field="images")
                    if im.dtype != np.uint8:
                        raise DataError(f"must be uint8, got {im.dtype}", path=path, field="images")
                attrs = {
                    "joint_names": _str_list(f.attrs.get("joint_names")),
                    "label_names": _str_list(f.attrs.get("label_names")),
                    "param_names": _str_list(f.attrs.get("param_names")),
                    "dt": _attr_number(f, "dt", 1.0, path),
                    "source": _as_str(f.attrs.get("source", "")),
                }
        except DataError:
            raise
        except (OSError, KeyError, ValueError, TypeError) as exc:
            raise DataError(f"cannot read the file ({first_line(exc)})", path=path) from None
        images = None
        if has_images:
            try:
                images = LazyImages(path)
            except OSError as exc:
                raise DataError(f"cannot read ({first_line(exc)})", path=path, field="images") from None
        try:
            return cls(
                motor=motor, images=images, labels=labels, params=params,
                joint_names=attrs["joint_names"] or None,
                label_names=attrs["label_names"] if attrs["label_names"] or labels is None else None,
                param_names=attrs["param_names"] or None,
                dt=attrs["dt"], source=attrs["source"], path=path,
            )
        except DataError as exc:
            raise exc.located(path=path) from None

    def load_images(self) -> "MotionDataset":
        """Return a copy whose images are read into memory once (for fast training)."""
        if self.images is None or not isinstance(self.images, LazyImages):
            return self
        out = self.subset(np.arange(len(self)))
        out.images = np.asarray(self.images)
        return out

    def summary(self) -> dict:
        """What ``primspace info`` prints: sizes, names, label counts, per-joint ranges."""
        counts = Counter(int(v) for v in self.labels) if self.labels is not None else Counter()
        label_counts = {name: counts.get(i, 0) for i, name in enumerate(self.label_names)}
        if counts.get(-1):
            label_counts["<unknown>"] = counts[-1]
        lo = self.motor.min(axis=(0, 1))
        hi = self.motor.max(axis=(0, 1))
        out = {
            "path": None if self.path is None else str(self.path),
            "n_samples": self.n_samples,
            "length": self.length,
            "n_joints": self.n_joints,
            "joint_names": list(self.joint_names),
            "dt": self.dt,
            "source": self.source,
            "label_counts": label_counts if self.labels is not None else None,
            "image_shape": None if self.images is None else list(self.images.shape[1:]),
            "joint_ranges": {
                name: [float(a), float(b)] for name, a, b in zip(self.joint_names, lo, hi)
            },
        }
        if self.params is not None:
            out["param_ranges"] = {
                name: [float(a), float(b)]
                for name, a, b in zip(self.param_names, self.params.min(0), self.params.max(0))
            }
        return out


# ---------------------------------------------------------------------------- writer


class DatasetWriter:
    """Write a data set into an HDF5 file block by block, then publish it atomically.

    For data too large to hold at once (a simulated image set, shards arriving from
    workers): the file is created at a temporary path with every array sized for
    ``n_samples``; :meth:`write` validates and stores a block of samples at any offset;
    leaving the ``with`` block without an error checks that every sample was written
    and renames the file into place. On an error the temporary file is removed and
    nothing is left at ``path``.

    Parameters
    ----------
    path : path-like
        Final file.
    n_samples, length : int
        N and T.
    joint_names : list of str
        J names.
    image_size : (H, W), optional
        Frame size, or None for a data set without images.
    label_names, param_names : list of str
    with_labels, with_params : bool, optional
        Whether the file holds labels / params (default: names were given).
    dt : float
    source : str
    overwrite : bool
        Replace an existing file (else :class:`~primspace.errors.OutputExistsError`,
        raised before anything is written).
    compression_level : int
        gzip level of the per-sample image chunks.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "d.h5")
    >>> with DatasetWriter(path, n_samples=2, length=5, joint_names=["a"]) as w:
    ...     w.write(0, motor=np.zeros((2, 5, 1)))
    >>> MotionDataset.load(path).motor.shape
    (2, 5, 1)
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        n_samples: int,
        length: int,
        joint_names: Sequence[str],
        image_size: tuple[int, int] | None = None,
        label_names: Sequence[str] = (),
        param_names: Sequence[str] = (),
        with_labels: bool | None = None,
        with_params: bool | None = None,
        dt: float = 1.0,
        source: str = "",
        overwrite: bool = False,
        compression_level: int = 4,
    ) -> None:
        self.path = Path(path)
        self.n_samples, self.length = int(n_samples), int(length)
        self.joint_names = [str(s) for s in joint_names]
        self.image_size = None if image_size is None else (int(image_size[0]), int(image_size[1]))
        self.label_names = [str(s) for s in label_names]
        self.param_names = [str(s) for s in param_names]
        self.with_labels = bool(self.label_names) if with_labels is None else with_labels
        self.with_params = bool(self.param_names) if with_params is None else with_params
        self.dt, self.source = float(dt), str(source)
        self.overwrite = overwrite
        self.compression_level = compression_level
        if self.n_samples < 1 or self.length < 2 or not self.joint_names:
            raise DataError(
                f"a data set needs N >= 1, T >= 2 and J >= 1, got N={self.n_samples}, T={self.length}, "
                f"J={len(self.joint_names)}", path=self.path, field="motor",
            )
        self._written = np.zeros(self.n_samples, dtype=bool)
        self._stack: contextlib.ExitStack | None = None
        self._file: h5py.File | None = None

    def __enter__(self) -> "DatasetWriter":
        stack = contextlib.ExitStack()
        tmp = stack.enter_context(atomic_path(self.path, overwrite=self.overwrite))
        try:
            f = stack.enter_context(h5py.File(tmp, "w"))
            f.attrs["schema_version"] = SCHEMA_VERSION
            f.attrs["joint_names"] = np.array(self.joint_names, dtype=h5py.string_dtype())
            f.attrs["label_names"] = np.array(self.label_names, dtype=h5py.string_dtype())
            f.attrs["param_names"] = np.array(self.param_names, dtype=h5py.string_dtype())
            f.attrs["dt"] = self.dt
            f.attrs["source"] = self.source
            n, t = self.n_samples, self.length
            f.create_dataset("motor", shape=(n, t, len(self.joint_names)), dtype=np.float32)
            if self.with_labels:
                f.create_dataset("labels", shape=(n,), dtype=np.int32, fillvalue=-1)
            if self.with_params:
                f.create_dataset("params", shape=(n, len(self.param_names)), dtype=np.float32)
            if self.image_size is not None:
                shape = (n, t, *self.image_size, 3)
                f.create_dataset(
                    "images", shape=shape, dtype=np.uint8, chunks=(1,) + shape[1:],
                    compression="gzip", compression_opts=self.compression_level,
                )
        except BaseException:
            stack.__exit__(*sys.exc_info())
            raise
        self._stack, self._file = stack, f
        return self

    def write(self, start: int, *, motor, images=None, labels=None, params=None) -> None:
        """Validate and store samples ``start .. start + len(motor) - 1``."""
        block, sl = self._check_block(start, motor, images, labels, params)
        if images is not None:
            self._file["images"][sl] = np.asarray(block.images)
        self._store(block, sl)

    def copy_from(self, start: int, path: str | os.PathLike) -> int:
        """Copy every sample of the data set file ``path`` into samples ``start ..``.

        For merging shards written by workers into one file. The source is loaded and
        validated as :meth:`MotionDataset.load` does; its names, T, J, image size and
        fields must match this file's. Motor, labels and params are copied as arrays.
        Image chunks are copied as stored (``read_direct_chunk`` /
        ``write_direct_chunk``: no recompression) when the source's chunk shape and
        filter pipeline equal this file's, each decoded once on the way to check that it
        is intact (a corrupted chunk is refused, never copied); otherwise the images are
        decoded and re-encoded block by block.

        Returns
        -------
        int
            The number of samples copied.

        Raises
        ------
        DataError
            If the source is not a valid data set file or does not match this file
            (naming the source file and the field), or does not fit at ``start``, or
            one of its image chunks cannot be decoded (naming the source sample).
        """
        if self._file is None:
            raise RuntimeError("DatasetWriter.copy_from outside its with block")
        source = MotionDataset.load(path)
        try:
            try:
                block, sl = self._check_block(start, source.motor, source.images, source.labels, source.params)
            except DataError as exc:
                raise DataError(f"cannot be copied into {self.path}: {exc.reason}", path=path, field=exc.field) from None
            wanted = [("joint_names", self.joint_names), ("dt", self.dt)]
            if self.with_labels and self.label_names:
                wanted.append(("label_names", self.label_names))
            if self.with_params and self.param_names:
                wanted.append(("param_names", self.param_names))
            for name, value in wanted:
                if getattr(source, name) != value:
                    raise DataError(f"{getattr(source, name)} does not match the file's {value}", path=path, field=name)
            if source.images is not None:
                self._copy_image_chunks(source.path, sl)
            self._store(block, sl)
        finally:
            if source.images is not None:
                source.images.close()
        return sl.stop - sl.start

    def _check_block(self, start: int, motor, images, labels, params) -> tuple["MotionDataset", slice]:
        """Validate a block of samples against this file; return it and its slice."""
        if self._file is None:
            raise RuntimeError("DatasetWriter.write outside its with block")
        motor = as_float32(motor, "motor", self.path)
        k = motor.shape[0] if motor.ndim == 3 else 0
        block = MotionDataset(
            motor=motor,
            images=images,
            labels=labels,
            params=params,
            joint_names=self.joint_names,
            label_names=(self.label_names or None) if labels is not None else None,
            param_names=(self.param_names or None) if params is not None else None,
            dt=self.dt,
        ) if k else None
        if block is None or not 0 <= start or start + k > self.n_samples:
            raise DataError(
                f"block of {k} samples at {start} does not fit in N={self.n_samples}", path=self.path, field="motor"
            )
        checks = [
            ("motor", block.motor.shape[1:], (self.length, len(self.joint_names))),
            ("images", None if images is None else block.images.shape[2:4], self.image_size),
        ]
        for name, got, want in checks:
            if got != want:
                if got is None or want is None:
                    raise DataError(
                        "missing from a block" if got is None else "given but the file has none",
                        path=self.path, field=name, index=start,
                    )
                raise DataError(f"block shape {got} does not match the file's {want}", path=self.path, field=name, index=start)
        for name, given, wanted in (("labels", labels, self.with_labels), ("params", params, self.with_params)):
            if (given is not None) != wanted:
                raise DataError(
                    "given but the file has none" if given is not None else "missing from a block",
                    path=self.path, field=name, index=start,
                )
        return block, slice(start, start + k)

    def _store(self, block: "MotionDataset", sl: slice) -> None:
        """Store a checked block's motor, labels and params; mark its samples written."""
        f = self._file
        f["motor"][sl] = block.motor
        if block.labels is not None:
            f["labels"][sl] = block.labels
        if block.params is not None:
            f["params"][sl] = block.params
        self._written[sl] = True

    def _copy_image_chunks(self, path: Path, sl: slice) -> None:
        """Images of the file ``path`` into ``sl``: raw chunks when the storage matches."""
        target = self._file["images"]
        try:
            with h5py.File(path, "r") as f:
                source = f["images"]
                if source.chunks == target.chunks and _filters(source) == _filters(target):
                    rest = (0,) * (source.ndim - 1)
                    for i in range(sl.stop - sl.start):
                        # decode once (no recompression): a corrupted chunk is refused, not copied
                        _read_samples(source, slice(i, i + 1), path)
                        mask, chunk = source.id.read_direct_chunk((i, *rest))
                        target.id.write_direct_chunk((sl.start + i, *rest), chunk, mask)
                else:
                    for a in range(0, sl.stop - sl.start, _IMAGE_WRITE_BLOCK):
                        b = min(a + _IMAGE_WRITE_BLOCK, sl.stop - sl.start)
                        target[sl.start + a : sl.start + b] = _read_samples(source, slice(a, b), path)
        except (OSError, KeyError) as exc:
            raise DataError(f"cannot be read, the file may be truncated ({first_line(exc)})", path=path, field="images") from None

    def __exit__(self, exc_type, exc, tb) -> bool:
        stack, self._stack, self._file = self._stack, None, None
        if exc_type is None and not self._written.all():
            missing = int(np.flatnonzero(~self._written)[0])
            try:
                raise DataError(
                    f"{int((~self._written).sum())} samples never written", path=self.path, field="motor", index=missing
                )
            except DataError:
                stack.__exit__(*sys.exc_info())
                raise
        return bool(stack.__exit__(exc_type, exc, tb))


# --------------------------------------------------------------------------- helpers


def _read_samples(dset: h5py.Dataset, rows, path, field_name: str = "images") -> np.ndarray:
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
                path=path, field=field_name, index=int(k),
            ) from None
    raise DataError(f"cannot be read, the file may be corrupted ({cause})", path=path, field=field_name) from None


def _names(names: Sequence[str] | None, n: int, prefix: str) -> list[str]:
    if names is None or len(names) == 0:
        return [f"{prefix}{i}" for i in range(n)]
    return [str(s) for s in names]


def _filters(dataset: h5py.Dataset) -> list[tuple]:
    """The filter pipeline of a dataset: (filter id, client values) per filter, in order."""
    plist = dataset.id.get_create_plist()
    return [tuple(plist.get_filter(i)[::2]) for i in range(plist.get_nfilters())]


def _read_array(f: h5py.File, name: str, path) -> np.ndarray:
    node = f[name]
    if not isinstance(node, h5py.Dataset):
        raise DataError("is not an array", path=path, field=name)
    try:
        return node[()]
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot be read, the file may be truncated ({first_line(exc)})", path=path, field=name) from None


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

