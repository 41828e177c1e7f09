"""How a segmentation is scored against the ground truth: boundaries matched one-to-one within
a tolerance (precision, recall, F1) and per-step labelling accuracy after the best matching of
ids; :func:`segmentation_scores` applies both, for every method and peer alike."""

from __future__ import annotations

from numbers import Real

import numpy as np

from primspace.cluster.metrics import clustering_accuracy
from primspace.segmentation.result import SegmentationResult
from primspace.utils.errors import UserError

__all__ = ["boundaries_from_segments", "boundary_f1", "step_labelling_accuracy", "segmentation_scores", "valid_lengths"]


def boundaries_from_segments(step_segments, lengths=None) -> list[np.ndarray]:
    """True boundary steps per sequence: ``t > 0`` where the segment index changes, both valid.

    Parameters
    ----------
    step_segments : array-like (N, T) of int, or list of 1-D arrays
        Segment index of each step, -1 at padding.
    lengths : array-like (N,) of int, optional
        Valid steps per sequence; later steps are ignored.

    Returns
    -------
    list of ndarray of int64
    """
    rows = _rows(step_segments, "step_segments")
    L = None if lengths is None else valid_lengths(lengths, len(rows))
    out = []
    for i, seg in enumerate(rows):
        valid = (seg != -1) & (np.arange(len(seg)) < (len(seg) if L is None else L[i]))
        change = (seg[1:] != seg[:-1]) & valid[1:] & valid[:-1]
        out.append(np.flatnonzero(change).astype(np.int64) + 1)
    return out


def boundary_f1(true_boundaries, found_boundaries, tolerance, extent=0) -> dict:
    """Precision, recall and F1 of found boundaries matched one-to-one within ``tolerance`` steps.

    A found ``f`` and a true ``t`` may match if ``|f - t| <= tolerance``, each at most once,
    and the matches are as many as possible. Per sequence, both sorted, the earliest
    unmatched found boundary is matched to the earliest true one within reach: optimal, as
    the reaches ``[t - tol, t + extent + tol]`` end in the order they start (all are equally
    long: earliest-deadline-first matching of points to intervals; an exchange argument).

    ``extent > 0``: each true boundary is the first step of a transition of ``extent``
    steps that belongs to neither primitive (the composite simulator's), and a found one
    matches anywhere from ``tol`` before it to ``tol`` after the transition's end.

    Parameters
    ----------
    true_boundaries, found_boundaries : list of array-like of int
        Per sequence, boundary steps; as many sequences in both.
    tolerance : float
        >= 0, in steps.
    extent : float, default 0
        >= 0: the steps of the transition that starts at each true boundary.

    Returns
    -------
    dict
        ``precision``, ``recall``, ``f1``, ``tp``, ``fp``, ``fn`` pooled over the sequences.
        Precision is 1 with nothing found, recall 1 with nothing to find (F1 1 if both).
    """
    if isinstance(tolerance, bool) or not isinstance(tolerance, Real) or not tolerance >= 0 or tolerance == np.inf:
        raise UserError(f"tolerance must be a finite number >= 0 (steps), got {tolerance!r}")
    if isinstance(extent, bool) or not isinstance(extent, Real) or not extent >= 0 or extent == np.inf:
        raise UserError(f"transition extent must be a finite number >= 0 (steps), got {extent!r}")
    if len(true_boundaries) != len(found_boundaries):
        raise UserError(f"{len(true_boundaries)} sequences of true boundaries but {len(found_boundaries)} found")
    tp = fp = fn = 0
    for t, f in zip(true_boundaries, found_boundaries):
        t, f = np.sort(np.asarray(t, dtype=float).ravel()), np.sort(np.asarray(f, dtype=float).ravel())
        m = _matches(t, f, float(tolerance), float(tolerance) + float(extent))
        tp, fp, fn = tp + m, fp + len(f) - m, fn + len(t) - m
    precision = tp / (tp + fp) if tp + fp else 1.0
    recall = tp / (tp + fn) if tp + fn else 1.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": float(precision), "recall": float(recall), "f1": float(f1), "tp": tp, "fp": fp, "fn": fn}


def _matches(t: np.ndarray, f: np.ndarray, before: float, after: float) -> int:
    """Most one-to-one pairs ``t - before <= f <= t + after`` of two sorted arrays (greedy, optimal)."""
    i = j = m = 0
    while i < len(t) and j < len(f):
        if f[j] < t[i] - before:
            j += 1  # f[j] is too early for t[i] and every later true boundary
        elif f[j] > t[i] + after:
            i += 1  # t[i] is too early for f[j] and every later found boundary
        else:
            i, j, m = i + 1, j + 1, m + 1
    return m


def step_labelling_accuracy(true_step_labels, found_step_labels) -> float:
    """Per-step accuracy over all valid steps pooled, after the best one-to-one matching of ids.

    ``true_step_labels``, ``found_step_labels``: (N, T) arrays or lists of 1-D arrays, a row
    per sequence; -1 is padding. Steps whose true label is -1 are ignored; a row may be
    longer than its partner by padding only; a found -1 at a valid step counts as wrong.
    Scored with :func:`~primspace.cluster.metrics.clustering_accuracy` (Hungarian).
    """
    t_rows, f_rows = _rows(true_step_labels, "true step labels"), _rows(found_step_labels, "found step labels")
    if len(t_rows) != len(f_rows):
        raise UserError(f"{len(t_rows)} sequences of true step labels but {len(f_rows)} found")
    ts, fs = [], []
    for i, (t, f) in enumerate(zip(t_rows, f_rows)):
        k = min(len(t), len(f))
        if np.any(t[k:] != -1) or np.any(f[k:] != -1):
            raise UserError(f"sequence {i}: {len(t)} true step labels but {len(f)} found (beyond padding)")
        ts.append(t[:k][t[:k] != -1])
        fs.append(f[:k][t[:k] != -1])
    t, f = np.concatenate(ts), np.concatenate(fs)
    if t.size == 0:
        raise UserError("no valid steps to score (every true step label is -1)")
    known = f != -1
    return clustering_accuracy(t[known], f[known]) * float(known.mean()) if known.any() else 0.0


def segmentation_scores(result: SegmentationResult, data, tolerance: int, transition: int = 0, **more) -> dict:
    """What ``primspace segment`` reports for any method: segments found and, when ``data`` (a
    :class:`~primspace.data.MotionDataset`) has the step fields, boundary F1 within ``tolerance``
    steps, per-step accuracy (then ``more``, e.g. the accuracy given the true boundaries);
    with ``transition > 0`` steps also ``boundary_transition``, the F1 that counts a found
    boundary anywhere within ``tolerance`` of the transition (:func:`boundary_f1`'s ``extent``)."""
    scores: dict = {"segments_found": int(sum(len(b) + 1 for b in result.boundaries))}
    if data.step_segments is None:
        return scores
    lengths = data.valid_lengths
    truth = boundaries_from_segments(data.step_segments, lengths)
    if transition:
        scores["boundary_transition"] = boundary_f1(truth, result.boundaries, tolerance, extent=transition)
    return scores | {
        "boundary": boundary_f1(truth, result.boundaries, tolerance),
        "accuracy": step_labelling_accuracy(data.step_labels, result.padded_step_labels(data.length)),
        **more,
        "tolerance": int(tolerance),
        "segments_true": int(sum(len(b) + 1 for b in truth)),
    }


def _rows(x, what: str) -> list[np.ndarray]:
    """A 2-D array or a list of 1-D arrays as a list of 1-D integer arrays."""
    if not isinstance(x, (list, tuple)) and np.ndim(x) != 2:
        raise UserError(f"{what} must be an (N, T) array or a list of 1-D arrays, got shape {np.shape(x)}")
    out = [np.asarray(r) for r in x]
    for i, r in enumerate(out):
        if r.ndim != 1 or (r.size and not np.issubdtype(r.dtype, np.integer)):
            raise UserError(f"{what}: sequence {i} must be a 1-D array of integers, got {r.dtype} {r.shape}")
    return out


def valid_lengths(lengths, n: int) -> np.ndarray:
    L = np.asarray(lengths)
    if L.shape != (n,) or (L.size and not np.issubdtype(L.dtype, np.integer)):
        raise UserError(f"lengths must be {n} integers (one per sequence), got {L.dtype} {L.shape}")
    return L.astype(np.int64)
