"""Linear probe: how much of the generative factors a linear map reads from the codes.

The paper shows the structure of its latent space as a picture (Fig. latent_encoding:
"First two principal components of the learned latent vectors for samples belonging to one
specific primitive"), of which it writes: "By examining resulting latent vectors
corresponding to samples from one primitive, we can see that random linear projection
initialization method yields more "structured" result". A linear probe turns that picture
into a number: the
cross-validated R² of a ridge regression from the codes to the factors that generated each
motion (for the simulator's data: ``params`` = block x, y and size).

Choices, and why:

* **Within each primitive.** The paper's figure shows one primitive's codes, and each
  primitive maps the block to its motion differently, so one linear map across
  primitives would measure the primitives' layout as much as the encoding of the block.
  The probe is fitted per group (``groups`` = the primitive labels) and the headline R²
  is the sample-weighted mean over groups.
* **Out-of-fold.** R² is computed from predictions on held-out samples (``n_splits``-fold
  cross-validation, shuffled, seeded): a probe on q-dimensional codes with few samples
  would otherwise fit noise. Codes are standardised and the ridge strength chosen inside
  each training fold only (leave-one-out over ``alphas``), so nothing of the held-out fold
  leaks into the fit.
* A factor constant within a group (e.g. one block size) has no R²: None.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from primspace.utils.errors import UserError

__all__ = ["ALPHAS", "ProbeResult", "linear_probe"]

#: Ridge strengths tried (on standardised codes), chosen per training fold.
ALPHAS = tuple(np.logspace(-3, 3, 13))

# fewer samples than this in a group: the group is left out (no held-out fold to speak of)
_MIN_GROUP = 4


@dataclass
class ProbeResult:
    """Cross-validated R² of the linear probe.

    Attributes
    ----------
    factor_names : list of str
    r2 : dict
        Factor -> R², the sample-weighted mean over groups (None: constant in every group).
    mean_r2 : float or None
        Mean of ``r2`` over the factors that have one.
    per_group : dict
        Group label (str) -> factor -> R² (None: constant in that group).
    n_samples : int
        Samples in the groups that were probed.
    skipped_groups : list of str
        Groups with fewer than 4 samples, left out.
    """

    factor_names: list[str]
    r2: dict[str, float | None]
    mean_r2: float | None
    per_group: dict[str, dict[str, float | None]]
    n_samples: int
    skipped_groups: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "factor_names": list(self.factor_names),
            "r2": dict(self.r2),
            "mean_r2": self.mean_r2,
            "per_group": {g: dict(v) for g, v in self.per_group.items()},
            "n_samples": self.n_samples,
            "skipped_groups": list(self.skipped_groups),
        }


def linear_probe(
    codes,
    factors,
    groups=None,
    *,
    factor_names: Sequence[str] | None = None,
    n_splits: int = 5,
    alphas: Sequence[float] = ALPHAS,
    random_state: int = 0,
) -> ProbeResult:
    """Out-of-fold R² of ridge regressions from ``codes`` to each factor, per group.

    Parameters
    ----------
    codes : array-like (n, q)
    factors : array-like (n, f)
        The generative factors (e.g. a data set's ``params``).
    groups : array-like (n,), optional
        One probe per group (e.g. the primitive labels); default one group.
    factor_names : list of str, optional
    n_splits : int
        Folds (fewer in a group with fewer samples).
    alphas : sequence of float
        Ridge strengths, chosen inside each training fold.
    random_state : int
        Seed of the fold assignment.

    Returns
    -------
    ProbeResult
    """
    Z, F, g, names = _checked(codes, factors, groups, factor_names)
    per_group, weights, skipped = {}, {}, []
    for label in np.unique(g):
        rows = np.flatnonzero(g == label)
        if len(rows) < _MIN_GROUP:
            skipped.append(str(label))
            continue
        per_group[str(label)] = _probe_group(Z[rows], F[rows], names, n_splits, alphas, random_state)
        weights[str(label)] = len(rows)
    r2 = {}
    for name in names:
        vals = [(per_group[k][name], w) for k, w in weights.items() if per_group[k][name] is not None]
        r2[name] = float(sum(v * w for v, w in vals) / sum(w for _, w in vals)) if vals else None
    have = [v for v in r2.values() if v is not None]
    return ProbeResult(
        factor_names=names,
        r2=r2,
        mean_r2=float(np.mean(have)) if have else None,
        per_group=per_group,
        n_samples=int(sum(weights.values())),
        skipped_groups=skipped,
    )


def _checked(codes, factors, groups, factor_names):
    Z = np.asarray(codes, dtype=np.float64)
    F = np.asarray(factors, dtype=np.float64)
    if F.ndim == 1:
        F = F[:, None]
    if Z.ndim != 2 or F.ndim != 2:
        raise UserError(f"linear probe: codes must be (n, q) and factors (n, f), got {Z.shape} and {F.shape}")
    if len(Z) != len(F):
        raise UserError(f"linear probe: {len(Z)} codes but {len(F)} rows of factors")
    for what, arr in (("codes", Z), ("factors", F)):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        if bad.size:
            raise UserError(f"linear probe: {what} of sample {bad[0]} are not finite")
    g = np.zeros(len(Z), dtype=np.int64) if groups is None else np.asarray(groups)
    if g.shape != (len(Z),):
        raise UserError(f"linear probe: groups must have one entry per code ({len(Z)}), got shape {g.shape}")
    names = list(factor_names) if factor_names is not None else [f"factor_{j}" for j in range(F.shape[1])]
    if len(names) != F.shape[1]:
        raise UserError(f"linear probe: {len(names)} factor names for {F.shape[1]} factors")
    return Z, F, g, names


def _probe_group(Z, F, names, n_splits, alphas, random_state) -> dict[str, float | None]:
    """Out-of-fold predictions of every factor in one group, and their R²."""
    from sklearn.linear_model import RidgeCV
    from sklearn.model_selection import KFold, cross_val_predict
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    folds = KFold(n_splits=min(n_splits, len(Z)), shuffle=True, random_state=random_state)
    out = {}
    for j, name in enumerate(names):
        y = F[:, j]
        total = float(np.sum((y - y.mean()) ** 2))
        if total <= 1e-12 * max(1.0, float(np.sum(y**2))):
            out[name] = None
            continue
        model = make_pipeline(StandardScaler(), RidgeCV(alphas=np.asarray(alphas, dtype=float)))
        pred = cross_val_predict(model, Z, y, cv=folds)
        out[name] = float(1.0 - np.sum((y - pred) ** 2) / total)
    return out
