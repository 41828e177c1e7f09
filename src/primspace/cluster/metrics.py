"""Clustering scores: accuracy after Hungarian matching, NMI, ARI.

Accuracy is the subspace-clustering literature's figure (e.g. Vidal 2011, Elhamifar & Vidal
2013): the fraction of points whose predicted cluster, mapped one-to-one onto the true labels
by the assignment that maximises the agreement (Hungarian algorithm on the contingency
table, :func:`scipy.optimize.linear_sum_assignment`), equals the true label. With more
predicted clusters than true ones the unmatched clusters count as wrong. NMI (arithmetic
normalisation) and ARI are scikit-learn's.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from sklearn.metrics import adjusted_rand_score, normalized_mutual_info_score
from sklearn.metrics.cluster import contingency_matrix

from primspace.utils.errors import UserError

__all__ = ["clustering_accuracy", "clustering_scores", "UNKNOWN_LABEL"]

UNKNOWN_LABEL = -1


def _pair(labels_true, labels_pred) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(labels_true)
    p = np.asarray(labels_pred)
    if t.ndim != 1 or p.ndim != 1:
        raise UserError(f"labels must be 1-D, got shapes {t.shape} and {p.shape}")
    if t.shape != p.shape:
        raise UserError(f"{t.size} true labels for {p.size} predicted labels")
    if t.size == 0:
        raise UserError("no labels to score")
    return t, p


def clustering_accuracy(labels_true, labels_pred) -> float:
    """Fraction of points correct after the best one-to-one matching of cluster ids.

    Parameters
    ----------
    labels_true, labels_pred : array-like of shape (n,)
        Any hashable ids; the two sets of ids need not agree in value or number.

    Returns
    -------
    float in [0, 1]

    Examples
    --------
    >>> clustering_accuracy([0, 0, 1, 1, 2], [5, 5, 3, 3, 3])
    0.8
    """
    t, p = _pair(labels_true, labels_pred)
    table = contingency_matrix(t, p)
    rows, cols = linear_sum_assignment(table, maximize=True)
    return float(table[rows, cols].sum() / t.size)


def clustering_scores(labels_true, labels_pred, *, unknown=UNKNOWN_LABEL) -> dict:
    """Accuracy, NMI and ARI over the points whose true label is known.

    Parameters
    ----------
    labels_true : array-like of int, shape (n,)
        ``unknown`` (default -1, the data set's "unknown") marks points left out of scoring.
    labels_pred : array-like of shape (n,)
    unknown : int or None
        The true-label value to ignore; None scores every point.

    Returns
    -------
    dict
        ``accuracy``, ``nmi``, ``ari`` (floats, None if no point is scored), ``n_scored``,
        ``n_ignored``.
    """
    t, p = _pair(labels_true, labels_pred)
    known = np.ones(t.shape, dtype=bool) if unknown is None else t != unknown
    n_scored = int(known.sum())
    out = {"accuracy": None, "nmi": None, "ari": None, "n_scored": n_scored, "n_ignored": int(t.size - n_scored)}
    if n_scored:
        t, p = t[known], p[known]
        out["accuracy"] = clustering_accuracy(t, p)
        out["nmi"] = float(normalized_mutual_info_score(t, p))
        out["ari"] = float(adjusted_rand_score(t, p))
    return out
