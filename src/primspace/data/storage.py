"""The data set's HDF5 file written: block by block, and files merged into it
(:class:`DatasetWriter`); reading it is :mod:`primspace.data.reading`'s.

Which nodes and attributes a file has, their types, shapes, chunks and compression come
from the schema table (:data:`primspace.data.schema.FIELDS`); this module only knows how
to move them between HDF5 and NumPy. Every error names the file, the field and, when it
applies, the sample.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np

from primspace.data.checks import checked_fields
from primspace.data.images import IMAGE_BLOCK, as_view, read_samples
from primspace.data.reading import read_fields
from primspace.data.schema import (
    ARRAYS,
    ATTRIBUTES,
    SCHEMA_VERSION,
    WRITER_ATTRIBUTE,
    Field,
    arrays_of,
    dims_of,
    field,
)
from primspace.data.values import as_float32
from primspace.utils.errors import DataError, first_line
from primspace.utils.files import atomic_path, check_free_space

__all__ = ["DatasetWriter", "write_dataset"]

#: Arrays held in memory (contiguous), then those read on demand (chunked per sample):
#: the order a file's arrays are created and stored in.
_EAGER = tuple(f for f in ARRAYS if not f.lazy)
_LAZY = tuple(f for f in ARRAYS if f.lazy)


def write_dataset(ds, path: Path, overwrite: bool, compression_level: int, writer=None) -> Path:
    """Write the data set ``ds`` to ``path`` in blocks of samples (see :meth:`MotionDataset.save`);
    refused first when its disk cannot hold the arrays uncompressed (:func:`~primspace.utils.files.check_free_space`)."""
    check_free_space(path, (1 << 20) + sum(_raw_bytes(v) for v in arrays_of(ds).values() if v is not None))
    settings = {a.writer_option: _option_value(a, getattr(ds, a.name)) for a in ARRAYS if a.writer_option}
    with DatasetWriter(
        path,
        n_samples=len(ds),
        length=ds.length,
        **{a.name: getattr(ds, a.name) for a in ATTRIBUTES if a.in_memory},
        **settings,
        overwrite=overwrite,
        compression_level=compression_level,
        writer=writer,
    ) as out:
        arrays = arrays_of(ds)
        for a in _LAZY:  # read (and decoded) block by block, never all at once
            if arrays[a.name] is not None:
                arrays[a.name] = as_view(arrays[a.name])
        for start in range(0, len(ds), IMAGE_BLOCK):
            stop = min(start + IMAGE_BLOCK, len(ds))
            out.write(start, **{name: None if v is None else v[start:stop] for name, v in arrays.items()})
    return path


def _raw_bytes(values) -> int:
    """Bytes of an array (or an array-like with ``shape`` and ``dtype``) uncompressed; 0 if unknown."""
    try:
        return int(np.prod(values.shape, dtype=np.int64)) * np.dtype(values.dtype).itemsize
    except (AttributeError, TypeError):
        return 0


def _option_value(array: Field, value):
    """The writer option of an optional array: its ``block_dims`` (``image_size``), else
    whether it is there (``with_labels``)."""
    if not array.block_dims:
        return value is not None
    if value is None:
        return None
    dims = dims_of({array.name: value})
    return tuple(dims[d] for d in array.block_dims)


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
    with_steps, with_source_ids : bool
        Whether the file holds ``lengths``, ``step_labels`` and ``step_segments``; ``source_ids``.
    scene_names : list of str
        S names of the ``scene`` array (a simulator's scene that varies per sample).
    with_scene : bool, optional
        Whether the file holds ``scene`` (default: scene names were given).
    dt : float
    source : str
    overwrite : bool
        Replace an existing file (else :class:`~primspace.utils.errors.OutputExistsError`,
        raised before anything is written).
    compression_level : int
        gzip level of the per-sample image chunks.
    writer : str, optional
        A mark of the program writing the file (e.g. ``"primspace simulate"``), stored
        as the file attribute ``primspace_writer`` and read back by :func:`~primspace.utils.outputs.file_writer`;
        None (default) writes no mark.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from primspace.data import MotionDataset
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
        with_steps: bool = False,
        with_source_ids: bool = False,
        scene_names: Sequence[str] = (),
        with_scene: bool | None = None,
        dt: float = 1.0,
        source: str = "",
        overwrite: bool = False,
        compression_level: int = 4,
        writer: str | None = None,
    ) -> None:
        self.path = Path(path)
        self.writer = None if writer is None else str(writer)
        self.n_samples, self.length = int(n_samples), int(length)
        self.joint_names = [str(s) for s in joint_names]
        self.image_size = None if image_size is None else (int(image_size[0]), int(image_size[1]))
        self.label_names = [str(s) for s in label_names]
        self.param_names = [str(s) for s in param_names]
        self.with_labels = bool(self.label_names) if with_labels is None else with_labels
        self.with_params = bool(self.param_names) if with_params is None else with_params
        self.with_steps, self.with_source_ids = bool(with_steps), bool(with_source_ids)
        self.scene_names = [str(s) for s in scene_names]
        self.with_scene = bool(self.scene_names) if with_scene is None else with_scene
        self.dt, self.source = float(dt), str(source)
        self.overwrite = overwrite
        self.compression_level = compression_level
        if self.n_samples < 1 or self.length < 2 or not self.joint_names:
            raise DataError(
                f"a data set needs N >= 1, T >= 2 and J >= 1, got N={self.n_samples}, T={self.length}, "
                f"J={len(self.joint_names)}",
                path=self.path,
                field="motor",
            )
        self._written = np.zeros(self.n_samples, dtype=bool)
        self._stack: contextlib.ExitStack | None = None
        self._file: h5py.File | None = None

    # -- the file's layout
    def _holds(self, array: Field) -> bool:
        """Whether the file has ``array`` (required, or its writer option says so)."""
        return array.required or bool(getattr(self, array.writer_option))

    def _dims(self) -> dict[str, int]:
        """The file's dimensions, by schema symbol."""
        dims = {"N": self.n_samples, "T": self.length, "J": len(self.joint_names), "P": len(self.param_names)}
        dims["S"] = len(self.scene_names)
        if self.image_size is not None:
            dims["H"], dims["W"] = self.image_size
        return dims

    def __enter__(self) -> DatasetWriter:
        stack = contextlib.ExitStack()
        tmp = stack.enter_context(atomic_path(self.path, overwrite=self.overwrite))
        try:
            f = stack.enter_context(h5py.File(tmp, "w"))
            for attr in ATTRIBUTES:
                if not attr.with_owner_only or self._holds(field(attr.owner)):
                    f.attrs[attr.name] = self._attribute_value(attr)
            if self.writer is not None:
                f.attrs[WRITER_ATTRIBUTE] = self.writer
            dims = self._dims()
            for array in _EAGER + _LAZY:  # as files have always been laid out: small arrays first
                if self._holds(array):
                    f.create_dataset(array.name, **array.create_options(dims, self.compression_level))
        except BaseException:
            stack.__exit__(*sys.exc_info())
            raise
        self._stack, self._file = stack, f
        return self

    def _attribute_value(self, attr: Field):
        if attr.codec == "version":
            return SCHEMA_VERSION
        if attr.codec == "strings":
            return np.array(getattr(self, attr.name), dtype=h5py.string_dtype())
        return getattr(self, attr.name)

    # -- blocks
    def write(
        self,
        start: int,
        *,
        motor,
        images=None,
        labels=None,
        params=None,
        lengths=None,
        step_labels=None,
        step_segments=None,
        source_ids=None,
        scene=None,
    ) -> None:
        """Validate and store samples ``start .. start + len(motor) - 1``."""
        block, sl = self._check_block(
            start,
            dict(
                motor=motor,
                images=images,
                labels=labels,
                params=params,
                lengths=lengths,
                step_labels=step_labels,
                step_segments=step_segments,
                source_ids=source_ids,
                scene=scene,
            ),
        )
        for array in _LAZY:
            value = getattr(block, array.name)
            if value is not None:
                self._file[array.name][sl] = np.asarray(value)
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
        values = read_fields(path)  # read and checked as MotionDataset.load does
        try:
            source = checked_fields(values, Path(path))
        except DataError as exc:
            raise exc.located(path=Path(path)) from None
        try:
            try:
                block, sl = self._check_block(start, arrays_of(source))
            except DataError as exc:
                raise DataError(
                    f"cannot be copied into {self.path}: {exc.reason}", path=path, field=exc.field
                ) from None
            for name in self._names_to_match():
                if getattr(source, name) != getattr(self, name):
                    raise DataError(
                        f"{getattr(source, name)} does not match the file's {getattr(self, name)}",
                        path=path,
                        field=name,
                    )
            for array in _LAZY:
                if getattr(source, array.name) is not None:
                    self._copy_chunks(array.name, source.path, sl)
            self._store(block, sl)
        finally:
            for array in _LAZY:
                if getattr(source, array.name) is not None:
                    getattr(source, array.name).close()
        return sl.stop - sl.start

    def _names_to_match(self) -> list[str]:
        """Attributes a merged file must share: names of required arrays, ``dt``, then
        names of the optional arrays this file holds (when it names them)."""
        arrays = {a.name: a for a in ARRAYS}
        first, then = [], []
        for attr in ATTRIBUTES:
            if not attr.matched:
                continue
            owner = arrays.get(attr.owner)
            if owner is None or owner.required:
                first.append(attr.name)
            elif self._holds(owner) and getattr(self, attr.name):
                then.append(attr.name)
        return first + then

    def _check_block(self, start: int, arrays: dict) -> tuple[SimpleNamespace, slice]:
        """Validate a block of samples against this file (as :class:`MotionDataset` does); return it and its slice."""
        if self._file is None:
            raise RuntimeError("DatasetWriter.write outside its with block")
        motor = as_float32(arrays["motor"], "motor", self.path)
        k = motor.shape[0] if motor.ndim == 3 else 0
        names = {}  # the file's names of the arrays given (none: the defaults)
        for attr in ATTRIBUTES:
            if attr.owner is not None:
                given = field(attr.owner).required or arrays.get(attr.owner) is not None
                names[attr.name] = (getattr(self, attr.name) or None) if given else None
        block = checked_fields(dict(arrays, motor=motor, **names, dt=self.dt)) if k else None
        if block is None or not 0 <= start or start + k > self.n_samples:
            raise DataError(
                f"block of {k} samples at {start} does not fit in N={self.n_samples}", path=self.path, field="motor"
            )
        file_dims, block_dims = self._dims(), dims_of(arrays_of(block))
        for array in ARRAYS:
            given, wanted = arrays.get(array.name) is not None, self._holds(array)
            if given != wanted:
                raise DataError(
                    "given but the file has none" if given else "missing from a block",
                    path=self.path,
                    field=array.name,
                    index=start,
                )
            if not given:
                continue
            got = tuple(block_dims[d] for d in array.block_dims)
            want = tuple(file_dims[d] for d in array.block_dims)
            if got != want:
                raise DataError(
                    f"block shape {got} does not match the file's {want}", path=self.path, field=array.name, index=start
                )
        return block, slice(start, start + k)

    def _store(self, block: SimpleNamespace, sl: slice) -> None:
        """Store a checked block's in-memory arrays (all but the images); mark its samples written."""
        for array in _EAGER:
            value = getattr(block, array.name)
            if value is not None:
                self._file[array.name][sl] = value
        self._written[sl] = True

    def _copy_chunks(self, name: str, path: Path, sl: slice) -> None:
        """The array ``name`` of the file ``path`` into ``sl``: raw chunks when the storage matches."""
        target = self._file[name]
        try:
            with h5py.File(path, "r") as f:
                source = f[name]
                if source.chunks == target.chunks and _filters(source) == _filters(target):
                    rest = (0,) * (source.ndim - 1)
                    for i in range(sl.stop - sl.start):
                        # decode once (no recompression): a corrupted chunk is refused, not copied
                        read_samples(source, slice(i, i + 1), path, name)
                        mask, chunk = source.id.read_direct_chunk((i, *rest))
                        target.id.write_direct_chunk((sl.start + i, *rest), chunk, mask)
                else:
                    for a in range(0, sl.stop - sl.start, IMAGE_BLOCK):
                        b = min(a + IMAGE_BLOCK, sl.stop - sl.start)
                        target[sl.start + a : sl.start + b] = read_samples(source, slice(a, b), path, name)
        except (OSError, KeyError) as exc:
            raise DataError(
                f"cannot be read, the file may be truncated ({first_line(exc)})", path=path, field=name
            ) from None

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


def _filters(dataset: h5py.Dataset) -> list[tuple]:
    """The filter pipeline of a dataset: (filter id, client values) per filter, in order."""
    plist = dataset.id.get_create_plist()
    return [tuple(plist.get_filter(i)[::2]) for i in range(plist.get_nfilters())]
