"""TEMPORARY: read_indices until primspace.data.indices lands."""
from __future__ import annotations
import os
from pathlib import Path
import numpy as np
from primspace.data import MotionDataset
from primspace.errors import DataError


def read_indices(path: str | os.PathLike, dataset: MotionDataset | None = None) -> np.ndarray:
    """Sample indices from a ``.npy`` file or a text file (integers separated by
    whitespace or commas; ``#`` starts a comment); with ``dataset``, each must be one of
    its samples (the error names the index file and the data file)."""
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", path=path, field="indices")
    try:
        if path.suffix.lower() == ".npy":
            arr = np.load(path, allow_pickle=False)
        else:
            text = path.read_text(encoding="utf-8")
            tokens = [t for line in text.splitlines() for t in line.split("#", 1)[0].replace(",", " ").split()]
            arr = np.array([int(t) for t in tokens], dtype=np.int64)
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read sample indices ({str(exc).splitlines()[0]})", path=path, field="indices") from None
    arr = np.asarray(arr)
    if arr.ndim != 1 or arr.size == 0 or arr.dtype.kind not in "iu":
        raise DataError("must be a non-empty list of integers", path=path, field="indices")
    if len(np.unique(arr)) != arr.size:
        raise DataError("lists a sample more than once", path=path, field="indices")
    if dataset is not None:
        bad = arr[(arr < 0) | (arr >= len(dataset))]
        if bad.size:
            where = f" of {dataset.path}" if dataset.path is not None else ""
            raise DataError(f"sample {int(bad[0])} is out of range for the {len(dataset)} samples{where}",
                            path=path, field="indices")
    return arr.astype(np.int64)
