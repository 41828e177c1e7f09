"""A tau sweep built on the estimator: R^2, rank and scores per tau, as the paper chose tau.

Paper, Motion Capture Data: "The choice of tau was made based on coefficient of
determination R^2 ... For 0.85 < R^2 < 0.95 the corresponding values of tau are
0.05 < tau < 0.2." :func:`tau_sweep` prints that table for any grid, the way scikit-learn's
``validation_curve`` varies one parameter: for every grid value it fits
``clone(estimator).set_params(<tau option>=value)``. The fits differ only in tau, so they
share one decomposition (:meth:`LowRankSubspaceClustering.decompose`, passed to each fit as
``svd=``): the SVD of ``Z~`` is computed once; each tau costs one spectral step.
:func:`sweep` is the same with the estimator's settings as keywords.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from sklearn.base import clone
from sklearn.utils import check_array

from primspace.cluster.estimator import LowRankSubspaceClustering, resolve_tau, small_problem_threads, tau_option_from
from primspace.cluster.lrsc import R2_GRID, SelfRepresentationSVD
from primspace.cluster.metrics import clustering_scores
from primspace.utils.errors import UserError

__all__ = ["sweep", "tau_sweep", "R2_GRID", "DEFAULT_R2_GRID", "TAU_PARAMETERS"]


#: Former name of :data:`R2_GRID` (the same tuple).
DEFAULT_R2_GRID = R2_GRID

#: The estimator's three ways of giving tau; a sweep varies one of them.
TAU_PARAMETERS = ("tau", "tau_relative", "r2_target")

_EMPTY_NOTE = "tau keeps no component of Q*"


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

    :func:`tau_sweep` on ``LowRankSubspaceClustering(n_clusters, affine=..., ...)``.

    Parameters
    ----------
    X : array-like of shape (n_samples, n_features)
        Points as rows.
    n_clusters : int
    taus, tau_relatives, r2_targets : sequence of float, optional
        The grid, as absolute taus, relative taus or R^2 targets (at most one; default
        :data:`R2_GRID` as R^2 targets). Meanings as in
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
        As :func:`tau_sweep`.
    """
    X = check_array(X, dtype=np.float64, ensure_min_samples=2)
    grids = [(k, g) for k, g in zip(TAU_PARAMETERS, (taus, tau_relatives, r2_targets)) if g is not None]
    if len(grids) > 1:
        raise UserError(f"give at most one grid; got {', '.join(k for k, _ in grids)}")
    kind, grid = grids[0] if grids else ("r2_target", R2_GRID)
    estimator = LowRankSubspaceClustering(
        n_clusters,
        affine=affine,
        affinity=affinity,
        ones_weight=ones_weight,
        spectral=spectral,
        n_init=n_init,
        random_state=random_state,
    )
    return tau_sweep(
        estimator, X, param_name=kind, param_range=grid, labels_true=labels_true, return_labels=return_labels
    )


def tau_sweep(
    estimator: LowRankSubspaceClustering,
    X,
    *,
    param_name: str = "r2_target",
    param_range: Sequence[float] = R2_GRID,
    labels_true=None,
    return_labels: bool = False,
    svd: SelfRepresentationSVD | None = None,
) -> list[dict]:
    """Fit ``clone(estimator)`` with ``param_name`` set to each value, sharing one SVD.

    As scikit-learn's ``validation_curve`` varies one parameter of a cloned estimator; here
    the parameter is one of the three ways of giving tau, the other two are cleared, and every
    fit gets the decomposition of ``X`` computed once (``fit(X, svd=...)``), so the sweep costs
    one SVD plus one spectral step per value. The estimator's other settings (``n_clusters``,
    ``affine``, ``affinity``, ``random_state`` ...) are kept: a row equals
    ``clone(estimator).set_params(<param_name>=value).fit(X)``. A ``RandomState`` instance is
    shared by the fits in grid order rather than copied for each.

    Parameters
    ----------
    estimator : LowRankSubspaceClustering
        Its settings; it is not fitted (a fitted one is cloned like any other).
    X : array-like of shape (n_samples, n_features)
    param_name : {"tau", "tau_relative", "r2_target"}
    param_range : sequence of float
        The grid, in the meaning of ``param_name`` (default :data:`R2_GRID`).
    labels_true : array-like of int, shape (n_samples,), optional
        Scores each row (``-1`` = unknown, not scored).
    return_labels : bool
        Add each row's predicted labels under ``"labels"``.
    svd : SelfRepresentationSVD, optional
        ``estimator.decompose(X)`` when the caller already has it (one SVD for a fit and a
        sweep of the same points).

    Returns
    -------
    list of dict
        One row per grid value, in grid order: ``grid`` (``param_name``), ``value``, ``tau``,
        ``tau_relative``, ``r2``, ``rank``, and with labels ``accuracy``, ``nmi``, ``ari``. A
        tau that keeps no component of ``Q*`` gives ``rank`` 0, no scores, and a ``note``.
    """
    grid = checked_grid(param_name, param_range)
    X = check_array(X, dtype=np.float64, ensure_min_samples=2)
    n_clusters = estimator.n_clusters
    if not (isinstance(n_clusters, (int, np.integer)) and 1 <= n_clusters <= X.shape[0]):
        raise UserError(f"n_clusters must be an integer in [1, {X.shape[0]}], got {n_clusters}")
    if labels_true is not None:
        labels_true = np.asarray(labels_true)
        if labels_true.shape != (X.shape[0],):
            raise UserError(f"{labels_true.size} true labels for {X.shape[0]} points")
    with small_problem_threads(X.shape[0]):
        if svd is None:
            svd = estimator.decompose(X)
        return [_row(estimator, X, svd, param_name, value, labels_true, return_labels) for value in grid]


def checked_grid(param_name: str, param_range) -> list[float]:
    """The grid as floats, every value validated (before any work is done)."""
    if param_name not in TAU_PARAMETERS:
        raise UserError(f"param_name must be one of {', '.join(TAU_PARAMETERS)}; got {param_name!r}")
    grid = [float(v) for v in param_range]
    if not grid:
        raise UserError("the tau grid is empty")
    for value in grid:
        tau_option_from(*(value if k == param_name else None for k in TAU_PARAMETERS))
    return grid


def _row(estimator, X, svd, param_name, value, labels_true, return_labels) -> dict:
    """One grid value: the clone's fit on the shared SVD, or a note if Q* would be 0."""
    row = {"grid": param_name, "value": value}
    tau = resolve_tau(svd, param_name, value)
    if svd.rank(tau) == 0:  # the estimator refuses Q* = 0; the table records it
        return {
            **row,
            "tau": tau,
            "tau_relative": tau * svd.top_singular_value**2,
            "r2": svd.r2(tau),
            "rank": 0,
            "note": _EMPTY_NOTE,
        }
    model = clone(estimator).set_params(**{k: (value if k == param_name else None) for k in TAU_PARAMETERS})
    if isinstance(estimator.random_state, np.random.RandomState):
        model.set_params(random_state=estimator.random_state)  # one stream through the grid, not a copy per fit
    model.fit(X, svd=svd)
    row.update(tau=model.tau_, tau_relative=model.tau_relative_, r2=model.r2_, rank=model.rank_)
    if labels_true is not None:
        scores = clustering_scores(labels_true, model.labels_)
        row.update(accuracy=scores["accuracy"], nmi=scores["nmi"], ari=scores["ari"])
    if return_labels:
        row["labels"] = model.labels_
    return row
