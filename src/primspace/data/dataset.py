"""`MotionDataset`: demonstrations of fixed length T, held in memory (images on demand).

One data set is one HDF5 file. Arrays are batch-first, ``(n, T, J)``; its fields
(``motor``, and optionally ``images``, ``labels``, ``params``; the attributes
``joint_names``, ``label_names``, ``param_names``, ``dt``, ``source``) are described
once, in the schema table :data:`primspace.data.schema.FIELDS`, which this class
iterates to convert, check, subset and summarise them. The file is read by
:mod:`primspace.data.reading` and written by :mod:`primspace.data.storage`; images are :class:`~primspace.data.images.LazyImages`
views, read only when indexed, so :meth:`MotionDataset.subset` selects train/eval
samples without copying images.

Every check names the file, the field and the sample index, e.g.
``demo.h5, field 'motor', sample 12: contains NaN or inf``. Values too large for
float32 are refused before the cast (named as too large, not as the inf the cast would
make), and an image chunk that cannot be decoded (a corrupted or truncated file) is a
:class:`~primspace.utils.errors.DataError` naming the file, field ``images`` and the sample,
on every read path: :class:`LazyImages` indexing, :meth:`MotionDataset.load_images`,
:meth:`MotionDataset.save` and :meth:`DatasetWriter.copy_from`.
"""

from __future__ import annotations

import dataclasses
import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from primspace.data.checks import convert_fields, validate_fields
from primspace.data.images import LazyImages, as_view
from primspace.data.indices import check_indices, mask_indices
from primspace.data.reading import read_fields
from primspace.data.schema import ARRAYS, SCHEMA_VERSION, names_of
from primspace.data.storage import DatasetWriter, write_dataset
from primspace.utils.errors import DataError

__all__ = ["MotionDataset", "LazyImages", "DatasetWriter", "SCHEMA_VERSION"]


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
    lengths, step_labels, step_segments : array-like of int, optional (all or none)
        Demonstrations of different lengths made of several primitives: ``lengths``
        (N,) valid steps per sample (the motor after them is padding), ``step_labels``
        (N, T) the primitive of each step and ``step_segments`` (N, T) its segment
        index (0, 1, ...), both -1 exactly at the padding.
    source_ids : sequence of str, shape (N,), optional
        Where each sample was recorded, e.g. ``robomimic:lift.hdf5:data/demo_3`` or
        ``lerobot:pusht:episode 12``: set by the importers, kept by :meth:`subset` and
        carried into predictions and experiment results (one line of text each).
    scene : array-like, shape (N, S), optional
        Each sample's scene, where a simulator varies it (:mod:`primspace.sim.variation`:
        block and table colours, light, camera pose, a distractor), named by ``scene_names``;
        kept aligned by :meth:`subset`.
    joint_names, label_names, param_names, scene_names : list of str, optional
        Names; defaults are ``j0..``, ``0..`` (one per label value), ``p0..``, ``s0..``.
    dt : float, default 1.0
        Seconds between time steps.
    source : str
        Where the data came from (free text, kept in the file).
    file_indices : array-like of int, shape (N,), optional
        The number of each sample: its index in the data file ``path`` (or, without a
        file, in the data set it was taken from). Default ``0..N-1``; :meth:`subset`
        carries it, so ``data.subset([4, 9]).file_indices`` is ``[4, 9]``. Runs, cluster
        outputs and predictions number samples by it (:mod:`primspace.data.schema`,
        *Sample numbers*). Not stored in the file: a saved subset is a new file.

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
    lengths: np.ndarray | None = None
    step_labels: np.ndarray | None = None
    step_segments: np.ndarray | None = None
    source_ids: np.ndarray | None = None
    scene: np.ndarray | None = None
    joint_names: list[str] | None = None
    label_names: list[str] | None = None
    param_names: list[str] | None = None
    scene_names: list[str] | None = None
    dt: float = 1.0
    source: str = ""
    path: Path | None = field(default=None, repr=False)
    file_indices: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        convert_fields(self)  # the arrays (motor first), then the names defaulted from them
        self.file_indices = _file_indices(self.file_indices, len(self), self.path)
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
    def valid_lengths(self) -> np.ndarray:
        """(N,) the valid steps of each sample: ``lengths``, or T each when there is no padding."""
        return self.lengths if self.lengths is not None else np.full(len(self), self.length)

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
        """Check every field; raise :class:`DataError` naming file, field and sample.

        Each array is checked (``motor`` first), then the attribute naming its last
        axis, then the attributes of no array (``dt``), in the schema table's order.
        """
        validate_fields(self)

    # ----------------------------------------------------------------------- subsets
    def subset(self, indices) -> MotionDataset:
        """The samples at ``indices`` (ints or a boolean mask), in that order.

        Motor, labels and params are copied (they are small); images stay a lazy view
        of the same file or array, so no image data is read or copied.

        Raises
        ------
        UserError
            Indices that are not integers, out of range or empty, or a mask of the wrong
            shape (:func:`~primspace.data.indices.check_indices`; a sample may repeat).
        """
        idx = np.asarray(indices)
        if idx.dtype == bool:
            idx = mask_indices(idx, len(self))
        idx = check_indices(idx.reshape(-1), len(self), unique=False)
        taken = {}
        for array in ARRAYS:
            value = getattr(self, array.name)
            if value is not None:
                taken[array.name] = as_view(value).subset(idx) if array.lazy else value[idx]
        return dataclasses.replace(self, **taken, file_indices=self.file_indices[idx])

    def rows_of(self, file_indices) -> np.ndarray | None:
        """The rows of this data set holding the samples numbered ``file_indices`` (in the
        data file, :attr:`file_indices`), in that order; None if one of them is not here."""
        row = {int(v): r for r, v in reversed(list(enumerate(self.file_indices)))}  # the first row of each number
        found = [row.get(int(i)) for i in np.asarray(file_indices).reshape(-1)]
        return None if any(r is None for r in found) else np.asarray(found, dtype=np.int64)

    def without_images(self) -> MotionDataset:
        """The same samples with the images dropped."""
        return dataclasses.replace(self, **{array.name: None for array in ARRAYS if array.lazy})

    # ---------------------------------------------------------------------------- io
    def save(
        self, path: str | os.PathLike, overwrite: bool = False, compression_level: int = 4, writer: str | None = None
    ) -> Path:
        """Write the data set to an HDF5 file, atomically.

        Images are written in blocks of samples, one gzip-compressed chunk per sample,
        so saving a lazily-read image set never holds it all in memory. ``writer``, when
        given, is stored as the file attribute ``primspace_writer`` (read back by
        :func:`primspace.utils.outputs.file_writer`).

        Raises
        ------
        OutputExistsError
            If ``path`` exists and ``overwrite`` is false.
        """
        return write_dataset(self, Path(path), overwrite, compression_level, writer=writer)

    @classmethod
    def load(cls, path: str | os.PathLike) -> MotionDataset:
        """Read and validate a data set file; images stay on disk until accessed.

        Raises
        ------
        DataError
            If the file is missing, not HDF5, truncated, or any field is invalid.
        """
        path = Path(path)
        values = read_fields(path)
        try:
            return cls(**values, path=path)
        except DataError as exc:
            raise exc.located(path=path) from None

    def load_images(self) -> MotionDataset:
        """Return a copy whose images are read into memory once (for fast training)."""
        if self.images is None or not isinstance(self.images, LazyImages):
            return self
        out = self.subset(np.arange(len(self)))
        out.images = np.asarray(self.images)
        return out

    def _steps_summary(self) -> dict | None:
        """Demonstrations of several primitives: valid lengths, segments, steps per primitive."""
        if self.lengths is None:
            return None
        segments = self.step_segments.max(axis=1) + 1
        counts = Counter(int(v) for v in self.step_labels[self.step_labels >= 0])
        return {
            "lengths": [int(self.lengths.min()), int(self.lengths.max())],
            "segments": [int(segments.min()), int(segments.max())],
            "n_segments": int(segments.sum()),
            "steps_per_label": {name: counts.get(i, 0) for i, name in enumerate(self.label_names)},
        }

    def source_id(self, index: int) -> str:
        """Where sample ``index`` was recorded (its source id), else ``sample <index>``."""
        return f"sample {index}" if self.source_ids is None else str(self.source_ids[index])

    def summary(self) -> dict:
        """What ``primspace info`` prints: sizes, names, label counts, per-joint ranges."""
        counts = Counter(int(v) for v in self.labels) if self.labels is not None else Counter()
        label_counts = {name: counts.get(i, 0) for i, name in enumerate(self.label_names)}
        if counts.get(-1):
            label_counts["<unknown>"] = counts[-1]
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
            "steps": self._steps_summary(),
        }
        if self.source_ids is not None:  # only then: files without them summarise as before
            out["source_ids"] = _first_last(self.source_ids)
        for array in ARRAYS:  # [min, max] per name of each named numeric array
            value = getattr(self, array.name)
            if array.summary_key is not None and value is not None:
                axes = tuple(range(value.ndim - 1))
                out[array.summary_key] = {
                    name: [float(a), float(b)]
                    for name, a, b in zip(getattr(self, names_of(array).name), value.min(axes), value.max(axes))
                }
        return out


def _first_last(ids: np.ndarray, shown: int = 3) -> list[str]:
    """The first and last ``shown`` source ids (all of them when there are few), for ``info``."""
    ids = [str(v) for v in ids]
    return ids if len(ids) <= 2 * shown else ids[:shown] + ["..."] + ids[-shown:]


def _file_indices(value, n: int, path) -> np.ndarray:
    """``file_indices`` as int64 (N,): ``0..N-1`` when not given; one :class:`DataError` if malformed."""
    if value is None:
        return np.arange(n, dtype=np.int64)
    out = np.asarray(value)
    if out.shape != (n,) or (out.size and (out.dtype.kind not in "iu" or out.min() < 0)):
        raise DataError(
            f"must be {n} non-negative integers (one per sample), got shape {out.shape}",
            path=path,
            field="file_indices",
        )
    return out.astype(np.int64)
