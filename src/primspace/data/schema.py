"""The data set's fields, once: one table that reading, writing, subsetting and checks iterate.

A data set file holds arrays (HDF5 datasets, batch-first) and file attributes. Each is
one :class:`Field` in :data:`FIELDS`, which says what it stores (dtype, shape, whether
it is required), how it is stored (chunks, compression, fill value), how the in-memory
:class:`~primspace.data.MotionDataset` converts and checks it (the functions are in
:mod:`primspace.data.field_checks`), and how it is subset. Code that handles "every field" iterates the table instead of naming fields:

* :class:`~primspace.data.MotionDataset` converts (``coerce``, ``normalize``) and
  checks (``validate``) every field, subsets the arrays (``lazy``: a view, else rows)
  and summarises them (``summary_key``);
* :func:`primspace.data.reading.read_fields` reads and checks the file
  (``check_stored``, ``missing``, ``codec``);
* :class:`~primspace.data.DatasetWriter` creates the file's arrays (``file_shape``,
  ``create_options``) and attributes (``codec``), checks each block against the file
  (``writer_option``, ``block_dims``) and compares a merged file's names (``owner``).

Shapes are symbolic: ``N`` samples, ``T`` time steps, ``J`` joints, ``H`` x ``W``
frames, ``P`` generative factors, ``S`` scene values; ``J``, ``P`` and ``S`` are also the
lengths of ``joint_names``, ``param_names`` and ``scene_names``. :func:`markdown_table` renders the arrays as the
table of ``docs/data.md`` (a test keeps the two equal).

Sample numbers
--------------
One rule everywhere: a sample is numbered by its index in its data file (from 0). The
``--indices`` files, a run's record (``config.json`` ``data.indices``), ``reconstruct`` and
``animate`` ``--sample``, the ``sample`` column of ``cluster`` and ``segment`` outputs and a
prediction's ``indices`` all use it. In memory, :attr:`MotionDataset.file_indices` carries
the numbers through :meth:`MotionDataset.subset`, so the rows of ``data.subset([4, 9])`` are
samples 4 and 9; a file written from a subset is a new data file, numbered from 0.

Examples
--------
>>> from primspace.data.schema import ARRAYS, field
>>> [f.name for f in ARRAYS]
['motor', 'images', 'labels', 'params', 'lengths', 'step_labels', 'step_segments', 'source_ids', 'scene']
>>> field("images").file_shape({"N": 2, "T": 5, "H": 48, "W": 64})
(2, 5, 48, 64, 3)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any, Literal

import numpy as np

from primspace.data.field_checks import (
    as_number,
    as_text,
    coerce_images,
    coerce_labels,
    coerce_motor,
    coerce_params,
    coerce_scene,
    default_label_names,
    default_names,
    stored_floating,
    stored_strings,
    stored_uint8,
    validate_dt,
    validate_images,
    validate_joint_names,
    validate_labels,
    validate_motor,
    validate_param_names,
    validate_params,
    validate_scene,
    validate_scene_names,
)
from primspace.data.steps import coerce_steps, validate_lengths, validate_step_labels, validate_step_segments
from primspace.data.values import coerce_source_ids, validate_source_ids
from primspace.utils.outputs import DATA_SET_MARK

__all__ = [
    "SCHEMA_VERSION",
    "CHECKSUM_CHUNK_BYTES",
    "WRITER_ATTRIBUTE",
    "Field",
    "FIELDS",
    "ARRAYS",
    "ATTRIBUTES",
    "field",
    "names_of",
    "arrays_of",
    "empty_arrays",
    "dims_of",
    "markdown_table",
]

#: Version of the HDF5 layout that :class:`~primspace.data.DatasetWriter` writes: 2 adds
#: the Fletcher-32 checksum of ``motor``, ``labels``, ``params`` and the step fields
#: (``Field.checksum``). Files of version 1 (no checksum) still read. The optional
#: ``source_ids`` array (0.7) kept the version: a reader that does not know it ignores it.
SCHEMA_VERSION = 2

#: The most bytes of a chunk of an array stored with a checksum (whole samples per chunk).
CHECKSUM_CHUNK_BYTES = 1 << 18

#: The optional file attribute marking which program wrote the file (``writer=`` of
#: :meth:`MotionDataset.save` and :class:`DatasetWriter`; read by
#: :func:`primspace.utils.outputs.file_writer`). Not a :class:`MotionDataset` field:
#: loading ignores it, and a file without it (every file written without ``writer=``,
#: every file of other tools) has no mark.
WRITER_ATTRIBUTE = DATA_SET_MARK  # primspace.utils.outputs reads it back


@dataclass(frozen=True)
class Field:
    """One field of a data set: an HDF5 dataset (array) or a file attribute.

    Parameters
    ----------
    name : str
        The HDF5 node or attribute name, and the :class:`MotionDataset` attribute.
    stored : {"dataset", "attribute"}
        An array (HDF5 dataset, first axis = sample) or a file attribute.
    doc : str
        What it holds (the docs' "type" column).
    required : bool
        Every file has it (else optional: None in memory, absent from the file).
    dtype : numpy dtype, optional
        The array's type in the file.
    shape : tuple of str or int
        The array's shape in the file, in symbols (see the module docstring); the
        per-sample shape is ``shape[1:]``.
    chunks : {"contiguous", "sample"}
        HDF5 storage: contiguous, or one chunk per sample (read one sample at a time).
    compression : str, optional
        HDF5 filter of the chunks (``"gzip"``: level = the writer's ``compression_level``).
    fillvalue : optional
        HDF5 fill value (what an unwritten sample reads as).
    checksum : bool
        Stored with HDF5's Fletcher-32 checksum (schema version 2 on) in chunks of whole
        samples (:data:`CHECKSUM_CHUNK_BYTES` at most, one sample at least), so a
        corrupted byte is refused when the array is read instead of read silently. An
        array with no elements (P = 0) stays contiguous. Gzip-compressed arrays
        (images) are checked by their codec.
    lazy : bool
        Read on demand (a :class:`~primspace.data.LazyImages` view): subset as a view,
        written first and merged chunk by chunk, dropped by ``without_images``.
    owner : str, optional
        For a names attribute: the array whose last axis it names. Names are checked
        after their array.
    matched : bool
        An attribute that a file merged by ``DatasetWriter.copy_from`` must share with
        the target: compared when its owner is required or none (first), or held by the
        target file and named there (then).
    with_owner_only : bool
        A names attribute written only into files that hold its owner (the attributes that
        files have always carried are written into every file, empty where the array is absent).
    writer_option : str, optional
        The :class:`~primspace.data.DatasetWriter` argument saying whether the file
        holds this optional array: ``block_dims`` of the array (``image_size``) or a
        bool (``with_labels``).
    block_dims : tuple of str
        The dimensions a block given to ``DatasetWriter.write`` must share with the file.
    summary_key : str, optional
        ``MotionDataset.summary`` key of the array's per-name ``[min, max]`` ranges.
    missing : str
        For a required array: why a file without it is refused.
    codec : {"strings", "number", "text", "version"}, optional
        How an attribute is written and read: an array of strings, one number, free
        text, the schema version.
    default : optional
        An attribute's value when a file lacks it (also the constructor default).
    coerce : callable, optional
        ``coerce(value, path) -> ndarray``: the constructor's conversion of an array
        (raises :class:`DataError`).
    normalize : callable, optional
        ``normalize(value, dataset) -> value``: the constructor's conversion of an
        attribute, given the data set's converted arrays (default names).
    validate : callable, optional
        ``validate(dataset)``: raise :class:`DataError` naming file, field and sample.
    check_stored : callable, optional
        ``check_stored(dtype) -> reason or None``: the dtype a file may store.
    """

    name: str
    stored: Literal["dataset", "attribute"]
    doc: str
    required: bool = False
    dtype: np.dtype | None = None
    shape: tuple[str | int, ...] = ()
    chunks: Literal["contiguous", "sample"] = "contiguous"
    compression: str | None = None
    fillvalue: Any = None
    checksum: bool = False
    lazy: bool = False
    owner: str | None = None
    matched: bool = False
    with_owner_only: bool = False
    writer_option: str | None = None
    block_dims: tuple[str, ...] = ()
    summary_key: str | None = None
    missing: str = ""
    codec: Literal["strings", "number", "text", "version"] | None = None
    default: Any = None
    coerce: Callable[[Any, Any], np.ndarray] | None = None
    normalize: Callable[[Any, Any], Any] | None = None
    validate: Callable[[Any], None] | None = None
    check_stored: Callable[[np.dtype], str | None] | None = None

    @property
    def is_array(self) -> bool:
        """An HDF5 dataset (else a file attribute)."""
        return self.stored == "dataset"

    @property
    def in_memory(self) -> bool:
        """A :class:`MotionDataset` attribute (the schema version is only in the file)."""
        return self.codec != "version"

    def file_shape(self, dims: Mapping[str, int]) -> tuple[int, ...]:
        """The array's shape for the dimensions ``dims`` (``{"N": 10, "T": 61, ...}``)."""
        return tuple(int(dims[d]) if isinstance(d, str) else d for d in self.shape)

    def create_options(self, dims: Mapping[str, int], compression_level: int) -> dict:
        """Keyword arguments of ``h5py.Group.create_dataset`` for this array."""
        shape = self.file_shape(dims)
        options: dict = {"shape": shape, "dtype": self.dtype}
        if self.fillvalue is not None:
            options["fillvalue"] = self.fillvalue
        if self.chunks == "sample":
            options["chunks"] = (1,) + shape[1:]
        if self.checksum and all(shape):
            row = int(np.prod(shape[1:])) * self.dtype.itemsize
            options["chunks"] = (max(1, min(shape[0], CHECKSUM_CHUNK_BYTES // row)),) + shape[1:]
            options["fletcher32"] = True
        if self.compression is not None:
            options["compression"] = self.compression
            options["compression_opts"] = compression_level
        return options

    def empty(self, dims: Mapping[str, int]) -> np.ndarray:
        """An uninitialised in-memory array of this field's type and shape."""
        return np.empty(self.file_shape(dims), dtype=self.dtype)


# ----------------------------------------------------------------------- table

#: Every field, in the order they are converted, checked, read and written: arrays
#: first (``motor`` then the optional ones), then the file attributes in file order.
FIELDS: tuple[Field, ...] = (
    Field(
        "motor",
        "dataset",
        "float32, joint values in physical units",
        required=True,
        checksum=True,
        dtype=np.dtype(np.float32),
        shape=("N", "T", "J"),
        block_dims=("T", "J"),
        summary_key="joint_ranges",
        missing="missing (every data set needs joint values)",
        coerce=coerce_motor,
        validate=validate_motor,
        check_stored=stored_floating,
    ),
    Field(
        "images",
        "dataset",
        "uint8, one gzip-compressed chunk per sample",
        dtype=np.dtype(np.uint8),
        shape=("N", "T", "H", "W", 3),
        chunks="sample",
        compression="gzip",
        lazy=True,
        writer_option="image_size",
        block_dims=("H", "W"),
        coerce=coerce_images,
        validate=validate_images,
        check_stored=stored_uint8,
    ),
    Field(
        "labels",
        "dataset",
        "int32, primitive index, -1 = unknown",
        checksum=True,
        dtype=np.dtype(np.int32),
        shape=("N",),
        fillvalue=-1,
        writer_option="with_labels",
        coerce=coerce_labels,
        validate=validate_labels,
    ),
    Field(
        "params",
        "dataset",
        "float32, generative factors (block x, y, size ...)",
        checksum=True,
        dtype=np.dtype(np.float32),
        shape=("N", "P"),
        writer_option="with_params",
        summary_key="param_ranges",
        coerce=coerce_params,
        validate=validate_params,
    ),
    Field(
        "lengths",
        "dataset",
        "int32, valid steps per sample (later steps are padding)",
        checksum=True,
        dtype=np.dtype(np.int32),
        shape=("N",),
        writer_option="with_steps",
        coerce=partial(coerce_steps, "lengths"),
        validate=validate_lengths,
    ),
    Field(
        "step_labels",
        "dataset",
        "int32, primitive index per step, -1 = padding",
        checksum=True,
        dtype=np.dtype(np.int32),
        shape=("N", "T"),
        fillvalue=-1,
        writer_option="with_steps",
        coerce=partial(coerce_steps, "step_labels"),
        validate=validate_step_labels,
    ),
    Field(
        "step_segments",
        "dataset",
        "int32, segment index per step (0, 1, ...), -1 = padding",
        checksum=True,
        dtype=np.dtype(np.int32),
        shape=("N", "T"),
        fillvalue=-1,
        writer_option="with_steps",
        coerce=partial(coerce_steps, "step_segments"),
        validate=validate_step_segments,
    ),
    Field(
        "source_ids",
        "dataset",
        "UTF-8 strings, where each sample was recorded (file, demo key, episode)",
        dtype=np.dtype(object, metadata={"vlen": str}),
        shape=("N",),
        writer_option="with_source_ids",
        coerce=coerce_source_ids,
        validate=validate_source_ids,
        check_stored=stored_strings,
    ),
    Field(
        "scene",
        "dataset",
        "float32, each sample's scene in a simulator that varies it (block colour, light ...)",
        checksum=True,
        dtype=np.dtype(np.float32),
        shape=("N", "S"),
        writer_option="with_scene",
        coerce=coerce_scene,
        validate=validate_scene,
        check_stored=stored_floating,
    ),
    Field("schema_version", "attribute", "layout version of the file", codec="version", default=None),
    Field(
        "joint_names",
        "attribute",
        "J joint names",
        owner="motor",
        matched=True,
        codec="strings",
        default=None,
        normalize=partial(default_names, prefix="j", array="motor", ndim=3),
        validate=validate_joint_names,
    ),
    Field(
        "label_names",
        "attribute",
        "a name per label value",
        owner="labels",
        matched=True,
        codec="strings",
        default=None,
        normalize=default_label_names,
    ),
    Field(
        "param_names",
        "attribute",
        "P names of the params",
        owner="params",
        matched=True,
        codec="strings",
        default=None,
        normalize=partial(default_names, prefix="p", array="params", ndim=2),
        validate=validate_param_names,
    ),
    Field(
        "scene_names",
        "attribute",
        "S names of the scene values",
        owner="scene",
        matched=True,
        with_owner_only=True,
        codec="strings",
        default=None,
        normalize=partial(default_names, prefix="s", array="scene", ndim=2),
        validate=validate_scene_names,
    ),
    Field(
        "dt",
        "attribute",
        "seconds between time steps",
        matched=True,
        codec="number",
        default=1.0,
        normalize=as_number,
        validate=validate_dt,
    ),
    Field(
        "source",
        "attribute",
        "free text: where the data came from",
        codec="text",
        default="",
        normalize=as_text,
    ),
)

#: The arrays (HDF5 datasets), in table order.
ARRAYS: tuple[Field, ...] = tuple(f for f in FIELDS if f.is_array)
#: The file attributes, in table order.
ATTRIBUTES: tuple[Field, ...] = tuple(f for f in FIELDS if not f.is_array)

_BY_NAME = {f.name: f for f in FIELDS}


def field(name: str) -> Field:
    """The field called ``name`` (KeyError for a name the schema does not have)."""
    return _BY_NAME[name]


def names_of(array: Field) -> Field | None:
    """The attribute naming the last axis of ``array`` (``joint_names`` for ``motor``)."""
    return next((f for f in ATTRIBUTES if f.owner == array.name), None)


def arrays_of(values) -> dict[str, Any]:
    """The data set's arrays among ``values``, by name, in table order (None where absent).

    ``values`` is a mapping (a generation shard's dict: other keys are dropped) or an
    object with the arrays as attributes (a :class:`MotionDataset`), e.g.
    ``writer.write(start, **arrays_of(shard))``.
    """
    if isinstance(values, Mapping):
        return {f.name: values.get(f.name) for f in ARRAYS}
    return {f.name: getattr(values, f.name, None) for f in ARRAYS}


def empty_arrays(dims: Mapping[str, int], names=None) -> dict[str, np.ndarray]:
    """Uninitialised arrays of the schema's types and shapes, to be filled in place.

    Parameters
    ----------
    dims : mapping
        The dimensions by symbol, e.g. ``{"N": 10, "T": 61, "J": 9, "P": 3}`` (add
        ``H`` and ``W`` for images).
    names : iterable of str, optional
        The arrays to make (default: ``motor`` and every optional array whose
        dimensions are all in ``dims``; the step fields have only N and T, so a caller
        without them names its arrays).
    """
    if names is None:
        names = [f.name for f in ARRAYS if all(d in dims for d in f.shape if isinstance(d, str))]
    return {name: field(name).empty(dims) for name in names}


def dims_of(arrays: Mapping[str, Any]) -> dict[str, int]:
    """The symbolic dimensions (N, T, J, ...) read off the shapes of the given arrays.

    ``arrays`` maps field names to arrays (or None, skipped); a dimension is taken from
    the first array that has it in the table's order.
    """
    dims: dict[str, int] = {}
    for f in ARRAYS:
        value = arrays.get(f.name)
        if value is None or len(value.shape) != len(f.shape):
            continue
        for symbol, size in zip(f.shape, value.shape):
            if isinstance(symbol, str):
                dims.setdefault(symbol, int(size))
    return dims


def markdown_table() -> str:
    """The arrays as the Markdown table of ``docs/data.md`` (node, type, shape, required)."""
    rows = ["| node | type | shape | required |", "|---|---|---|---|"]
    for f in ARRAYS:
        shape = "(" + ", ".join(str(d) for d in f.shape) + ("," if len(f.shape) == 1 else "") + ")"
        rows.append(f"| `{f.name}` | {f.doc} | {shape} | {'yes' if f.required else 'no'} |")
    return "\n".join(rows)
