"""Calibrated projection: a linear map from a run's initial codes to its fitted codes.

The paper starts every code, a new sample's included, at its random projection ``P m``.
Its reason, in *Initialization of Latent Vectors* (derivation in Appendix A), is what ``P``
keeps of the trajectory space. Subspaces stay subspaces: "Moreover, under the assumption
of motion primitives being close to linear subspaces in trajectory space, the projected
primitives are also close to linear subspaces in latent space if latent dimension
suffice." Inner products survive in expectation (its equations: ``E_P[Pa·Pb] = a·b``,
variance at most ``(3‖a‖²‖b‖² − (a·b)²)/q``), so similar motions start at similar codes.

That the codes then stay near ``P m`` is not that reason but the paper's reading of its own
inference result, in *Intra-primitive generalisation*: "On the other hand, initialization
with random linear projection yields good results already without any training, which
means the initial distribution of projected points did not change much during the first
part of the training." This module tests that reading. The fitted codes do move
(``‖Z − P m‖_F / ‖P m‖_F`` 5-7 % on the paper preset, 11-53 % on the smaller demo, LASA
and wrist-sensor data: CHANGELOG.md, 0.5.0, *Beyond the paper: the calibrated start*); where
they move most, and not linearly in ``P m`` (the wrist-sensor recordings, 46-53 %), the raw
projection ends above zero init. (A LASA run with projection ending above zero did not
reproduce: docs/model.md, *When the raw projection loses*.)

:class:`CodeCalibration` learns the correction from the training part itself. After ``fit``
the run has, for each training sample, its initial code ``x_i = P m_i`` (the initialiser's
output) and its fitted code ``y_i``. A ridge regression with intercept

    y ≈ B x + c,    (B, c) = argmin Σ_i ‖y_i − B x_i − c‖² + α ‖B − I‖²_F

is solved in closed form, ``α`` chosen by efficient leave-one-out cross-validation on the
training codes (:class:`sklearn.linear_model.RidgeCV`; one α for all q outputs, tried
relative to the mean eigenvalue of the centred ``XᵀX`` so the grid does not depend on the
codes' scale). The penalty pulls ``B`` towards the identity (``prior="identity"``, the
default: ``‖B − I‖²_F``, i.e. a ridge of ``y − x`` on ``x``), the paper's own reading
that codes stay where ``P m`` put them; a strong penalty leaves ``P m`` shifted by the
mean movement. Pulled towards zero instead (``prior="zero"``, the textbook ridge) the map
predicted held-out fitted codes worse than ``P m`` itself where the training part is
small (measured over 31 fits of the demo, LASA, wrist-sensor and paper presets: held-out
R² minus that of ``P m`` −0.25 to +0.01, mean −0.07; towards the identity −0.02 to
+0.01, mean −0.002).

A new sample then starts inference at ``B P m + c`` ("calibrated"): the same ``P`` and the
same frozen θ, a start moved to where fitted codes of similar ``P m`` ended. This goes
beyond the paper (its new samples start at ``P m``).

With a sequence of codes (``window``: codes ``(n, K·q)``) the windows are pooled, one map
for every window, as the projection itself is one ``P`` for every window.

Diagnostics (all on the training part): the relative movement ``‖Y − X‖_F / ‖X‖_F`` of
the fitted codes from their initial values; the R² of ``X`` itself as a prediction of
``Y`` (the paper's reading: near 1 when codes did not move); and the held-out R² of
the map (out-of-fold predictions, folds by sample, α chosen inside each training fold).
"""

from __future__ import annotations

import numpy as np
import torch

from primspace.utils.errors import UserError

__all__ = ["CodeCalibration", "RELATIVE_ALPHAS"]

#: Ridge strengths tried, relative to the mean eigenvalue of the centred XᵀX.
RELATIVE_ALPHAS = tuple(float(a) for a in np.logspace(-6, 3, 19))


class CodeCalibration:
    """Ridge map (with intercept) from initial codes to fitted codes (scikit-learn style).

    Parameters
    ----------
    latent_dim : int
        q: the size of one code; inputs of width ``K·q`` are ``K`` pooled windows.
    alphas : sequence of float
        Ridge strengths relative to the mean eigenvalue of the centred ``XᵀX``.
    n_splits : int
        Folds for the held-out R² (folds by sample).
    random_state : int
        Seed of the fold assignment.
    prior : {"identity", "zero"}
        What the penalty pulls ``B`` towards.

    Attributes
    ----------
    coef_ : ndarray (q, q)
        ``B`` (output x input).
    intercept_ : ndarray (q,)
        ``c``.
    alpha_ : float
        The chosen strength (absolute).
    heldout_r2_ : float or None
        R² of out-of-fold predictions of the fitted codes (None below 3 samples).
    identity_r2_ : float
        R² of the initial codes themselves as the prediction.
    movement_ : float
        ``‖Y − X‖_F / ‖X‖_F``.
    n_samples_ : int

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> x = rng.normal(size=(50, 3)); y = 2 * x + 1
    >>> cal = CodeCalibration(latent_dim=3).fit(x, y)
    >>> np.allclose(cal.transform(x[:2]), y[:2], atol=1e-3)
    True
    """

    def __init__(
        self, latent_dim: int, alphas=RELATIVE_ALPHAS, n_splits: int = 5, random_state: int = 0, prior: str = "identity"
    ) -> None:
        self.latent_dim = latent_dim
        self.prior = prior
        self.alphas = alphas
        self.n_splits = n_splits
        self.random_state = random_state

    # ---------------------------------------------------------------------------- fit
    def fit(self, initial, fitted) -> CodeCalibration:
        """Fit ``B``, ``c`` and ``α`` on the training part's codes.

        Parameters
        ----------
        initial : array-like (n, K·q)
            The initialiser's codes of the training samples (``P m``).
        fitted : array-like (n, K·q)
            Their codes after training.
        """
        if self.prior not in ("identity", "zero"):
            raise UserError(f"calibration prior must be 'identity' or 'zero', got {self.prior!r}")
        x, y, groups = self._pairs(initial, fitted)
        q = int(self.latent_dim)
        self.n_samples_ = int(len(np.unique(groups)))
        self.movement_ = float(np.linalg.norm(y - x) / max(np.linalg.norm(x), 1e-300))
        total = float(np.sum((y - y.mean(axis=0)) ** 2))
        self.identity_r2_ = _r2(y, x, total)
        if len(x) < 2:
            self.coef_, self.intercept_, self.alpha_ = np.zeros((q, q)), y.mean(axis=0), float("inf")
            self.heldout_r2_ = None
            return self
        self.coef_, self.intercept_, self.alpha_ = self._ridge(x, y)
        self.heldout_r2_ = self._heldout_r2(x, y, groups, total) if self.n_samples_ >= 3 else None
        return self

    def transform(self, initial) -> np.ndarray:
        """Calibrated codes ``B x + c`` (float32), the same shape as ``initial``."""
        if not hasattr(self, "coef_"):
            raise UserError("CodeCalibration is not fitted; call fit first")
        x = np.asarray(initial, dtype=np.float64)
        q = int(self.latent_dim)
        if x.ndim != 2 or x.shape[1] % q:
            raise UserError(f"codes to calibrate must have shape (n, K*{q}), got {x.shape}")
        rows = x.reshape(-1, q)
        return (rows @ self.coef_.T + self.intercept_).reshape(x.shape).astype(np.float32)

    def diagnostics(self) -> dict:
        """The numbers a run reports: movement, R² of the raw start, held-out R² of the map, α, n."""
        return {
            "movement": self.movement_,
            "identity_r2": self.identity_r2_,
            "heldout_r2": self.heldout_r2_,
            "alpha": self.alpha_,
            "n_samples": self.n_samples_,
        }

    # ----------------------------------------------------------------------- helpers
    def _pairs(self, initial, fitted):
        """Rows (one per code, windows pooled) of both, and the sample each row came from."""
        q = int(self.latent_dim)
        x = np.asarray(initial, dtype=np.float64)
        y = np.asarray(fitted, dtype=np.float64)
        if x.shape != y.shape or x.ndim != 2 or x.shape[1] % q or not len(x):
            raise UserError(f"calibration: initial codes {x.shape} and fitted codes {y.shape} must both be (n, K*{q})")
        for what, arr in (("initial", x), ("fitted", y)):
            bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
            if bad.size:
                raise UserError(f"calibration: the {what} code of sample {bad[0]} is not finite")
        k = x.shape[1] // q
        return x.reshape(-1, q), y.reshape(-1, q), np.repeat(np.arange(len(x)), k)

    def _ridge(self, x, y):
        from sklearn.linear_model import RidgeCV

        xc = x - x.mean(axis=0)
        scale = max(float(np.sum(xc**2)) / x.shape[1], 1e-12)  # mean eigenvalue of the centred XᵀX
        shift = x if self.prior == "identity" else 0.0  # shrink B towards I (or towards 0)
        model = RidgeCV(alphas=scale * np.asarray(self.alphas, dtype=float), fit_intercept=True).fit(x, y - shift)
        coef = np.asarray(model.coef_, dtype=np.float64) + (np.eye(x.shape[1]) if self.prior == "identity" else 0.0)
        return coef, np.asarray(model.intercept_, dtype=np.float64), float(model.alpha_)

    def _heldout_r2(self, x, y, groups, total) -> float:
        n_groups = int(groups.max()) + 1
        folds = np.random.default_rng(self.random_state).permutation(n_groups) % min(self.n_splits, n_groups)
        fold_of_row = folds[groups]
        pred = np.empty_like(y)
        for f in np.unique(fold_of_row):
            held = fold_of_row == f
            coef, intercept, _ = self._ridge(x[~held], y[~held])
            pred[held] = x[held] @ coef.T + intercept
        return _r2(y, pred, total)

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        """The fitted map and its diagnostics (tensors and numbers: a checkpoint entry)."""
        return {
            "latent_dim": int(self.latent_dim),
            "prior": self.prior,
            "coef": torch.from_numpy(np.ascontiguousarray(self.coef_)),
            "intercept": torch.from_numpy(np.ascontiguousarray(self.intercept_)),
            **self.diagnostics(),
        }

    @classmethod
    def from_state_dict(cls, state: dict) -> CodeCalibration:
        try:
            cal = cls(int(state["latent_dim"]), prior=state.get("prior", "zero"))  # early 0.5 maps: towards zero
            cal.coef_ = np.asarray(state["coef"], dtype=np.float64)
            cal.intercept_ = np.asarray(state["intercept"], dtype=np.float64)
            cal.alpha_ = float(state["alpha"])
            cal.movement_ = float(state["movement"])
            cal.identity_r2_ = float(state["identity_r2"])
            cal.heldout_r2_ = None if state["heldout_r2"] is None else float(state["heldout_r2"])
            cal.n_samples_ = int(state["n_samples"])
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"not a CodeCalibration state ({exc})") from None
        q = cal.latent_dim
        if cal.coef_.shape != (q, q) or cal.intercept_.shape != (q,):
            raise UserError(
                f"not a CodeCalibration state (coef {cal.coef_.shape}, intercept {cal.intercept_.shape} for q = {q})"
            )
        return cal

    def same_map(self, other: CodeCalibration | None) -> bool:
        """Whether ``other`` is this very map (same prior, ``B``, ``c``)."""
        return (
            other is not None
            and other.prior == self.prior
            and np.array_equal(other.coef_, self.coef_)
            and np.array_equal(other.intercept_, self.intercept_)
        )

    def __repr__(self) -> str:
        fitted = "" if not hasattr(self, "coef_") else f", movement={self.movement_:.3g}, heldout_r2={self.heldout_r2_}"
        return f"CodeCalibration(latent_dim={self.latent_dim}{fitted})"


def _r2(y: np.ndarray, pred: np.ndarray, total: float) -> float:
    """1 − Σ‖y − ŷ‖² / Σ‖y − ȳ‖², pooled over the outputs."""
    return float(1.0 - np.sum((y - pred) ** 2) / max(total, 1e-300))
