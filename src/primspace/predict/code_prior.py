"""A Gaussian prior in code space per primitive, chosen by held-out likelihood, and its decoded moments.

The paper: "Specific motions within each primitive are determined by location of the
object in space. Hence, each primitive is a low-dimensional manifold in trajectory space",
and for the codes, "we assume that data points **z**_i belong to the union of K
low-dimensional subspaces with errors" (*Clustering*), affine ones in its affine subspace
clustering. :func:`choose_prior` turns a primitive's fitted codes into a distribution. Three families are tried, each a Gaussian ``N(μ, C)`` over the codes:

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
motions at once, in the smaller of the observed space and the ensemble's space. The same
holds for the fitted demonstrations paired with their codes (their moments: the data's own
Gaussian), and for a blend of the two (:meth:`DecodedGaussian.blend`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from primspace.utils.errors import UserError

__all__ = [
    "PRIOR_GRID",
    "GaussianCode",
    "choose_prior",
    "fit_gaussian",
    "DecodedGaussian",
    "ConditionedGaussian",
    "SequentialGaussian",
    "StepGains",
    "condition_primitives",
    "CV_FOLDS",
    "fold_split",
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
#: Folds of the K-fold prediction of the fitted demonstrations that chooses the predictors' settings
#: (the prior's noise, blend and temperature; the Gaussian peers' settings).
CV_FOLDS = 5


def fold_split(groups, n: int, seed, folds: int = CV_FOLDS) -> np.ndarray:
    """The fold (0 to ``folds - 1``) of each of ``n`` fitted demonstrations, -1 for those in no group:
    each group's indices (``groups``: a list of index arrays, e.g. a primitive's demonstrations) in the
    order of a permutation by ``np.random.default_rng(seed)``, dealt to the folds in turn."""
    rng = np.random.default_rng(seed)
    fold_of = np.full(int(n), -1)
    for members in groups:
        own = rng.permutation(members)
        fold_of[own] = np.arange(len(own)) % int(folds)
    return fold_of


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
        cov = FactorAnalysis(n_components=rank, svd_method="lapack").fit(codes).get_covariance()
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

    @classmethod
    def from_moments(cls, mean: np.ndarray, deviations: np.ndarray, n_motion: int) -> DecodedGaussian:
        """The Gaussian of ``mean`` (D,) and ``deviations`` (M, D) (``Σ = AᵀA``)."""
        out = cls.__new__(cls)
        out.n_motion, out.mean, out.deviations = int(n_motion), np.asarray(mean), np.asarray(deviations)
        return out

    @classmethod
    def blend(cls, data: DecodedGaussian | None, model: DecodedGaussian, weight: float) -> DecodedGaussian:
        """The moments of the mixture ``weight · data + (1 - weight) · model`` (``model`` alone when
        ``data`` is None): its mean, and deviations ``[√w A_data; √(1-w) A_model; √(w(1-w)) (μ_data - μ_model)]``."""
        w = float(weight) if data is not None else 0.0
        if w <= 0.0:
            return model
        if w >= 1.0:
            return data
        gap = np.sqrt(w * (1.0 - w)) * (data.mean - model.mean)[None]
        deviations = np.concatenate([np.sqrt(w) * data.deviations, np.sqrt(1.0 - w) * model.deviations, gap])
        return cls.from_moments(w * data.mean + (1.0 - w) * model.mean, deviations, model.n_motion)

    def conditioned(self, mask: np.ndarray, r: float) -> ConditionedGaussian:
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


def condition_primitives(ensembles, seen: np.ndarray, mask: np.ndarray, wanted, r: float):
    """Conditioned means (n, P, D) and log evidences (n, P) of the Gaussians ``ensembles[k]`` for
    ``k`` in ``wanted[i]`` (the primitives asked of motion ``i``) on ``seen`` (n, T, J) where ``mask`` (n, T); NaN elsewhere."""
    n, _, j = seen.shape
    flat, flat_mask = seen.reshape(n, -1), np.repeat(mask, j, axis=1)
    d = ensembles[0].mean.shape[0]
    means = np.full((n, len(ensembles), d), np.nan)
    evidence = np.full((n, len(ensembles)), -np.inf)
    rows, inverse = np.unique(flat_mask, axis=0, return_inverse=True)
    for g, row in enumerate(rows):
        members = np.flatnonzero(inverse.reshape(-1) == g)
        for k in sorted({k for i in members for k in wanted[i]}):
            take = members[[k in wanted[i] for i in members]]
            cond = ensembles[k].conditioned(row, r)
            means[take, k], evidence[take, k] = cond.update(flat[take][:, row])
    return means, evidence


class StepGains:
    """The Kalman gains of :class:`DecodedGaussian` observed one step (``joints`` entries) at a time,
    steps ``1..steps`` in order, noise ``r``: the covariance recursion never reads the observed
    values, so it is computed once, before any motion arrives (``D² J`` per step), and a step then
    costs ``D J`` per motion (:class:`SequentialGaussian`)."""

    def __init__(self, prior: DecodedGaussian, r: float, joints: int, steps: int):
        if not r > 0:
            raise UserError(f"the observation noise must be > 0, got {r}")
        self.prior, self.joints = prior, int(joints)
        a = prior.deviations
        cov = a.T @ a
        eye = float(r) * np.eye(self.joints)
        self.chols, self.gains, self.logdets = [], [], []
        for t in range(int(steps)):
            index = np.arange(t * self.joints, (t + 1) * self.joints)
            chol = np.linalg.cholesky(cov[np.ix_(index, index)] + eye)
            gain_t = np.linalg.solve(chol.T, np.linalg.solve(chol, cov[index]))  # S⁻¹ Σ_o·, (J, D)
            cov -= cov[:, index] @ gain_t
            self.chols.append(chol)
            self.gains.append(gain_t)
            self.logdets.append(2.0 * np.log(np.diag(chol)).sum())


class SequentialGaussian:
    """:class:`DecodedGaussian` conditioned one step at a time (online): a mean and log evidence
    per motion, updated with the gains of :class:`StepGains`.

    After steps ``1..t`` have been observed, :attr:`means` and :attr:`evidence` equal
    :meth:`ConditionedGaussian.update` on their entries (the Kalman filter's sequential form of
    the same Gaussian conditioning; tested)."""

    def __init__(self, gains: StepGains, n: int):
        self.gains = gains
        self.means = np.tile(gains.prior.mean, (int(n), 1))
        self.evidence = np.zeros(int(n))

    def observe(self, t: int, values: np.ndarray) -> None:
        """Condition on step ``t`` (0-based) of every motion, its ``values`` (n, J)."""
        from scipy.linalg import solve_triangular

        g, j = self.gains, self.gains.joints
        residual = np.asarray(values, dtype=np.float64) - self.means[:, t * j : (t + 1) * j]
        white = solve_triangular(g.chols[t], residual.T, lower=True)
        self.evidence += -0.5 * ((white**2).sum(axis=0) + g.logdets[t] + j * math.log(2 * math.pi))
        self.means += residual @ g.gains[t]
