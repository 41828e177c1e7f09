"""A Gaussian prior in code space per primitive, chosen by held-out likelihood, and its decoded moments (issue 39).

The paper observes that the codes of one primitive lie near a common affine subspace
(*Clustering*: "samples belonging to the same primitive lie near a low-dimensional
affine subspace"). :func:`choose_prior` turns a primitive's fitted codes into a
distribution. Three families are tried, each a Gaussian ``N(μ, C)`` over the codes:

* ``shrunk``: the full covariance shrunk towards a multiple of the identity,
  ``(1 - s) S + s (tr S / d) I`` (scikit-learn's ``ShrunkCovariance``);
* ``factor``: low rank plus diagonal, ``W Wᵀ + Ψ`` with ``r`` factors (``FactorAnalysis``);
* ``subspace``: the primitive's affine subspace (the rank that keeps a share ``v`` of the
  codes' variance) with an isotropic spread around it, the probabilistic PCA of Tipping and
  Bishop (``W Wᵀ + σ² I``, ``σ²`` the mean variance left out): the paper's subspace as a density.

The family and its setting are chosen once for all primitives, by the mean log-likelihood
of held-out fitted codes (K-fold within each primitive, :data:`PRIOR_GRID`); the table of
scores is kept, so the note can say which the data chose and why.

:class:`DecodedGaussian` holds what the decoder makes of draws from a prior: the mean
``μ_d`` and the deviations ``A`` (``N`` draws x (``T·J`` + ``q``): decoded motion and code
side by side) of ``N`` decoded draws, ``Σ = AᵀA``. Conditioning on observed entries ``o``
with noise ``r`` per entry is the ensemble Kalman update (the same as ProMP conditioning,
with the decoded ensemble's moments in place of ProMP's basis functions),
``μ + Σ_{·o} (Σ_oo + r I)⁻¹ (x_o - μ_o)``, and the evidence of the observed entries is
``log N(x_o; μ_o, Σ_oo + r I)``. Both are computed per observation mask for a batch of
motions at once, in the smaller of the observed space and the ensemble's space.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from primspace.errors import UserError

__all__ = [
    "PRIOR_GRID",
    "GaussianCode",
    "choose_prior",
    "fit_gaussian",
    "DecodedGaussian",
    "ConditionedGaussian",
    "SequentialGaussian",
]

#: The prior families and settings :func:`choose_prior` tries (name, setting).
PRIOR_GRID = (
    ("shrunk", 0.01),
    ("shrunk", 0.03),
    ("shrunk", 0.1),
    ("shrunk", 0.3),
    ("shrunk", 1.0),
    ("factor", 2),
    ("factor", 4),
    ("factor", 8),
    ("factor", 16),
    ("subspace", 0.99),
    ("subspace", 0.999),
)
#: Folds of the held-out likelihood within each primitive (fewer when a primitive has fewer codes).
PRIOR_FOLDS = 5


@dataclass
class GaussianCode:
    """A Gaussian over codes: its mean (d,), covariance (d, d), and the family that made it."""

    mean: np.ndarray
    cov: np.ndarray
    family: tuple

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws (n, d)."""
        values, vectors = np.linalg.eigh(self.cov)
        root = vectors * np.sqrt(np.clip(values, 0.0, None))
        return self.mean + rng.standard_normal((int(n), len(self.mean))) @ root.T

    def log_likelihood(self, codes: np.ndarray) -> np.ndarray:
        """(m,) log density of ``codes`` (m, d)."""
        chol = np.linalg.cholesky(self.cov)
        dev = np.linalg.solve(chol, (np.asarray(codes) - self.mean).T)
        logdet = 2.0 * np.log(np.diag(chol)).sum()
        return -0.5 * ((dev**2).sum(axis=0) + logdet + len(self.mean) * math.log(2 * math.pi))


def _floor(cov: np.ndarray, scale: float) -> np.ndarray:
    """``cov`` with a tiny ridge, so that it is positive definite whatever the codes."""
    return cov + (1e-6 * scale + 1e-12) * np.eye(len(cov))


def fit_gaussian(codes: np.ndarray, family: tuple, pooled_var: float | None = None) -> GaussianCode:
    """The Gaussian of ``family`` (a :data:`PRIOR_GRID` entry) fitted to ``codes`` (m, d).

    A primitive of one code has the isotropic covariance ``pooled_var · I`` (the mean
    per-dimension variance within the other primitives), or a tiny one without it."""
    codes = np.asarray(codes, dtype=np.float64)
    m, d = codes.shape
    mean = codes.mean(axis=0)
    centred = codes - mean
    scale = float((centred**2).sum() / max(m - 1, 1) / d) if m > 1 else float(pooled_var or 0.0)
    if m < 2:
        return GaussianCode(mean, _floor(np.eye(d) * scale, scale or 1.0), family)
    name, setting = family
    sample_cov = centred.T @ centred / (m - 1)
    if name == "shrunk":
        s = float(setting)
        cov = (1.0 - s) * sample_cov + s * (np.trace(sample_cov) / d) * np.eye(d)
    elif name == "factor":
        from sklearn.decomposition import FactorAnalysis

        rank = max(1, min(int(setting), m - 1, d))
        cov = FactorAnalysis(n_components=rank, random_state=0).fit(codes).get_covariance()
    elif name == "subspace":
        _, s, vt = np.linalg.svd(centred, full_matrices=False)
        var = s**2 / (m - 1)
        total = var.sum()
        rank = 0 if total <= 0 else int(np.searchsorted(np.cumsum(var) / total, float(setting) - 1e-12) + 1)
        rank = min(rank, max(min(m - 1, d) - 1, 0))
        rest = (total - var[:rank].sum()) / max(d - rank, 1)
        noise = max(rest, 1e-6 * total / d)
        cov = (vt[:rank].T * (var[:rank] - noise).clip(0.0)) @ vt[:rank] + noise * np.eye(d)
    else:
        raise UserError(f"unknown prior family {name!r}: choose one of shrunk, factor, subspace")
    return GaussianCode(mean, _floor(cov, scale or 1.0), family)


def _pooled_variance(groups: list[np.ndarray]) -> float:
    """The mean per-dimension variance of the codes within their primitives (those of two codes or more)."""
    parts = [(g - g.mean(axis=0)) for g in groups if len(g) > 1]
    if not parts:
        return 1.0
    dev = np.concatenate(parts)
    return float((dev**2).sum() / max(len(dev) - len(parts), 1) / dev.shape[1])


def choose_prior(groups: list[np.ndarray], grid=PRIOR_GRID, folds: int = PRIOR_FOLDS, seed: int = 0) -> dict:
    """The family of ``grid`` whose held-out log-likelihood of the codes is best.

    ``groups``: the fitted codes of each primitive (m_k, d). Each primitive of at least 3
    codes is split into ``min(folds, m_k)`` folds; a family's score is the mean held-out
    log-likelihood per code over all primitives. Returns ``{"family": (name, setting),
    "scores": {"name setting": score}}`` (the only family when no primitive has 3 codes)."""
    rng = np.random.default_rng([int(seed), 39, 1])
    pooled = _pooled_variance(groups)
    splits = []
    for codes in groups:
        if len(codes) >= 3:
            k = min(int(folds), len(codes))
            splits.append((codes, np.array_split(rng.permutation(len(codes)), k)))
    scores: dict = {}
    if not splits:
        return {"family": tuple(grid[0]), "scores": scores}
    for family in grid:
        total, count = 0.0, 0
        for codes, parts in splits:
            for held in parts:
                train = np.delete(codes, held, axis=0)
                total += float(fit_gaussian(train, tuple(family), pooled).log_likelihood(codes[held]).sum())
                count += len(held)
        scores[f"{family[0]} {family[1]:g}"] = total / count
    best = max(scores, key=scores.get)
    return {"family": next(tuple(f) for f in grid if f"{f[0]} {f[1]:g}" == best), "scores": scores}


class DecodedGaussian:
    """The moments of ``N`` draws decoded: ``members`` (N, D), each a decoded motion
    flattened (``T·J``) followed by its code (``q``) (module docstring)."""

    def __init__(self, members: np.ndarray, n_motion: int):
        members = np.asarray(members, dtype=np.float64)
        if members.ndim != 2 or len(members) < 2:
            raise UserError(f"a decoded ensemble needs at least 2 members, got shape {members.shape}")
        self.n_motion = int(n_motion)
        self.mean = members.mean(axis=0)
        self.deviations = (members - self.mean) / math.sqrt(len(members) - 1)  # Σ = AᵀA

    def conditioned(self, mask: np.ndarray, r: float) -> "ConditionedGaussian":
        """The conditioning on the motion's entries where ``mask`` (T·J,) is set, noise ``r`` per entry."""
        return ConditionedGaussian(self, np.asarray(mask, dtype=bool), float(r))


class ConditionedGaussian:
    """:meth:`DecodedGaussian.conditioned`: one mask and noise, any number of motions."""

    def __init__(self, prior: DecodedGaussian, mask: np.ndarray, r: float):
        if not r > 0:
            raise UserError(f"the observation noise must be > 0, got {r}")
        self.prior, self.r = prior, r
        self.index = np.flatnonzero(mask)
        a = prior.deviations
        ao = a[:, self.index]  # (N, o)
        n, o = ao.shape
        self.small_obs = o <= n
        if self.small_obs:  # S = A_oᵀA_o + rI, (o, o)
            s = ao.T @ ao + r * np.eye(o)
            self.chol = np.linalg.cholesky(s)
            self.logdet = 2.0 * np.log(np.diag(self.chol)).sum()
        else:  # M = A_oA_oᵀ + rI, (N, N): S⁻¹ = (I - A_oᵀ M⁻¹ A_o) / r, log|S| = (o - N) log r + log|M|
            m = ao @ ao.T + r * np.eye(n)
            self.chol = np.linalg.cholesky(m)
            self.logdet = (o - n) * math.log(r) + 2.0 * np.log(np.diag(self.chol)).sum()
        self.ao = ao

    def _solve(self, mat: np.ndarray) -> np.ndarray:
        from scipy.linalg import cho_solve

        return cho_solve((self.chol, True), mat)

    def _weighted(self, residual: np.ndarray) -> np.ndarray:
        """(n, N): ``A_o S⁻¹ (x_o - μ_o)`` per motion, the ensemble's coefficients of the update."""
        if self.small_obs:
            return (self.ao @ self._solve(residual.T)).T
        return self._solve(self.ao @ residual.T).T  # push-through: A_o S⁻¹ = M⁻¹ A_o

    def update(self, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, D) conditioned means and (n,) log evidences of ``observed`` (n, o): the motions' values
        at the mask's entries."""
        residual = np.asarray(observed, dtype=np.float64) - self.prior.mean[self.index]
        coeff = self._weighted(residual)
        means = self.prior.mean + coeff @ self.prior.deviations
        if self.small_obs:
            quad = (residual * self._solve(residual.T).T).sum(axis=1)
        else:
            quad = ((residual**2).sum(axis=1) - (residual * (coeff @ self.ao)).sum(axis=1)) / self.r
        evidence = -0.5 * (quad + self.logdet + len(self.index) * math.log(2 * math.pi))
        return means, evidence


class SequentialGaussian:
    """:class:`DecodedGaussian` conditioned one step at a time (online): the covariance, shared
    by motions observed on the same entries, and a mean and log evidence per motion.

    After the entries of steps ``1..t`` have been observed, :attr:`means` and :attr:`evidence`
    equal :meth:`ConditionedGaussian.update` on those entries (the Kalman filter's sequential
    form of the same Gaussian conditioning; tested). A step costs ``D² J`` for the covariance
    and ``D J`` per motion."""

    def __init__(self, prior: DecodedGaussian, n: int, r: float):
        if not r > 0:
            raise UserError(f"the observation noise must be > 0, got {r}")
        a = prior.deviations
        self.cov = a.T @ a
        self.means = np.tile(prior.mean, (int(n), 1))
        self.evidence = np.zeros(int(n))
        self.r = float(r)

    def observe(self, index: np.ndarray, values: np.ndarray) -> None:
        """Condition on the entries ``index`` (k,) of every motion, their ``values`` (n, k)."""
        index = np.asarray(index)
        s = self.cov[np.ix_(index, index)] + self.r * np.eye(len(index))
        chol = np.linalg.cholesky(s)
        residual = np.asarray(values, dtype=np.float64) - self.means[:, index]
        white = np.linalg.solve(chol, residual.T)  # L⁻¹ (x - μ), (k, n)
        logdet = 2.0 * np.log(np.diag(chol)).sum()
        self.evidence += -0.5 * ((white**2).sum(axis=0) + logdet + len(index) * math.log(2 * math.pi))
        gain_t = np.linalg.solve(chol.T, np.linalg.solve(chol, self.cov[index]))  # S⁻¹ Σ_o·, (k, D)
        self.means += residual @ gain_t
        self.cov -= self.cov[:, index] @ gain_t
