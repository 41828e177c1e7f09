"""Upper bounds for segmentation and labelling: what the true segments allow, with and without labels.

A low labelling score has two readings: the method fails, or the primitives cannot be told
apart (the data are ambiguous). These bounds separate them, on the *true* segments of held-out
demonstrations (from their ``step_segments`` and ``step_labels``):

* **Supervised** (:func:`supervised_bound`): a classifier trained with the labels,
  stratified k-fold cross-validated (``k`` = :data:`FOLDS`, or the rarest primitive's count
  if fewer; shuffled with ``random_state``), predicts each true segment's primitive from one
  feature vector per segment. Two classifiers: multinomial logistic regression on
  standardised features (a linear reader), and the nearest neighbour in the features as
  they are (the geometry an unsupervised clustering sees). If a classifier names the
  primitives of the true segments, the data are not ambiguous and a low unsupervised score
  is the method's.
* **Unsupervised, boundaries given** (:func:`clustered_bound`): the true segments'
  features clustered as primspace clusters segments
  (:func:`~primspace.segmentation.label_segments`), scored per step (Hungarian).

Features of a segment (:func:`segment_features`): ``raw``, its scaled joints resampled to
:data:`~primspace.segmentation.peers.LABEL_STEPS` steps and flattened; ``relative``, the
same minus its first step (the pose it started from removed: if primitives were ambiguous
because a primitive starts where the one before ended, this would read them better);
:func:`window_code_features`, the mean of the window codes a segment touches (what
primspace clusters), or their sequence resampled to :data:`CODE_WINDOWS` (what a labeller
that keeps the order could read).

Accuracies are per step (each segment weighs its length), comparable with
:func:`~primspace.segmentation.step_labelling_accuracy`; a classifier's labels are the true
ids, so no matching is needed. ``first`` and ``later`` split them by the segment's place in
its demonstration (first from home; later from where the one before ended).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from primspace.segmentation.peers import LABEL_STEPS, resample_segment
from primspace.segmentation.result import label_segments
from primspace.segmentation.scores import step_labelling_accuracy
from primspace.utils.errors import UserError

__all__ = [
    "FOLDS",
    "CODE_WINDOWS",
    "TrueSegments",
    "true_segments",
    "segment_features",
    "window_code_features",
    "supervised_bound",
    "clustered_bound",
]

#: Folds of the cross-validation.
FOLDS = 5
#: Windows a segment's code sequence is resampled to (the shortest composite-demo primitive spans 4-5).
CODE_WINDOWS = 4


@dataclass
class TrueSegments:
    """The true segments, ordered by demonstration then time: demonstration, steps
    ``[start, stop)``, primitive label, and place in the demonstration (0 = first)."""

    sample: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    label: np.ndarray
    position: np.ndarray

    def __len__(self) -> int:
        return len(self.sample)


def true_segments(step_segments, step_labels, lengths) -> TrueSegments:
    """The true segments of demonstrations from their ``(N, T)`` step fields (-1 at padding)."""
    seg, lab, L = np.asarray(step_segments), np.asarray(step_labels), np.asarray(lengths, dtype=np.int64)
    if seg.shape != lab.shape or seg.ndim != 2 or L.shape != (len(seg),):
        raise UserError(f"step_segments {seg.shape}, step_labels {lab.shape} and lengths {L.shape} do not match")
    rows = []
    for i in range(len(seg)):
        s = seg[i, : L[i]]
        change = np.flatnonzero((s[1:] != s[:-1]) & (s[1:] >= 0)) + 1
        edges = np.concatenate([[0], change, [int(np.sum(s >= 0))]])
        rows += [(i, a, b, int(lab[i, a]), k) for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])) if b > a]
    cols = np.asarray(rows, dtype=np.int64).reshape(-1, 5).T
    return TrueSegments(*cols)


def segment_features(sequences, segments: TrueSegments, kind: str = "raw", n_steps: int = LABEL_STEPS) -> np.ndarray:
    """``(S, n_steps * J)``: each segment of ``sequences`` (``(L, J)`` arrays) resampled and
    flattened; ``kind="relative"`` subtracts the segment's first step first."""
    if kind not in ("raw", "relative"):
        raise UserError(f"kind must be 'raw' or 'relative', got {kind!r}")
    out = []
    for i, a, b in zip(segments.sample, segments.start, segments.stop):
        x = np.asarray(sequences[i], dtype=np.float64)[a:b]
        out.append((resample_segment(x - x[0] if kind == "relative" else x, n_steps)).ravel())
    return np.asarray(out)


def window_code_features(
    code_sequences, segments: TrueSegments, window: int, n_windows: int | None = None
) -> np.ndarray:
    """The window codes each segment touches (window ``k`` covers steps ``[kW, (k+1)W)``):
    their mean, ``(S, q)``, as primspace labels segments; or, with ``n_windows``, their
    sequence resampled to ``n_windows`` and flattened, ``(S, n_windows * q)`` (the code's
    trajectory through the segment, its order kept)."""
    out = []
    for i, a, b in zip(segments.sample, segments.start, segments.stop):
        z = np.asarray(code_sequences[i], dtype=np.float64)[a // window : (b - 1) // window + 1]
        out.append(z.mean(axis=0) if n_windows is None else resample_segment(z, n_windows).ravel())
    return np.asarray(out)


def _classifiers(random_state: int) -> dict:
    from sklearn.linear_model import LogisticRegression
    from sklearn.neighbors import KNeighborsClassifier
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    return {
        "logistic": make_pipeline(StandardScaler(), LogisticRegression(max_iter=5000, random_state=random_state)),
        "nearest": KNeighborsClassifier(n_neighbors=1),
    }


def _weighted(correct: np.ndarray, weight: np.ndarray, keep: np.ndarray) -> float | None:
    return float(np.sum(correct[keep] * weight[keep]) / np.sum(weight[keep])) if keep.any() else None


def supervised_bound(
    features, segments: TrueSegments, n_primitives: int, *, folds: int = FOLDS, random_state: int = 0
) -> dict | None:
    """Cross-validated accuracy of classifiers given the labels (module docstring).

    Returns
    -------
    dict or None
        Per classifier (``logistic``, ``nearest``): ``accuracy``, ``first``, ``later`` (per
        step; None where there is no such segment), ``recall`` (per primitive id, per
        segment) and ``confusion`` (``n_primitives`` x ``n_primitives`` segment counts, row
        = true). None when some primitive has fewer than two segments (no stratified split).
    """
    from sklearn.metrics import confusion_matrix
    from sklearn.model_selection import StratifiedKFold, cross_val_predict
    from threadpoolctl import threadpool_limits

    X, y = np.asarray(features, dtype=np.float64), segments.label
    present = np.unique(y)
    k = min(int(folds), int(np.bincount(y)[present].min())) if len(y) else 0
    if k < 2 or len(present) < 2:
        return None
    cv = StratifiedKFold(n_splits=k, shuffle=True, random_state=random_state)
    weight, first = (segments.stop - segments.start).astype(np.float64), segments.position == 0
    out = {}
    for name, model in _classifiers(random_state).items():
        with threadpool_limits(1):  # small problems: BLAS threads only contend
            pred = cross_val_predict(model, X, y, cv=cv)
        correct = (pred == y).astype(np.float64)
        confusion = confusion_matrix(y, pred, labels=np.arange(n_primitives))
        totals = confusion.sum(axis=1)
        out[name] = {
            "accuracy": _weighted(correct, weight, np.ones(len(y), dtype=bool)),
            "first": _weighted(correct, weight, first),
            "later": _weighted(correct, weight, ~first),
            "recall": [float(confusion[j, j] / totals[j]) if totals[j] else None for j in range(n_primitives)],
            "confusion": confusion.tolist(),
        }
    return out


def clustered_bound(
    features, segments: TrueSegments, step_labels, n_primitives: int, random_state: int = 0
) -> float | None:
    """Per-step labelling accuracy when the true segments' ``features`` are clustered without
    labels (:func:`~primspace.segmentation.label_segments`); None if there is nothing to cluster."""
    labels, note = label_segments(np.asarray(features, dtype=np.float64), n_primitives, random_state=random_state)
    if note is not None:
        return None
    truth = np.asarray(step_labels)
    found = np.full(truth.shape, -1)
    for i, a, b, label in zip(segments.sample, segments.start, segments.stop, labels):
        found[i, a:b] = label
    return step_labelling_accuracy(truth, found)
