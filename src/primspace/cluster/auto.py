"""Choosing tau without labels: ``LowRankSubspaceClustering(r2_target="auto")``.

The paper chose tau by a target R^2 of the reconstruction ``Z ~ Z Q*`` (0.85-0.95 for its
motion capture), and no one target suits every data set: clean simulated trajectories
cluster perfectly at R^2 = 0.9999 and poorly at 0.9, noisy sensor recordings the other way
round (docs/clustering.md, *Choosing tau without labels*). Here tau is chosen over a grid of
R^2 targets (:data:`AUTO_R2_GRID`) by a criterion that needs no labels. Every candidate
follows from the one SVD of ``Z~`` (:class:`~primspace.cluster.lrsc.SelfRepresentationSVD`),
so a candidate costs one spectral step (eigengap) or a few (stability), never another SVD.

Criteria (:data:`AUTO_CRITERIA`)
--------------------------------
``"relative_eigengap"`` (the default)
    ``(lambda_k - lambda_{k+1}) / (1 - lambda_{k+1}) = 1 - mu_k / mu_{k+1}``, where
    ``mu = 1 - lambda`` are the eigenvalues of the normalised Laplacian ``I - M``: how much
    closer to ``k`` disconnected blocks (``mu_k = 0``) the affinity is than to ``k + 1``.
    Unlike the plain gap it is not lowered by structure *inside* the clusters (a large
    ``lambda_{k+1}`` with ``lambda_k`` nearer 1 still scores high), and where ``Q*`` tends to
    the identity (rank near n: every eigenvalue near 1) it compares the small ``mu`` rather
    than rewarding ``lambda_k`` near 1. Why it is the default: the evaluation in
    docs/clustering.md.
``"eigengap"``
    ``lambda_k - lambda_{k+1}`` of the normalised affinity ``M = D^-1/2 W D^-1/2`` at the
    candidate's ``Q*`` (Ng, Jordan & Weiss 2001; von Luxburg 2007, section 8.3). ``M``'s
    eigenvalues lie in [-1, 1] whatever tau is, and ``k`` clusters with no affinity between
    them give ``lambda_1 = ... = lambda_k = 1`` with ``lambda_{k+1} < 1``: the gap measures
    how close the affinity is to ``k`` disconnected blocks. One eigenproblem (``k + 1``
    vectors) per candidate, shared with ``"relative_eigengap"``.
``"stability"``
    Mean adjusted Rand index between the labels of all points and those of random
    subsamples (``AUTO_SUBSAMPLES`` draws of ``AUTO_SUBSAMPLE_FRACTION`` of the points),
    each subsample clustered on its own block of the same ``Q*`` (Ben-Hur, Elisseeff & Guyon
    2002; Lange et al. 2004). ``1 + AUTO_SUBSAMPLES`` spectral steps per candidate. A
    labelling of all points with fewer than ``k`` distinct clusters scores 0 (it is
    perfectly "stable" and useless).

The chosen candidate is the one with the highest score, ties (within ``1e-9``) going to the
smaller R^2 target; a candidate whose tau keeps no component of ``Q*`` scores NaN and is never
chosen. Deterministic given ``random_state``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.metrics import adjusted_rand_score
from sklearn.utils import check_random_state

from primspace.cluster.lrsc import R2_GRID, SelfRepresentationSVD
from primspace.cluster.spectral import (
    choose_spectral_method,
    njw_labels,
    spectral_embedding,
)
from primspace.utils.errors import UserError

__all__ = [
    "AUTO_CRITERIA",
    "AUTO_R2_GRID",
    "DEFAULT_AUTO_CRITERION",
    "AutoTauChoice",
    "choose_tau",
    "eigengap_score",
    "top_eigenvalues",
    "stability_score",
]

#: The criteria ``r2_target="auto"`` can use; the first is the default.
AUTO_CRITERIA = ("relative_eigengap", "eigengap", "stability")
DEFAULT_AUTO_CRITERION = "relative_eigengap"

#: The candidates: the one R^2 grid (:data:`primspace.cluster.lrsc.R2_GRID`, which the sweep uses too).
AUTO_R2_GRID = R2_GRID

#: Stability: subsamples per candidate, and the fraction of the points in each.
AUTO_SUBSAMPLES = 5
AUTO_SUBSAMPLE_FRACTION = 0.8

_TIE = 1e-9
_FLAT = 1e-9  # 1 - lambda_{k+1} below this: the affinity is the identity to rounding


@dataclass(frozen=True, eq=False)
class AutoTauChoice:
    """The candidates of a label-free choice of tau, their scores, and the one chosen.

    Attributes
    ----------
    criterion : str
        One of :data:`AUTO_CRITERIA`.
    grid : tuple of float
        The candidates' R^2 targets.
    taus, r2, ranks, scores : ndarray of shape (len(grid),)
        Each candidate's tau, achieved R^2, rank of ``Q*`` and score (NaN: ``Q* = 0``).
    index : int
        The chosen candidate.
    """

    criterion: str
    grid: tuple
    taus: np.ndarray
    r2: np.ndarray
    ranks: np.ndarray
    scores: np.ndarray
    index: int

    @property
    def tau(self) -> float:
        return float(self.taus[self.index])

    @property
    def r2_target(self) -> float:
        return float(self.grid[self.index])

    def to_dict(self) -> dict:
        """``criterion``, ``r2_target`` (chosen), ``grid`` and ``scores`` (NaN as None)."""
        scores = [None if not np.isfinite(s) else float(s) for s in self.scores]
        return {
            "criterion": self.criterion,
            "r2_target": self.r2_target,
            "grid": [float(g) for g in self.grid],
            "scores": scores,
        }


def choose_tau(
    svd: SelfRepresentationSVD,
    n_clusters: int,
    *,
    criterion: str = DEFAULT_AUTO_CRITERION,
    grid=AUTO_R2_GRID,
    affinity: str = "squared",
    spectral: str = "auto",
    n_init: int = 20,
    random_state=None,
) -> AutoTauChoice:
    """Score every R^2 target of ``grid`` by ``criterion`` on one SVD; pick the best.

    Parameters
    ----------
    svd : SelfRepresentationSVD
        The decomposition of the points (:meth:`LowRankSubspaceClustering.decompose`).
    n_clusters : int
    criterion : {"relative_eigengap", "eigengap", "stability"}
        See the module docstring.
    grid : sequence of float
        R^2 targets in (0, 1).
    affinity, spectral, n_init
        As in :class:`~primspace.cluster.LowRankSubspaceClustering`.
    random_state : int, RandomState or None
        Seeds the eigensolvers, k-means and the subsamples.

    Raises
    ------
    UserError
        An unknown criterion, an empty grid or a target outside (0, 1), or no candidate
        keeping any component of ``Q*``.
    """
    if criterion not in AUTO_CRITERIA:
        raise UserError(f"auto criterion must be one of {', '.join(AUTO_CRITERIA)}; got {criterion!r}")
    grid = tuple(float(g) for g in grid)
    if not grid or not all(0 < g < 1 for g in grid):
        raise UserError(f"the auto grid must be R^2 targets in (0, 1), got {list(grid)}")
    seed = check_random_state(random_state).randint(np.iinfo(np.int32).max)
    taus = np.array([svd.tau_for_r2(g) for g in grid])
    ranks = np.array([svd.rank(t) for t in taus])
    scores = np.full(len(grid), np.nan)
    for i, tau in enumerate(taus):
        if ranks[i] == 0:
            continue
        if criterion != "stability":
            scores[i] = eigengap_score(
                svd,
                tau,
                n_clusters,
                affinity=affinity,
                spectral=spectral,
                random_state=seed,
                relative=criterion == "relative_eigengap",
            )
        else:
            scores[i] = stability_score(
                svd, tau, n_clusters, affinity=affinity, spectral=spectral, n_init=n_init, random_state=seed
            )
    if not np.any(np.isfinite(scores)):
        raise UserError("no tau of the auto grid keeps a component of Q*: the data are constant")
    best = np.nanmax(scores)
    index = int(np.flatnonzero(scores >= best - _TIE)[0])
    r2 = np.array([svd.r2(t) for t in taus])
    return AutoTauChoice(criterion, grid, taus, r2, ranks, scores, index)


def top_eigenvalues(
    svd: SelfRepresentationSVD,
    tau: float,
    count: int,
    *,
    affinity: str = "squared",
    spectral: str = "auto",
    random_state=None,
) -> np.ndarray:
    """The ``count`` largest eigenvalues of ``D^-1/2 W D^-1/2`` at ``tau``, descending; those
    at rounding level (or beyond the number of points) as 0."""
    factor = svd.factor(tau)
    n = factor.shape[0]
    method = choose_spectral_method(n, factor.shape[1], affinity, spectral)
    values = spectral_embedding(
        factor, min(count, n), affinity=affinity, method=method, random_state=random_state
    ).eigenvalues
    padded = np.zeros(count)
    padded[: min(values.size, count)] = values[:count]
    return padded


def eigengap_score(
    svd: SelfRepresentationSVD,
    tau: float,
    n_clusters: int,
    *,
    affinity: str = "squared",
    spectral: str = "auto",
    random_state=None,
    relative: bool = False,
) -> float:
    """``lambda_k - lambda_{k+1}`` of ``D^-1/2 W D^-1/2`` at ``tau``, or with ``relative``
    that divided by ``1 - lambda_{k+1}`` (0 where ``lambda_{k+1}`` is 1 to rounding)."""
    if n_clusters >= svd.n_samples:
        return 0.0
    values = top_eigenvalues(svd, tau, n_clusters + 1, affinity=affinity, spectral=spectral, random_state=random_state)
    gap = float(values[n_clusters - 1] - values[n_clusters])
    if not relative:
        return gap
    rest = 1.0 - float(values[n_clusters])
    return gap / rest if rest > _FLAT else 0.0


def stability_score(
    svd: SelfRepresentationSVD,
    tau: float,
    n_clusters: int,
    *,
    affinity: str = "squared",
    spectral: str = "auto",
    n_init: int = 20,
    random_state=None,
    n_subsamples: int = AUTO_SUBSAMPLES,
    fraction: float = AUTO_SUBSAMPLE_FRACTION,
) -> float:
    """Mean ARI between all points' labels and each subsample's own labels, at ``tau``.

    A subsample is clustered on its block of the same ``Q*`` (rows of ``F``), so it tests the
    spectral step's stability, not the SVD's.
    """
    factor = svd.factor(tau)
    n = factor.shape[0]
    size = max(n_clusters + 1, round(fraction * n))
    if size >= n:
        return 1.0
    rng = np.random.default_rng(random_state)
    full = _labels(factor, n_clusters, affinity, spectral, n_init, rng)
    if np.unique(full).size < n_clusters:
        return 0.0
    aris = []
    for _ in range(n_subsamples):
        idx = np.sort(rng.choice(n, size=size, replace=False))
        aris.append(adjusted_rand_score(full[idx], _labels(factor[idx], n_clusters, affinity, spectral, n_init, rng)))
    return float(np.mean(aris))


def _labels(factor, n_clusters, affinity, spectral, n_init, rng) -> np.ndarray:
    method = choose_spectral_method(factor.shape[0], factor.shape[1], affinity, spectral)
    seed = int(rng.integers(np.iinfo(np.int32).max))
    embedding = spectral_embedding(factor, n_clusters, affinity=affinity, method=method, random_state=seed)
    with warnings.catch_warnings():  # k-means finding < k clusters: scored as degenerate, not warned
        warnings.simplefilter("ignore", ConvergenceWarning)
        return njw_labels(embedding.vectors, n_clusters, n_init=n_init, random_state=seed)
