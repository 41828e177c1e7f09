"""Choosing tau by held-out evidence: ``LowRankSubspaceClustering(r2_target="select")``, the default.

Neither the fixed R^2 target nor the label-free criterion of :mod:`primspace.cluster.auto`
is best on every data set: the fixed 0.99 loses on noisy sensor recordings (BasicMotions
0.28 against 0.71) and on clean simulated trajectories (0.68 against 1.00), the label-free
choice loses on learned codes (0.57 against 0.88). Selection compares the candidates by a
score that needs no labels, measured on points a fit did not see, and keeps the best:

Candidates
    :data:`SELECT_FIXED_TARGETS` (the fixed default 0.99 first, then 0.7, where noisy
    recordings cluster best) and the R^2 target the label-free criterion chose on all points
    (:func:`~primspace.cluster.auto.choose_tau`), each target once.
Score: held-out stability
    The points (at most :data:`SELECT_MAX_SAMPLES`, drawn once) are split at random into
    thirds ``A, B, C``; ``A + C`` and ``B + C`` are clustered *independently* (each its own
    SVD, its own tau for the candidate's R^2 target), and the two partitions are compared on
    the shared third ``C`` by the adjusted Rand index, times the smaller of the two fits'
    normalised label entropies (``H(labels) / log k``: 1 for equal clusters, near 0 when one
    cluster takes nearly every point). Mean over :data:`SELECT_REPEATS` splits, the same
    splits for every candidate. A tau that fits structure shared by the whole data set gives
    the same partition of ``C`` from either half; a tau that fits noise (``Q*`` near the
    identity) or merges subspaces does not. The entropy factor discounts a partition that is
    stable because it is degenerate (one cluster and consistent outliers: smartwatch
    recordings at R^2 0.99 agree with ARI 0.82 at accuracy 0.18).

Eligible: a candidate whose ``Q*`` (on all points) has rank at least ``k``. A ``Q*`` of rank
``r < k`` cannot be block-diagonal with ``k`` nonzero blocks (each block has rank >= 1), so it
cannot separate ``k`` subspaces, however stably it partitions the halves (paper-preset codes,
seed 2: R^2 0.9, rank 6 for 7 primitives, scores 0.92 against 0.88 for 0.99 at accuracy 0.55
against 0.79). Such candidates are not scored, unless no candidate is eligible.

The highest score wins; ties (within ``1e-9``) go to the earlier candidate, so the fixed
default wins ties. With too few points for the halves (fewer than ``n_clusters + 1`` in a
half) or only one distinct candidate, nothing is scored and the first candidate is kept.
Deterministic given ``random_state``. The evaluation is in docs/clustering.md.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.metrics import adjusted_rand_score
from sklearn.utils import check_random_state

from primspace.utils.errors import UserError

__all__ = [
    "SELECT",
    "SELECT_FIXED_TARGETS",
    "SELECT_MAX_SAMPLES",
    "SELECT_REPEATS",
    "TauSelection",
    "heldout_splits",
    "heldout_stability",
    "select_r2_target",
]

#: The ``r2_target`` that chooses tau by held-out evidence (the default).
SELECT = "select"

#: The fixed candidates, in tie-break order: the fixed default target first.
SELECT_FIXED_TARGETS = (0.99, 0.7)

#: Splits per candidate, and the most points the held-out score uses.
SELECT_REPEATS = 3
SELECT_MAX_SAMPLES = 2000

_TIE = 1e-9


@dataclass(frozen=True, eq=False)
class TauSelection:
    """The candidates of a held-out choice of tau, their scores and the one chosen.

    Attributes
    ----------
    r2_targets : tuple of float
        The distinct candidate R^2 targets, in tie-break order.
    sources : tuple of tuple of str
        Where each came from: ``"default"``, ``"fixed"`` and/or ``"auto"`` (the label-free
        criterion's choice).
    ranks : tuple of int
        Each candidate's rank of ``Q*`` on all points (-1: not known).
    scores : ndarray of shape (len(r2_targets),)
        Held-out stability of each (NaN: not scored: rank below ``n_clusters``, or see ``note``).
    index : int
        The chosen candidate.
    auto : dict
        The label-free criterion's record (:meth:`AutoTauChoice.to_dict
        <primspace.cluster.auto.AutoTauChoice.to_dict>`).
    repeats, n_points : int
        Splits per candidate, and the points they were drawn from.
    note : str or None
        Why nothing was scored, if nothing was.
    """

    r2_targets: tuple
    sources: tuple
    ranks: tuple
    scores: np.ndarray
    index: int
    auto: dict
    repeats: int
    n_points: int
    note: str | None = None

    @property
    def r2_target(self) -> float:
        return float(self.r2_targets[self.index])

    def to_dict(self) -> dict:
        """``score`` (its name), ``r2_target`` (chosen), ``chosen`` (its sources), ``candidates``
        (``r2_target``, ``sources``, ``rank``, ``score``; NaN as None), ``repeats``, ``n_points``,
        ``note`` and the label-free criterion's ``auto`` record."""
        return {
            "score": "heldout_stability",
            "r2_target": self.r2_target,
            "chosen": list(self.sources[self.index]),
            "candidates": [
                {
                    "r2_target": float(t),
                    "sources": list(s),
                    "rank": int(r),
                    "score": None if not np.isfinite(v) else float(v),
                }
                for t, s, r, v in zip(self.r2_targets, self.sources, self.ranks, self.scores)
            ],
            "repeats": self.repeats,
            "n_points": self.n_points,
            "note": self.note,
            "auto": self.auto,
        }


def heldout_splits(n_samples: int, *, repeats: int = SELECT_REPEATS, max_samples: int = SELECT_MAX_SAMPLES, rng=None):
    """``repeats`` splits ``(first, second, shared)`` of index arrays (sorted): two halves
    ``A + C`` and ``B + C`` of a random thirds split of at most ``max_samples`` of the
    ``n_samples`` points, and their shared third ``C``."""
    rng = np.random.default_rng(rng)
    pool = np.arange(n_samples) if n_samples <= max_samples else rng.choice(n_samples, max_samples, replace=False)
    splits = []
    for _ in range(repeats):
        a, b, c = np.array_split(rng.permutation(pool), 3)
        splits.append((np.sort(np.r_[a, c]), np.sort(np.r_[b, c]), np.sort(c)))
    return splits


def heldout_stability(X: np.ndarray, n_clusters: int, fit_labels: Callable[[np.ndarray], np.ndarray], splits) -> float:
    """Mean over ``splits`` of ARI on the shared third times the smaller normalised entropy.

    ``fit_labels(X_half)`` clusters one half on its own. A half whose fit fails (e.g. the
    candidate keeps no component of its ``Q*``) scores 0 for that split; k-means finding fewer
    than k clusters in a half is scored (low, by the entropy), not warned.
    """
    values = []
    for first, second, shared in splits:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                one, two = fit_labels(X[first]), fit_labels(X[second])
        except (UserError, ValueError):
            values.append(0.0)
            continue
        ari = adjusted_rand_score(one[np.searchsorted(first, shared)], two[np.searchsorted(second, shared)])
        values.append(ari * min(_balance(one, n_clusters), _balance(two, n_clusters)))
    return float(np.mean(values))


def _balance(labels: np.ndarray, n_clusters: int) -> float:
    """``H(labels) / log k``: 1 for k equal clusters, 0 for one."""
    if n_clusters < 2:
        return 1.0
    p = np.bincount(labels, minlength=n_clusters) / labels.size
    p = p[p > 0]
    return float(-(p * np.log(p)).sum() / np.log(n_clusters))


def select_r2_target(
    X: np.ndarray,
    n_clusters: int,
    auto: dict,
    fit_labels: Callable[[np.ndarray, float], np.ndarray],
    *,
    rank_of: Callable[[float], int] | None = None,
    fixed: Sequence[float] = SELECT_FIXED_TARGETS,
    repeats: int = SELECT_REPEATS,
    max_samples: int = SELECT_MAX_SAMPLES,
    random_state=None,
) -> TauSelection:
    """Score the candidates (``fixed`` targets, then ``auto["r2_target"]``) by held-out
    stability on the rows of ``X``; pick the best (see the module docstring).

    Parameters
    ----------
    X : ndarray of shape (n_samples, n_features)
    n_clusters : int
    auto : dict
        The label-free choice's record (``AutoTauChoice.to_dict()``); its ``r2_target`` is a
        candidate.
    fit_labels : callable
        ``fit_labels(X_half, r2_target)``: the labels of a fit of those points alone at that
        target, with every other setting of the fit being chosen.
    rank_of : callable, optional
        ``rank_of(r2_target)``: the rank of ``Q*`` on all points at that target; candidates
        below ``n_clusters`` are not scored while another is eligible. None: all eligible.
    fixed, repeats, max_samples
        The fixed candidates (the first is the tie-break winner), splits, points used.
    random_state : int, RandomState or None
        Seeds the splits.
    """
    targets, sources = [], []
    for target, source in [(t, "default" if i == 0 else "fixed") for i, t in enumerate(fixed)] + [
        (auto["r2_target"], "auto")
    ]:
        target = float(target)
        if target in targets:
            sources[targets.index(target)].append(source)
        else:
            targets.append(target)
            sources.append([source])
    n = X.shape[0]
    half = 2 * (min(n, max_samples) // 3)
    ranks = [-1 if rank_of is None else int(rank_of(t)) for t in targets]
    eligible = [r < 0 or r >= n_clusters for r in ranks]
    if not any(eligible):
        eligible = [True] * len(targets)
    scores = np.full(len(targets), np.nan)
    note = None
    if len(targets) == 1:
        note = "one candidate"
    elif half < n_clusters + 1:
        note = f"{n} points are too few to split into halves of more than {n_clusters} points"
    else:
        rng = check_random_state(random_state).randint(np.iinfo(np.int32).max)
        splits = heldout_splits(n, repeats=repeats, max_samples=max_samples, rng=rng)
        for i, target in enumerate(targets):
            if eligible[i]:
                scores[i] = heldout_stability(X, n_clusters, lambda part, t=target: fit_labels(part, t), splits)
    index = eligible.index(True)
    if np.any(np.isfinite(scores)):
        index = int(np.flatnonzero(scores >= np.nanmax(scores) - _TIE)[0])
    return TauSelection(
        r2_targets=tuple(targets),
        sources=tuple(tuple(s) for s in sources),
        ranks=tuple(ranks),
        scores=scores,
        index=index,
        auto=auto,
        repeats=repeats,
        n_points=min(n, max_samples),
        note=note,
    )
