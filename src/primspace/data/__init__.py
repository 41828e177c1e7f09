"""The motion data layer: data sets, their HDF5 file, resampling, scaling, importers."""

from primspace.data.dataset import DatasetWriter, LazyImages, MotionDataset
from primspace.data.importers import import_csv_folder, import_lasa, import_npz
from primspace.data.resample import resample
from primspace.data.scaling import JointScaler

__all__ = [
    "MotionDataset",
    "LazyImages",
    "DatasetWriter",
    "resample",
    "JointScaler",
    "import_npz",
    "import_csv_folder",
    "import_lasa",
]
