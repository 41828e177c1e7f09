"""The motion data layer: data sets, their HDF5 file, resampling, scaling, importers.

Modules: :mod:`~primspace.data.schema` (the fields of a data set, once; each field's
conversion and checks in :mod:`~primspace.data.field_checks`),
:mod:`~primspace.data.dataset` (:class:`MotionDataset`, in memory),
:mod:`~primspace.data.reading` (its HDF5 file read), :mod:`~primspace.data.storage`
(written: :class:`DatasetWriter`),
:mod:`~primspace.data.checks` (the constructor's conversions and checks, without the class),
:mod:`~primspace.data.images` (:class:`LazyImages`), :mod:`~primspace.data.indices`
(sample indices), :mod:`~primspace.data.values` (number checks),
:mod:`~primspace.data.resample`, :mod:`~primspace.data.scaling`,
:mod:`~primspace.data.importers`.
"""

from primspace.data.dataset import DatasetWriter, LazyImages, MotionDataset
from primspace.data.importers import (
    import_csv_folder,
    import_lasa,
    import_lerobot,
    import_npy_folder,
    import_npz,
    import_robomimic,
)
from primspace.data.indices import check_indices, read_indices
from primspace.data.resample import resample
from primspace.data.scaling import JointScaler

__all__ = [
    "MotionDataset",
    "LazyImages",
    "DatasetWriter",
    "resample",
    "JointScaler",
    "import_npz",
    "import_npy_folder",
    "import_csv_folder",
    "import_lasa",
    "import_robomimic",
    "import_lerobot",
    "check_indices",
    "read_indices",
]
