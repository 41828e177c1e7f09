"""Segmenting demonstrations into primitives from their sequences of window codes (``--method windows``).

The paper closes (Summary and Discussion): "To model more complex behaviours composed of many
consecutive primitives ... a sequence of such vectors is used", the challenges being that
"primitives might have different number of timesteps and not clear borderline between
primitives". A demonstration of ``L`` valid steps has window codes ``z_k``, window ``k``
covering steps ``[kW, (k+1)W)``. This module finds the borderlines from the codes and names
the primitives with the paper's tool: codes of one primitive lie near an affine subspace
(verbatim: "Moreover, these manifolds are close enough to affine subspaces, which enables us
to use subspace clustering algorithm for labeling a collection of motion in unsupervised
manner.").

* **Change points: exact penalised optimal partitioning** (Jackson et al. 2005) of a
  piecewise-constant model: within-segment sums of squares plus ``penalty`` per segment,
  minimised by dynamic programming in ``O(K^2 q)``.
* **Transition windows.** A window straddling a borderline mixes two primitives; fitted as it
  is, it becomes a short segment of its own (two boundaries for one: F1 about 0.75 on the
  planted data of the tests). So a segment after the first may leave its first window out of
  its fit; the boundary is placed inside that window by how much of its code resembles the
  segment before (within a step on the tests).
* **Automatic penalty** ``c sigma^2 (sqrt(q) + sqrt(2 log n))^2`` (:func:`auto_penalty`),
  ``sigma_j`` from median absolute consecutive differences (:func:`noise_variances`).
  Splitting noise gains about the largest of ``n`` chi-square statistics with ``q`` degrees
  of freedom; ``P(chi2_q >= q + 2 sqrt(q x) + 2 x) <= exp(-x)`` (Laurent & Massart 2000) with
  ``x = log n`` bounds it by the bracket. The BIC-like ``c q sigma^2 log n`` is too small for
  small ``q`` (q = 1, n = 32: 67 % of noise-only sequences split at c = 1) and needlessly large
  for large ``q``. ``c`` = :data:`AUTO_PENALTY_FACTOR` = 2: of noise-only sequences (noise
  estimated from the sequence alone, anisotropic) at most 6 % split at q <= 2 and n = 8, 3 %
  for n >= 16, none for q >= 8; c = 1 split up to 97 % at q = 40 (a transition window sheds the
  largest residual). The planted tests find every boundary with c = 2.
* **Fewest windows per segment** :data:`DEFAULT_MIN_SIZE` = 2: a segment after a transition
  keeps a window of its own, and no single outlying window becomes a primitive.
* **Labels: one code per segment** (the mean of its fitted windows), all segments clustered
  with the affine :class:`~primspace.cluster.LowRankSubspaceClustering`, tau chosen without
  labels (``r2_target="auto"``: a fixed 0.99 or 0.95 mislabelled up to 9 % or 15 % of planted
  steps where "auto" labelled all).
"""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np

from primspace.segmentation.result import SEGMENT_R2_TARGET, SegmentationResult, label_segments
from primspace.segmentation.scores import valid_lengths
from primspace.utils.errors import UserError

__all__ = [
    "AUTO_PENALTY_FACTOR",
    "DEFAULT_MIN_SIZE",
    "auto_penalty",
    "change_points",
    "noise_variances",
    "segment_sequences",
]

#: ``c`` of the automatic penalty (module docstring: why 2).
AUTO_PENALTY_FACTOR = 2.0
#: Fewest windows in a segment, a transition window included.
DEFAULT_MIN_SIZE = 2

# 1 / Phi^-1(3/4): the median absolute value of N(0, s^2) is s / 1.4826
_MAD_TO_SIGMA = 1.482602218505602


def noise_variances(codes) -> np.ndarray:
    """Noise variance of each code coordinate, ``sigma_j^2``, robust to change points.

    ``sigma_j = 1.4826 median|z[k+1, j] - z[k, j]| / sqrt(2)``: away from change points a
    consecutive difference is noise of variance ``2 sigma_j^2``; the median ignores the few.
    ``codes``: one (K, q) array or a list of them (differences within each). Zeros if no
    sequence has two windows.
    """
    seqs = [_codes(c, "codes") for c in (codes if isinstance(codes, (list, tuple)) else [codes])]
    diffs = [np.diff(z, axis=0) for z in seqs if len(z) > 1]
    if not diffs:
        return np.zeros(seqs[0].shape[1] if seqs else 0)
    return (_MAD_TO_SIGMA * np.median(np.abs(np.concatenate(diffs, axis=0)), axis=0)) ** 2 / 2.0


def auto_penalty(variances, n_windows: int, factor: float = AUTO_PENALTY_FACTOR) -> float:
    """``factor * (tr V / q_e) * (sqrt(q_e) + sqrt(2 log n))^2`` for ``V = diag(variances)``.

    ``q_e = (tr V)^2 / tr(V^2)`` is the noise's effective dimension (``q`` if isotropic:
    ``c sigma^2 (sqrt(q) + sqrt(2 log n))^2``); ``n = max(n_windows, 2)``. 0 for no noise.
    """
    v = np.asarray(variances, dtype=np.float64)
    trace = float(v.sum())
    if trace <= 0:
        return 0.0
    q_eff = trace**2 / float(np.sum(v**2))
    return float(factor * trace / q_eff * (np.sqrt(q_eff) + np.sqrt(2 * np.log(max(int(n_windows), 2)))) ** 2)


def change_points(
    codes, n_valid=None, *, penalty="auto", min_size: int = DEFAULT_MIN_SIZE, transitions: bool = True
) -> np.ndarray:
    """Windows where a new segment starts, by exact penalised optimal partitioning.

    Minimises the sum over segments of (within-segment sum of squares + ``penalty``) over
    every partition of the first ``n_valid`` windows into segments of ``min_size`` or more
    windows; with ``transitions`` a segment after the first may leave its first window out
    of its sum of squares (module docstring).

    Parameters
    ----------
    codes : array-like (K, q)
        Window codes of one sequence.
    n_valid : int, optional
        Only the first ``n_valid`` windows count (default all).
    penalty : "auto" or float
        Cost of one more segment, in squared code units. "auto": :func:`auto_penalty` of
        :func:`noise_variances` of these windows (at least 1e-9 of their sum of squares,
        so that rounding never splits a constant run).
    min_size : int
        Fewest windows per segment (>= 1).
    transitions : bool
        Allow transition windows. Window ``k`` may then be the last window of the old
        segment, shed (:func:`segment_sequences` places the step boundary inside it).

    Returns
    -------
    ndarray of int64
        Ascending window indices ``k >= 1``; empty for one segment.
    """
    Z = _codes(codes, "codes")
    n = len(Z) if n_valid is None else _count("n_valid", n_valid, 0)
    if n > len(Z):
        raise UserError(f"n_valid={n} is more than the {len(Z)} windows given")
    min_size, Z = _count("min_size", min_size, 1), Z[:n]
    beta = _penalty(penalty)
    beta = _auto(noise_variances(Z), Z) if beta is None else beta
    return _partition(Z, beta, min_size, bool(transitions))[0]


def _partition(Z: np.ndarray, beta: float, min_size: int, transitions: bool):
    """Change points and transition flags of the windows ``Z`` (none if too few to split)."""
    if len(Z) < 2 * min_size:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    return _optimal_partition(Z - Z.mean(axis=0), beta, min_size, transitions)


def _optimal_partition(Z: np.ndarray, beta: float, min_size: int, transitions: bool):
    """Optimal partitioning (Jackson et al. 2005): ``best[t]`` = least cost of windows ``[0, t)``.

    Segment ``[s, t)`` costs its sum of squares, or (``transitions``, ``s > 0``) that of
    ``[s + 1, t)`` when less: window ``s`` is then a transition. Ties go to the earliest
    start and to no transition.
    """
    n = len(Z)
    S = np.vstack([np.zeros((1, Z.shape[1])), np.cumsum(Z, axis=0)])
    Q = np.concatenate([[0.0], np.cumsum(np.sum(Z * Z, axis=1))])
    best = np.full(n + 1, np.inf)
    best[0] = -beta  # the first segment's penalty cancels: best[n] counts one per change point
    last, dropped = np.zeros(n + 1, dtype=np.int64), np.zeros(n + 1, dtype=bool)
    for t in range(min_size, n + 1):
        s = np.arange(0, t - min_size + 1)
        cost = _sum_of_squares(S, Q, s, t)
        drop = np.zeros(len(s), dtype=bool)
        if transitions:
            alt = np.where((s > 0) & (s + 1 < t), _sum_of_squares(S, Q, np.minimum(s + 1, t - 1), t), np.inf)
            drop = alt < cost
            cost = np.where(drop, alt, cost)
        total = best[s] + cost + beta
        j = int(np.argmin(total))
        best[t], last[t], dropped[t] = total[j], s[j], drop[j]
    points, flags, t = [], [], n
    while last[t] > 0:
        points.append(int(last[t]))
        flags.append(bool(dropped[t]))
        t = int(last[t])
    return np.asarray(points[::-1], dtype=np.int64), np.asarray(flags[::-1], dtype=bool)


def _sum_of_squares(S, Q, s, t) -> np.ndarray:
    """Within sum of squares of windows ``[s, t)`` for each start ``s < t``, from cumulative sums."""
    return np.maximum(Q[t] - Q[s] - np.sum((S[t] - S[s]) ** 2, axis=1) / (t - s), 0.0)


def segment_sequences(
    code_sequences,
    window: int,
    lengths,
    n_primitives: int,
    *,
    penalty="auto",
    min_size: int = DEFAULT_MIN_SIZE,
    transitions: bool = True,
    r2_target=SEGMENT_R2_TARGET,
    random_state=0,
) -> SegmentationResult:
    """Split every sequence at its change points and label the segments by subspace clustering.

    Parameters
    ----------
    code_sequences : array-like (N, K, q), or list of N arrays (K_i, q)
        Window codes; sequence ``i`` uses its first ``ceil(lengths[i] / window)`` (the rest
        is padding and may hold anything).
    window : int
        Steps per window, ``W >= 1``.
    lengths : array-like (N,) of int
        Valid steps per sequence, >= 1.
    n_primitives : int
        Clusters of segment codes.
    penalty : "auto" or float
        As in :func:`change_points`, but "auto" estimates the noise once from all sequences
        (one model, one noise level; a short sequence alone estimates it badly).
    min_size, transitions
        As in :func:`change_points`.
    r2_target : float or "auto"
        Of the affine :class:`~primspace.cluster.LowRankSubspaceClustering` of segment codes.
    random_state : int
        Seed of the clustering.

    Returns
    -------
    SegmentationResult
        With ``n_primitives`` or fewer segments in all there is nothing to cluster: each
        segment is its own label and ``note`` says so.
    """
    valid, L, window = _checked_sequences(code_sequences, window, lengths)
    n_primitives, min_size = _count("n_primitives", n_primitives, 1), _count("min_size", min_size, 1)
    beta, variances = _penalty(penalty), noise_variances(valid)
    penalties = np.array([_auto(variances, z) if beta is None else beta for z in valid])
    parts = [_partition(z, float(p), min_size, bool(transitions)) for z, p in zip(valid, penalties)]
    table = [_sequence_segments(z, *part, window, int(n)) for z, part, n in zip(valid, parts, L)]
    codes = np.concatenate([t[0] for t in table], axis=0)
    sample = np.concatenate([np.full(len(t[0]), i, dtype=np.int64) for i, t in enumerate(table)])
    start, stop = (np.concatenate([t[j] for t in table]) for j in (1, 2))
    labels, note = label_segments(codes, n_primitives, r2_target, random_state)
    return SegmentationResult(
        boundaries=[t[1][1:] for t in table],
        step_labels=[np.repeat(labels[sample == i], (stop - start)[sample == i]) for i in range(len(valid))],
        segment_codes=codes,
        segment_sample=sample,
        segment_start=start,
        segment_stop=stop,
        segment_labels=labels,
        change_points=[p[0] for p in parts],
        transitions=[p[1] for p in parts],
        penalties=penalties,
        window=window,
        note=note,
    )


def _sequence_segments(z, points, flags, window: int, length: int):
    """Code (mean of the fitted windows), first and past-the-last step of each segment.

    A segment starting at window ``k`` starts at step ``k * window``; after a transition
    window, at ``k * window + round(f * window)``, ``f`` in [0, 1] the least-squares share
    of the segment before in ``z_k ~ f a + (1 - f) b`` (``a``, ``b``: the codes either side).
    """
    edges = np.concatenate([[0], points, [len(z)]]).astype(np.int64)
    first = edges[:-1] + np.concatenate([[0], flags.astype(np.int64)])
    codes = np.stack([z[a:b].mean(axis=0) for a, b in zip(first, edges[1:])])
    steps = [0]
    for j, (k, drop) in enumerate(zip(points, flags)):
        d = codes[j] - codes[j + 1]
        f = float(np.clip((z[k] - codes[j + 1]) @ d / (d @ d), 0.0, 1.0)) if drop and d @ d > 0 else 0.0
        steps.append(int(k) * window + int(round(f * window)))
    steps.append(length)
    return codes, np.asarray(steps[:-1], dtype=np.int64), np.asarray(steps[1:], dtype=np.int64)


def _codes(codes, what: str) -> np.ndarray:
    Z = np.asarray(codes, dtype=np.float64)
    if Z.ndim != 2:
        raise UserError(f"{what} must be (K, q) window codes, got shape {Z.shape}")
    if not np.isfinite(Z).all():
        raise UserError(f"{what} are not finite (window {np.flatnonzero(~np.isfinite(Z).all(axis=1))[0]})")
    return Z


def _count(name: str, value, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral) or value < least:
        raise UserError(f"{name} must be an integer >= {least}, got {value!r}")
    return int(value)


def _penalty(penalty) -> float | None:
    """None for "auto", else the penalty, a finite number >= 0."""
    if isinstance(penalty, str) and penalty == "auto":
        return None
    if isinstance(penalty, bool) or not isinstance(penalty, Real) or not np.isfinite(penalty) or penalty < 0:
        raise UserError(f"penalty must be 'auto' or a finite number >= 0, got {penalty!r}")
    return float(penalty)


def _auto(variances, Z: np.ndarray) -> float:
    """The automatic penalty for the windows ``Z``, at least 1e-9 of their sum of squares."""
    spread = float(np.sum((Z - Z.mean(axis=0)) ** 2)) if len(Z) else 0.0
    return max(auto_penalty(variances, len(Z)), 1e-9 * spread)


def _checked_sequences(code_sequences, window, lengths):
    """The valid windows of each sequence (finite, one code size), lengths (>= 1) and window."""
    window = _count("window", window, 1)
    if not isinstance(code_sequences, (list, tuple)) and np.ndim(code_sequences) != 3:
        raise UserError(f"code sequences must be (N, K, q) or a list of (K, q) arrays, got {np.shape(code_sequences)}")
    seqs = [np.asarray(z, dtype=np.float64) for z in code_sequences]
    if not seqs or any(z.ndim != 2 for z in seqs) or len({z.shape[1] for z in seqs}) > 1:
        raise UserError(f"code sequences must be one or more (K, q) arrays of one q, got {[z.shape for z in seqs]}")
    L = valid_lengths(lengths, len(seqs))
    if np.any(L < 1):
        raise UserError(f"every length must be >= 1; sequence {int(np.argmin(L))} has {int(L.min())}")
    n_valid = -(-L // window)
    for i, (z, n) in enumerate(zip(seqs, n_valid)):
        if n > len(z):
            raise UserError(f"sequence {i}: length {L[i]} needs {n} windows of {window} steps; its codes have {len(z)}")
    return [_codes(z[:n], f"codes of sequence {i}") for i, (z, n) in enumerate(zip(seqs, n_valid))], L, window
