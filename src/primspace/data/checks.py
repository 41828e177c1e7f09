"""The constructor's conversions and checks of a data set's fields, on any object holding them.

:class:`~primspace.data.MotionDataset` converts and checks its fields with
:func:`convert_fields` and :func:`validate_fields`; :class:`~primspace.data.DatasetWriter`
(:mod:`~primspace.data.storage`, below the class) checks a block of samples, and a file it
merges, the same way with :func:`checked_fields`, which needs no class. What is converted
and checked, and in which order, is the schema table's (:data:`~primspace.data.schema.FIELDS`).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import SimpleNamespace

from primspace.data.schema import ARRAYS, ATTRIBUTES, names_of

__all__ = ["MEMBERS", "convert_fields", "validate_fields", "checked_fields"]

#: The attributes a data set holds in memory (the schema version is only in the file).
MEMBERS = tuple(f for f in ATTRIBUTES if f.in_memory)


def convert_fields(ds) -> None:
    """Convert ``ds``'s arrays (``motor`` first), then default its names from them, in place.

    Raises
    ------
    DataError
        Naming the file (``ds.path``), the field and the sample.
    """
    for array in ARRAYS:  # motor first: its errors come before the optional fields'
        value = getattr(ds, array.name)
        if value is not None or array.required:
            setattr(ds, array.name, array.coerce(value, ds.path))
    for attr in MEMBERS:  # names default from the converted arrays
        setattr(ds, attr.name, attr.normalize(getattr(ds, attr.name), ds))


def validate_fields(ds) -> None:
    """Check every field of ``ds``; raise :class:`~primspace.utils.errors.DataError` naming file,
    field and sample.

    Each array is checked (``motor`` first), then the attribute naming its last axis, then
    the attributes of no array (``dt``), in the schema table's order.
    """
    for array in ARRAYS:
        if getattr(ds, array.name) is None:
            continue
        array.validate(ds)
        names = names_of(array)
        if names is not None and names.validate is not None:
            names.validate(ds)
    for attr in MEMBERS:
        if attr.owner is None and attr.validate is not None:
            attr.validate(ds)


def checked_fields(values: Mapping, path=None) -> SimpleNamespace:
    """The data set fields ``values`` (by name; an absent one takes the constructor's
    default) converted and checked as the :class:`~primspace.data.MotionDataset` constructor
    does: an object holding them as attributes, and ``path``.

    Raises
    ------
    DataError
        As the constructor does.
    """
    ds = SimpleNamespace(**{f.name: values.get(f.name, f.default) for f in ARRAYS + MEMBERS}, path=path)
    convert_fields(ds)
    validate_fields(ds)
    return ds
