"""`JointScaler`: each joint scaled to [-1, 1] over the training data.

The paper (Motion Capture Data; Artificial Data) normalises every joint angle over all
sequences to [-1, 1] "to make contribution of each joint equally important". The
scaler is fitted on the training data, saved with the model, and inverts exactly, so
generated motions come back in physical units.
"""

from __future__ import annotations

import numpy as np

from primspace.utils.errors import DataError, UserError

__all__ = ["JointScaler"]


class JointScaler:
    """Per-joint affine map of ``[min_j, max_j]`` onto ``[-1, 1]``.

    ``y = (x - center) / half_range`` with ``center = (max + min) / 2`` and
    ``half_range = (max - min) / 2``. A joint that never moves (``max == min``) gets
    ``half_range = 1``: it maps to 0 and back without dividing by zero.

    The last axis of the input is the joint axis; all other axes are pooled, so
    ``(n, T, J)`` sequences and ``(m, J)`` frames both work.

    Attributes
    ----------
    data_min_, data_max_ : ndarray of shape (J,)
        Per-joint extremes seen in ``fit``.
    center_, half_range_ : ndarray of shape (J,)
        The affine map's parameters (float64).
    """

    def __init__(self) -> None:
        self.data_min_: np.ndarray | None = None
        self.data_max_: np.ndarray | None = None

    # ------------------------------------------------------------------ parameters
    @property
    def n_joints(self) -> int:
        self._check_fitted()
        return self.data_min_.shape[0]

    @property
    def center_(self) -> np.ndarray:
        self._check_fitted()
        return (self.data_max_ + self.data_min_) / 2.0

    @property
    def half_range_(self) -> np.ndarray:
        self._check_fitted()
        half = (self.data_max_ - self.data_min_) / 2.0
        return np.where(half > 0, half, 1.0)

    def _check_fitted(self) -> None:
        if self.data_min_ is None:
            raise UserError("JointScaler is not fitted; call fit first")

    # ------------------------------------------------------------------- transform
    def fit(self, x) -> JointScaler:
        """Record each joint's minimum and maximum over all samples and steps."""
        x = _as_joints(x)
        flat = x.reshape(-1, x.shape[-1])
        if flat.shape[0] == 0:
            raise DataError("cannot fit a scaler on no data", field="motor")
        if not np.isfinite(flat).all():
            raise DataError("contains NaN or inf", field="motor")
        # float64 whatever the input, so a scaler restored from to_dict() is the same map
        self.data_min_ = flat.min(axis=0).astype(np.float64)
        self.data_max_ = flat.max(axis=0).astype(np.float64)
        return self

    def transform(self, x) -> np.ndarray:
        """Scale physical joint values to [-1, 1] (values outside the fitted range go beyond)."""
        x = self._checked(x)
        return ((x - self.center_) / self.half_range_).astype(_out_dtype(x), copy=False)

    def fit_transform(self, x) -> np.ndarray:
        return self.fit(x).transform(x)

    def inverse_transform(self, y) -> np.ndarray:
        """Map scaled values back to physical units."""
        y = self._checked(y)
        return (y * self.half_range_ + self.center_).astype(_out_dtype(y), copy=False)

    def _checked(self, x) -> np.ndarray:
        self._check_fitted()
        x = _as_joints(x)
        if x.shape[-1] != self.n_joints:
            raise DataError(f"has {x.shape[-1]} joints, the scaler was fitted on {self.n_joints}", field="motor")
        return x

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict:
        """A JSON-serialisable description; :meth:`from_dict` restores it exactly."""
        self._check_fitted()
        return {"data_min": self.data_min_.tolist(), "data_max": self.data_max_.tolist()}

    @classmethod
    def from_dict(cls, state: dict) -> JointScaler:
        try:
            lo = np.asarray(state["data_min"], dtype=np.float64)
            hi = np.asarray(state["data_max"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"not a JointScaler state ({exc})") from None
        if lo.shape != hi.shape or lo.ndim != 1 or np.any(hi < lo):
            raise UserError("not a JointScaler state (min/max disagree)")
        scaler = cls()
        scaler.data_min_, scaler.data_max_ = lo, hi
        return scaler

    def __repr__(self) -> str:
        return f"JointScaler(n_joints={self.n_joints})" if self.data_min_ is not None else "JointScaler()"


def _as_joints(x) -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype.kind not in "fiu":
        raise DataError(f"must be numbers, got {arr.dtype}", field="motor")
    if arr.ndim < 1:
        raise DataError("needs a joint axis", field="motor")
    return arr.astype(np.float64, copy=False) if arr.dtype.kind != "f" else arr


def _out_dtype(x: np.ndarray):
    return x.dtype if x.dtype.kind == "f" else np.float64
