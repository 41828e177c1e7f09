"""Points to cluster, from a MotionDataset file (raw trajectories) or a latents ``.npy``.

``FILE.h5``
    The paper's motion-capture experiment: every joint scaled to [-1, 1] over the data set
    (:class:`primspace.data.JointScaler`, "to make contribution of each joint equally
    important"), each demonstration flattened to one point of ``T * J`` values (time-major:
    ``m_1, ..., m_T``). True labels come from the file's ``labels`` (``-1`` = unknown: such
    samples are clustered but not scored).
``LATENTS.npy``
    An ``(N, q)`` array, one latent code per row, used as is; true labels from an optional
    ``(N,)`` integer ``.npy`` (``-1`` = unknown).

A run's codes (``primspace cluster RUN``) are read by the command line, which knows runs:
points numbered by the run's samples (``ClusterPoints.samples``), labelled from its data file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from primspace.utils.errors import DataError, UserError, first_line

__all__ = ["ClusterPoints", "load_points", "read_labels", "H5_SUFFIXES"]

H5_SUFFIXES = (".h5", ".hdf5")


@dataclass(frozen=True, eq=False)
class ClusterPoints:
    """Points as rows, with optional true labels.

    Attributes
    ----------
    X : ndarray of shape (N, D), float64
    labels : ndarray of shape (N,), int64, or None
        ``-1`` = unknown.
    label_names : list of str or None
    path : Path
    description : str
        How ``X`` was built, for reports.
    samples : ndarray of shape (N,), int64, or None
        The number of each point's sample: its index in the data file (a run's codes: the
        run's samples, :mod:`primspace.data.schema` *Sample numbers*); None: the row
        (a data file's trajectories, or codes that belong to no run).
    raw : ndarray of shape (N, T * J) or None
        For a run's codes whose data file is readable: the raw trajectories of the same
        samples (:func:`trajectory_matrix`), to compare the codes' clustering with.
    """

    X: np.ndarray
    labels: np.ndarray | None
    label_names: list[str] | None
    path: Path
    description: str
    samples: np.ndarray | None = None
    raw: np.ndarray | None = None


def trajectory_matrix(motor) -> np.ndarray:
    """Trajectories as points: each joint scaled to [-1, 1] over the data, each sample flattened.

    The paper's motion-capture experiment (and its latent initialisation) treats a motion
    ``m_{1:T}`` as one point of R^{T J}. Returns ``(N, T * J)`` float64.
    """
    from primspace.data import JointScaler

    motor = np.asarray(motor, dtype=np.float64)
    n, t, j = motor.shape
    return JointScaler().fit_transform(motor).reshape(n, t * j)


def load_points(path: str | os.PathLike, labels: str | os.PathLike | None = None) -> ClusterPoints:
    """Read points (and true labels) from a MotionDataset ``.h5`` or an ``(N, q)`` ``.npy``.

    Parameters
    ----------
    path : path-like
    labels : path-like, optional
        An ``(N,)`` integer ``.npy`` of true labels; overrides the data set's labels.

    Raises
    ------
    DataError
        Missing or unreadable file, wrong shape, non-numbers, NaN or inf (naming the file,
        the field and the first bad sample).
    UserError
        An input whose suffix is neither ``.h5``/``.hdf5`` nor ``.npy``.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in H5_SUFFIXES:
        from primspace.data import MotionDataset

        ds = MotionDataset.load(path).without_images()
        n, t, j = ds.motor.shape
        X = trajectory_matrix(ds.motor)
        true = None if ds.labels is None else ds.labels.astype(np.int64)
        names = list(ds.label_names) if true is not None else None
        description = f"motion data set {n} x {t} steps x {j} joints, joints scaled to [-1, 1], flattened to {t * j}"
    elif suffix == ".npy":
        X = _read_npy(path, "latents")
        if X.ndim != 2:
            raise DataError(
                f"must be a 2-D (N, q) array of points as rows, got shape {X.shape}", path=path, field="latents"
            )
        if X.dtype.kind not in "fiu" or X.dtype == bool:
            raise DataError(f"must hold numbers, got {X.dtype}", path=path, field="latents")
        X = X.astype(np.float64)
        bad = np.flatnonzero(~np.isfinite(X).all(axis=1)) if X.size else []
        if len(bad):
            raise DataError("contains NaN or inf", path=path, field="latents", index=int(bad[0]))
        true, names = None, None
        description = f"latents {X.shape[0]} x {X.shape[1]}"
    else:
        raise UserError(f"{path}: expected a MotionDataset .h5 or an (N, q) .npy of latents")
    if X.shape[0] == 0:
        raise DataError("holds no points", path=path)
    if labels is not None:
        true, names = read_labels(Path(labels), X.shape[0]), None
    return ClusterPoints(X=X, labels=true, label_names=names, path=path, description=description)


def _read_npy(path: Path, field: str) -> np.ndarray:
    if not path.is_file():
        raise DataError("no such file", path=path)
    try:
        loaded = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise DataError(f"not a readable .npy array ({first_line(exc)})", path=path, field=field) from None
    if not isinstance(loaded, np.ndarray):  # an .npz archive loads as a mapping of arrays
        loaded.close()
        raise DataError("is an .npz archive; give one array as an .npy file", path=path, field=field)
    return loaded


def read_labels(path: Path, n: int) -> np.ndarray:
    """An ``(n,)`` integer ``.npy`` of true labels (``-1`` = unknown); one :class:`DataError` naming what is wrong."""
    lab = _read_npy(path, "labels")
    if lab.shape != (n,):
        raise DataError(f"must have shape ({n},) to match the points, got {lab.shape}", path=path, field="labels")
    if lab.dtype.kind not in "iu":
        raise DataError(f"must be integers (-1 = unknown), got {lab.dtype}", path=path, field="labels")
    bad = np.flatnonzero(lab < -1)
    if bad.size:
        raise DataError(f"label {int(lab[bad[0]])} is below -1", path=path, field="labels", index=int(bad[0]))
    return lab.astype(np.int64)
