"""A tau sweep sharing one SVD: R^2, rank and scores per tau, as the paper chose tau.

Paper, Motion Capture Data: "The choice of tau was made based on coefficient of
determination R^2 ... For 0.85 < R^2 < 0.95 the corresponding values of tau are
0.05 < tau < 0.2." :func:`sweep` prints that table for any grid: the SVD of ``Z~`` is
computed once; each tau costs one spectral step.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from sklearn.utils import check_array

from primspace.cluster.estimator import cluster_at_tau, resolve_tau, small_problem_threads, tau_option_from
from primspace.cluster.lrsc import self_representation_svd
from primspace.cluster.metrics import clustering_scores
from primspace.errors import UserError

__all__ = ["sweep", "DEFAULT_R2_GRID"]

#: The default grid: R^2 targets (scale-free, and how the paper picked tau).
DEFAULT_R2_GRID = (0.5, 0.7, 0.8, 0.85, 0.9, 0.95, 0.99, 0.995, 0.999, 0.9999)


def sweep(
    X,
    n_clusters: int,
    *,
    taus: Sequence[float] | None = None,
    tau_relatives: Sequence[float] | None = None,
    r2_targets: Sequence[float] | None = None,
    labels_true=None,
    affine: bool = True,
    affinity: str = "squared",
    ones_weight: float = 1.0,
    spectral: str = "auto",
    n_init: int = 20,
    random_state=0,
    return_labels: bool = False,
) -> list[dict]:
    """Cluster ``X`` at every tau of a grid, from one SVD.

    Parameters
    ----------
    X : array-like of shape (n_samples, n_features)
        Points as rows.
    n_clusters : int
    taus, tau_relatives, r2_targets : sequence of float, optional
        The grid, as absolute taus, relative taus or R^2 targets (at most one; default
        :data:`DEFAULT_R2_GRID` as R^2 targets). Meanings as in
        :class:`~primspace.cluster.LowRankSubspaceClustering`.
    labels_true : array-like of int, shape (n_samples,), optional
        Scores each row (``-1`` = unknown, not scored).
    affine, affinity, ones_weight, spectral, n_init, random_state
        As in :class:`~primspace.cluster.LowRankSubspaceClustering`. Every row uses the same
        ``random_state``, so a row equals a fit of the estimator at that tau.
    return_labels : bool
        Add each row's predicted labels under ``"labels"``.

    Returns
    -------
    list of dict
        One row per grid value, in grid order: ``grid`` (``"tau"``, ``"tau_relative"`` or
        ``"r2_target"``), ``value``, ``tau``, ``tau_relative``, ``r2``, ``rank``, and with
        labels ``accuracy``, ``nmi``, ``ari``. An R^2 target met with no component kept gives
        ``tau``/``rank`` None and no scores (``note`` says why).
    """
    X = check_array(X, dtype=np.float64, ensure_min_samples=2)
    grids = [(k, g) for k, g in (("tau", taus), ("tau_relative", tau_relatives), ("r2_target", r2_targets)) if g is not None]
    if len(grids) > 1:
        raise UserError(f"give at most one grid; got {', '.join(k for k, _ in grids)}")
    kind, grid = grids[0] if grids else ("r2_target", DEFAULT_R2_GRID)
    grid = [float(v) for v in grid]
    if not grid:
        raise UserError("the tau grid is empty")
    for value in grid:  # validate every value before any work
        tau_option_from(*(value if k == kind else None for k in ("tau", "tau_relative", "r2_target")))
    if not (isinstance(n_clusters, (int, np.integer)) and 1 <= n_clusters <= X.shape[0]):
        raise UserError(f"n_clusters must be an integer in [1, {X.shape[0]}], got {n_clusters}")
    if labels_true is not None:
        labels_true = np.asarray(labels_true)
        if labels_true.shape != (X.shape[0],):
            raise UserError(f"{labels_true.size} true labels for {X.shape[0]} points")
    with small_problem_threads(X.shape[0]):
        return _sweep_rows(
            X, n_clusters, kind, grid, labels_true, affine, affinity, ones_weight, spectral, n_init, random_state, return_labels
        )


def _sweep_rows(X, n_clusters, kind, grid, labels_true, affine, affinity, ones_weight, spectral, n_init, random_state, return_labels):
    svd = self_representation_svd(X, affine=affine, ones_weight=ones_weight)
    del X
    rows = []
    for value in grid:
        row = {"grid": kind, "value": value}
        tau = resolve_tau(svd, kind, value)
        row.update(tau=tau, tau_relative=tau * svd.top_singular_value**2, r2=svd.r2(tau), rank=svd.rank(tau))
        if row["rank"] == 0:
            rows.append({**row, "note": "tau keeps no component of Q*"})
            continue
        result = cluster_at_tau(
            svd, tau, n_clusters=n_clusters, affinity=affinity, spectral=spectral, n_init=n_init, random_state=random_state
        )
        if labels_true is not None:
            scores = clustering_scores(labels_true, result.labels)
            row.update(accuracy=scores["accuracy"], nmi=scores["nmi"], ari=scores["ari"])
        if return_labels:
            row["labels"] = result.labels
        rows.append(row)
    return rows
