"""Affine low-rank subspace clustering (paper, Background: Linear / Affine Subspace Clustering).

Modules
-------
:mod:`~primspace.cluster.lrsc`
    The closed form ``Q* = V P(Lambda) V^T`` from one SVD; R^2 and the choice of tau.
:mod:`~primspace.cluster.spectral`
    The Ng-Jordan-Weiss spectral step, dense or implicit (no n x n matrix).
:mod:`~primspace.cluster.estimator`
    :class:`LowRankSubspaceClustering`, the scikit-learn estimator.
:mod:`~primspace.cluster.auto`
    Choosing tau without labels (``r2_target="auto"``): the relative eigengap, the eigengap
    or the label stability of each R^2 target of the grid, on one SVD.
:mod:`~primspace.cluster.select`
    Choosing tau by held-out evidence (``r2_target="select"``, the default): the fixed
    targets and the label-free choice compared by their stability across independent halves.
:mod:`~primspace.cluster.sweep`
    R^2, rank and scores over a tau grid: clones of the estimator sharing one SVD; the one
    R^2 grid, :data:`R2_GRID`.
:mod:`~primspace.cluster.pipeline`
    Fit, score, sweep and figure data in one call (:func:`cluster_points`), shared by
    ``primspace cluster`` and the clustering experiment; figures from its result.
:mod:`~primspace.cluster.metrics`
    Accuracy (Hungarian matching), NMI, ARI.
:mod:`~primspace.cluster.inputs`, :mod:`~primspace.cluster.outputs`
    The command's input files and output directory.
"""

from primspace.cluster.auto import AUTO_CRITERIA, AutoTauChoice, choose_tau
from primspace.cluster.estimator import DEFAULT_R2_TARGET, DEFAULT_TAU_CHOICE, LowRankSubspaceClustering
from primspace.cluster.lrsc import (
    SelfRepresentationSVD,
    r2_from_singular_values,
    self_representation_svd,
    shrinkage,
    tau_for_r2,
)
from primspace.cluster.metrics import clustering_accuracy, clustering_scores
from primspace.cluster.pipeline import (
    ClusteringResult,
    cluster_points,
    clustering_figure,
    sweep_figure,
)
from primspace.cluster.select import SELECT_FIXED_TARGETS, TauSelection, select_r2_target
from primspace.cluster.spectral import (
    NormalizedAffinityOperator,
    affinity_from_factor,
    degrees_from_factor,
    njw_labels,
    spectral_embedding,
)
from primspace.cluster.sweep import DEFAULT_R2_GRID, R2_GRID, sweep, tau_sweep

__all__ = [
    "LowRankSubspaceClustering",
    "DEFAULT_R2_TARGET",
    "DEFAULT_TAU_CHOICE",
    "SELECT_FIXED_TARGETS",
    "TauSelection",
    "select_r2_target",
    "AUTO_CRITERIA",
    "AutoTauChoice",
    "choose_tau",
    "SelfRepresentationSVD",
    "self_representation_svd",
    "shrinkage",
    "r2_from_singular_values",
    "tau_for_r2",
    "NormalizedAffinityOperator",
    "affinity_from_factor",
    "degrees_from_factor",
    "spectral_embedding",
    "njw_labels",
    "clustering_accuracy",
    "clustering_scores",
    "sweep",
    "tau_sweep",
    "R2_GRID",
    "DEFAULT_R2_GRID",
    "cluster_points",
    "ClusteringResult",
    "clustering_figure",
    "sweep_figure",
]
