"""One clustering pipeline: fit, score, sweep, and the data the figures need.

``primspace cluster`` and the clustering experiment (paper: *Motion Capture Data*, *Affine
subspace clustering of latent space*) do the same thing to a set of points: fit
:class:`~primspace.cluster.LowRankSubspaceClustering`, score it against the true labels,
optionally sweep tau, and draw the paper's two figures. :func:`cluster_points` computes all
of it and returns a :class:`ClusteringResult`: plain data, JSON-ready through
:meth:`ClusteringResult.to_dict` (plus :meth:`~ClusteringResult.arrays` for the per-sample
arrays), from which :func:`clustering_figure` and :func:`sweep_figure` draw without the
estimator. The fit and the sweep share one SVD (:meth:`LowRankSubspaceClustering.decompose`).

Examples
--------
>>> from primspace.cluster import LowRankSubspaceClustering, cluster_points, clustering_figure
>>> result = cluster_points(X, LowRankSubspaceClustering(3, r2_target=0.99, random_state=0),
...                         labels_true=y, sweep_param="r2_target")       # doctest: +SKIP
>>> result.scores["accuracy"], result.tau, len(result.sweep)              # doctest: +SKIP
>>> clustering_figure(result, title="...")                                # doctest: +SKIP
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import numpy as np
from sklearn.base import clone
from sklearn.utils import check_array

from primspace.cluster.estimator import LowRankSubspaceClustering, tau_option_from
from primspace.cluster.metrics import clustering_scores
from primspace.cluster.outputs import figure_indices
from primspace.cluster.spectral import affinity_from_factor
from primspace.cluster.sweep import R2_GRID, checked_grid, tau_sweep
from primspace.utils.errors import UserError
from primspace.utils.folders import to_jsonable

__all__ = ["ClusteringResult", "cluster_points", "clustering_figure", "sweep_figure", "SINGULAR_VALUES_SHOWN"]

#: How many singular values :meth:`ClusteringResult.to_dict` lists.
SINGULAR_VALUES_SHOWN = 100

_ARRAYS = ("labels", "labels_true", "figure_indices", "figure_factor")
_DTYPES = {
    "labels": np.int64,
    "labels_true": np.int64,
    "figure_indices": np.int64,
    "figure_factor": np.float64,
    "eigenvalues": np.float64,
    "singular_values": np.float64,
}


@dataclass(frozen=True, eq=False)
class ClusteringResult:
    """What :func:`cluster_points` found: settings, tau, R^2, rank, labels, scores, sweep.

    Attributes
    ----------
    n_samples, n_features, n_clusters : int
    affine : bool
    affinity : str
    ones_weight : float
    tau_option : dict
        The tau option the fit was given, ``{"tau" | "tau_relative" | "r2_target": value}``
        (``{"r2_target": "select"}`` when none was: the held-out selection;
        ``{"r2_target": "auto"}`` for the label-free choice).
    tau, tau_relative, r2 : float
        As the estimator's ``tau_``, ``tau_relative_``, ``r2_``.
    rank : int
    spectral_method : str
    eigenvalues, singular_values : ndarray
    n_init : int
    seed : int, None or RandomState
        The estimator's ``random_state`` (:meth:`to_dict` writes a ``RandomState`` as its repr).
    seconds : float
        Wall time of the fit (its SVD included), not of the sweep.
    scores : dict or None
        :func:`~primspace.cluster.clustering_scores` (accuracy, NMI, ARI, ``n_scored``,
        ``n_ignored``), None without true labels.
    sweep : list of dict or None
        :func:`~primspace.cluster.tau_sweep` rows, None if no sweep was asked for.
    labels : ndarray of shape (n_samples,)
        The predicted cluster of each point.
    labels_true : ndarray of shape (n_samples,) or None
    label_names : list of str or None
    figure_indices : ndarray
        The points the clustering figure shows (:func:`~primspace.cluster.outputs.figure_indices`).
    figure_factor : ndarray of shape (len(figure_indices), rank)
        Those rows of ``F`` (``Q* = F F^T``): the figure's affinity is
        ``affinity_from_factor(figure_factor, affinity)`` (:meth:`figure_affinity`).
    auto : dict or None
        With ``r2_target="auto"``: ``criterion``, the chosen ``r2_target``, the candidate
        ``grid`` and the criterion's ``scores`` (:meth:`AutoTauChoice.to_dict
        <primspace.cluster.auto.AutoTauChoice.to_dict>`); else None.
    selection : dict or None
        With ``r2_target="select"``: the candidates, their held-out scores and the chosen
        ``r2_target`` (:meth:`TauSelection.to_dict
        <primspace.cluster.select.TauSelection.to_dict>`, the label-free record in its
        ``auto``); else None.
    """

    n_samples: int
    n_features: int
    n_clusters: int
    affine: bool
    affinity: str
    ones_weight: float
    tau_option: dict
    tau: float
    tau_relative: float
    r2: float
    rank: int
    spectral_method: str
    eigenvalues: np.ndarray
    singular_values: np.ndarray
    n_init: int
    seed: object
    seconds: float
    scores: dict | None
    sweep: list[dict] | None
    labels: np.ndarray = field(repr=False)
    labels_true: np.ndarray | None = field(repr=False)
    label_names: list[str] | None
    figure_indices: np.ndarray = field(repr=False)
    figure_factor: np.ndarray = field(repr=False)
    auto: dict | None = None
    selection: dict | None = None

    def to_dict(self, *, include_arrays: bool = False) -> dict:
        """JSON-ready summary (numpy converted, NaN as None).

        Keys, in order: ``n_samples``, ``n_features``, ``n_clusters``, ``affine``,
        ``affinity``, ``ones_weight``, ``tau_option``, ``tau``, ``tau_relative``, ``r2``,
        ``rank``, ``spectral_method``, ``eigenvalues``, ``singular_values`` (the first
        :data:`SINGULAR_VALUES_SHOWN`), ``n_init``, ``seed``, ``seconds`` (rounded to ms),
        ``scores``, ``sweep`` (rows without labels), and ``auto`` after ``tau_option`` when
        tau was chosen without labels (``selection`` there instead when chosen by held-out
        evidence); with ``include_arrays`` also
        ``label_names`` and :meth:`arrays` as lists, enough for :meth:`from_dict`.
        """
        out = {
            "n_samples": self.n_samples,
            "n_features": self.n_features,
            "n_clusters": self.n_clusters,
            "affine": self.affine,
            "affinity": self.affinity,
            "ones_weight": self.ones_weight,
            "tau_option": self.tau_option,
            **({} if self.auto is None else {"auto": self.auto}),
            **({} if self.selection is None else {"selection": self.selection}),
            "tau": self.tau,
            "tau_relative": self.tau_relative,
            "r2": self.r2,
            "rank": self.rank,
            "spectral_method": self.spectral_method,
            "eigenvalues": self.eigenvalues,
            "singular_values": self.singular_values[:SINGULAR_VALUES_SHOWN],
            "n_init": self.n_init,
            "seed": self.seed if self.seed is None or isinstance(self.seed, (int, np.integer)) else repr(self.seed),
            "seconds": round(self.seconds, 3),
            "scores": self.scores,
            "sweep": None
            if self.sweep is None
            else [{k: v for k, v in r.items() if k != "labels"} for r in self.sweep],
        }
        if include_arrays:
            out["label_names"] = self.label_names
            out.update(self.arrays())
        return to_jsonable(out)

    def summary(self) -> dict:
        """``tau``, ``r2``, ``rank``, ``accuracy``, ``nmi``, ``ari``: one row of a results table
        (the scores None without true labels); ``auto_criterion`` too when tau was chosen
        without labels, ``selected_r2_target`` when by held-out evidence."""
        scores = self.scores or {}
        row = {"tau": self.tau, "r2": self.r2, "rank": self.rank} | {
            k: scores.get(k) for k in ("accuracy", "nmi", "ari")
        }
        if self.selection is not None:
            return row | {"selected_r2_target": self.selection["r2_target"]}
        return row if self.auto is None else row | {"auto_criterion": self.auto["criterion"]}

    def arrays(self) -> dict:
        """The per-sample arrays (for ``np.savez``): labels, labels_true (if any), figure data."""
        return {name: getattr(self, name) for name in _ARRAYS if getattr(self, name) is not None}

    @classmethod
    def from_dict(cls, data: dict, arrays: dict | None = None) -> ClusteringResult:
        """Rebuild from ``to_dict(include_arrays=True)`` (or ``to_dict()`` plus ``arrays()``).

        Singular values beyond :data:`SINGULAR_VALUES_SHOWN` and the seconds' digits beyond
        ms are not in the dict; everything the figures use is.
        """
        data = {**data, **(arrays or {})}
        values = {f.name: data.get(f.name) for f in fields(cls)}
        for name, dtype in _DTYPES.items():
            if values[name] is not None:
                values[name] = np.asarray(values[name], dtype=dtype)
        if values["r2"] is None:  # JSON has no NaN
            values["r2"] = float("nan")
        return cls(**values)

    def figure_affinity(self) -> np.ndarray:
        """The affinity among the figure's points: ``(F_s F_s^T)^2`` or ``|F_s F_s^T|``."""
        return affinity_from_factor(self.figure_factor, self.affinity)


def cluster_points(
    X,
    estimator: LowRankSubspaceClustering,
    *,
    labels_true=None,
    label_names: Sequence[str] | None = None,
    sweep_param: str | None = None,
    sweep_values: Sequence[float] | None = None,
) -> ClusteringResult:
    """Fit a clone of ``estimator`` to ``X``, score it, optionally sweep tau: the pipeline.

    Parameters
    ----------
    X : array-like of shape (n_samples, n_features)
        Points as rows, finite (e.g. :func:`~primspace.cluster.inputs.trajectory_matrix` of
        motions, or latent codes).
    estimator : LowRankSubspaceClustering
        The settings (n_clusters, tau option, affine, affinity, ...); cloned, not modified.
    labels_true : array-like of int, shape (n_samples,), optional
        Scores the fit and every sweep row (``-1`` = unknown, not scored); shown in the figure.
    label_names : sequence of str, optional
        Names of the true labels, for the figure.
    sweep_param : {"tau", "tau_relative", "r2_target"}, optional
        Also sweep this tau option (:func:`~primspace.cluster.tau_sweep`) with the fit's
        other settings, on the fit's SVD. None: no sweep.
    sweep_values : sequence of float, optional
        The sweep's grid; default :data:`~primspace.cluster.R2_GRID` (for ``"r2_target"``;
        the other options need values).

    Returns
    -------
    ClusteringResult

    Raises
    ------
    ValueError
        As :meth:`LowRankSubspaceClustering.fit` and :func:`~primspace.cluster.tau_sweep`.
    """
    if sweep_param is not None and sweep_values is None and sweep_param != "r2_target":
        raise UserError(f"a sweep of {sweep_param} needs sweep_values")
    grid = None if sweep_param is None else checked_grid(sweep_param, R2_GRID if sweep_values is None else sweep_values)
    model = clone(estimator)
    started = time.perf_counter()
    svd = model.decompose(X)  # validates the settings and X first, as fit does
    X = check_array(X, dtype=np.float64, ensure_min_samples=2)
    if labels_true is not None:
        labels_true = np.asarray(labels_true)
        if labels_true.shape != (X.shape[0],):
            raise UserError(f"{labels_true.size} true labels for {X.shape[0]} points")
    model.fit(X, svd=svd)
    seconds = time.perf_counter() - started
    rows = None
    if grid is not None:
        rows = tau_sweep(model, X, param_name=sweep_param, param_range=grid, labels_true=labels_true, svd=svd)
    return _result(model, X.shape, seconds, labels_true, label_names, rows)


def _result(model, shape, seconds, labels_true, label_names, rows) -> ClusteringResult:
    shown = figure_indices(shape[0])
    kind, value = tau_option_from(model.tau, model.tau_relative, model.r2_target)
    return ClusteringResult(
        n_samples=shape[0],
        n_features=shape[1],
        n_clusters=model.n_clusters,
        affine=model.affine,
        affinity=model.affinity,
        ones_weight=model.ones_weight,
        tau_option={kind: value},
        tau=model.tau_,
        tau_relative=model.tau_relative_,
        r2=model.r2_,
        rank=model.rank_,
        spectral_method=model.spectral_method_,
        eigenvalues=model.eigenvalues_,
        singular_values=model.singular_values_,
        n_init=model.n_init,
        seed=model.random_state,
        seconds=seconds,
        scores=None if labels_true is None else clustering_scores(labels_true, model.labels_),
        sweep=rows,
        labels=model.labels_,
        labels_true=labels_true,
        label_names=None if label_names is None else list(label_names),
        figure_indices=shown,
        figure_factor=model.representation_factor_[shown],
        auto=None if model.auto_choice_ is None or model.selection_ is not None else model.auto_choice_.to_dict(),
        selection=None if model.selection_ is None else model.selection_.to_dict(),
    )


def clustering_figure(result: ClusteringResult, *, title: str = ""):
    """The paper's clustering figure of ``result`` (:func:`primspace.plots.plot_clustering`):
    the affinity of the shown points ordered by true label, and their predicted clusters."""
    from primspace.plots import plot_clustering

    shown = result.figure_indices
    return plot_clustering(
        result.figure_affinity(),
        result.labels[shown],
        None if result.labels_true is None else result.labels_true[shown],
        label_names=result.label_names,
        title=title,
    )


def sweep_figure(result: ClusteringResult, *, title: str = ""):
    """Tau against R^2 and the scores over ``result.sweep`` (:func:`primspace.plots.plot_tau_sweep`)."""
    from primspace.plots import plot_tau_sweep

    if result.sweep is None:
        raise ValueError("this result has no sweep: pass sweep_param to cluster_points")
    return plot_tau_sweep(result.sweep, title=title)
