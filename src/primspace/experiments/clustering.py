"""Subspace clustering of learned codes and of raw trajectories.

Two experiments of the paper:

* *Affine subspace clustering of latent space* (Fig. "Clustering results for latent
  encodings"): the codes of all samples (fitted for the train part, inferred for the eval
  part) at q = 40, clustered by affine low-rank subspace clustering with τ chosen so that
  R² = 0.9999, per initialisation. We also cluster the projection-initialised codes
  *before* any training: the paper's claim that the initial projection "already has some
  properties of fully trained latent representation", measured.
* *Motion capture data* (Fig. "Clustering results for robotic trajectory data"): the raw
  joint trajectories, scaled per joint and flattened, clustered over a τ sweep with the
  R² of each τ, as the paper chose τ; on the experiment's data set and on LASA.

Results go to ``results/clustering.json``; the accuracy-per-R² figure is drawn from them
(:mod:`primspace.experiments.figures`). The affinity and τ-sweep figures are still drawn
here from the fitted estimators (the shared clustering pipeline will take them over).
"""

from __future__ import annotations

import numpy as np

from primspace.experiments import figures
from primspace.experiments.intra import run_intra
from primspace.experiments.results import INITIAL_CODES, LEARNED_CODES
from primspace.experiments.runs import focus_runs, initial_codes, load_codes
from primspace.experiments.workspace import ExperimentDir

__all__ = ["run_clustering", "LEARNED_CODES", "INITIAL_CODES"]

_R2_GRID = (0.5, 0.7, 0.8, 0.85, 0.9, 0.95, 0.99, 0.999, 0.9999)


def _latent_sweep(X: np.ndarray, labels: np.ndarray) -> list[dict]:
    from primspace.cluster import sweep
    from primspace.cluster.outputs import to_jsonable

    k = len(np.unique(labels))
    return to_jsonable(sweep(X, k, r2_targets=_R2_GRID, labels_true=labels, random_state=0))


def _cluster(X: np.ndarray, labels: np.ndarray, r2_target: float) -> tuple[dict, object]:
    from primspace.cluster import LowRankSubspaceClustering, clustering_scores

    k = len(np.unique(labels[labels >= 0]))
    est = LowRankSubspaceClustering(n_clusters=k, r2_target=r2_target, random_state=0).fit(X)
    row = {"tau": float(est.tau_), "r2": float(est.r2_), "rank": int(est.rank_)} | {
        key: float(v) for key, v in clustering_scores(labels, est.labels_).items() if key in ("accuracy", "nmi", "ari")
    }
    return row, est


def _figure(exp: ExperimentDir, name: str, est, labels, label_names, title: str) -> None:
    from primspace import plots
    from primspace.cluster import affinity_from_factor
    from primspace.cluster.outputs import figure_indices

    shown = figure_indices(len(labels))
    w = affinity_from_factor(est.representation_factor_, "squared", rows=shown, cols=shown)
    fig = plots.plot_clustering(w, est.labels_[shown], labels[shown], label_names=label_names, title=title)
    plots.save_figure(fig, exp.figure(name))


def _trajectories(exp: ExperimentDir, name: str, motor, labels, label_names, r2_target: float) -> dict:
    """τ sweep and one clustering at ``r2_target`` of raw trajectories."""
    from primspace import plots
    from primspace.cluster import sweep
    from primspace.cluster.inputs import trajectory_matrix
    from primspace.cluster.outputs import to_jsonable

    X = trajectory_matrix(motor)
    k = len(np.unique(labels))
    rows = sweep(X, k, r2_targets=_R2_GRID, labels_true=labels, random_state=0)
    plots.save_figure(plots.plot_tau_sweep(rows, title=f"{name}: τ sweep of raw trajectories"), exp.figure(f"trajectory_sweep_{name}"))
    chosen, est = _cluster(X, labels, r2_target)
    _figure(exp, f"trajectory_clustering_{name}", est, labels, label_names,
            f"{name}: raw trajectories, τ = {chosen['tau']:.3g} (R² = {chosen['r2']:.3f})")
    return {"n": int(len(X)), "dim": int(X.shape[1]), "k": int(k), "r2_target": r2_target, "chosen": chosen, "sweep": to_jsonable(rows)}


def run_clustering(exp: ExperimentDir) -> dict:
    """Cluster the codes of every init at the preset's q, and the raw trajectories (data, LASA)."""
    from primspace.data import import_lasa

    preset = exp.preset
    intra = exp.read_results("intra") or run_intra(exp)
    data = exp.dataset()
    q, seed, inits = focus_runs(exp, intra)
    results: dict = {"latent_dim": q, "seed": seed, "r2_target": preset.cluster_r2, "latent": [], "trajectory": {}, "latent_sweep": {}}
    with exp.stage("clustering"):
        for init in inits:
            z, _ = load_codes(exp, init, q, seed)
            results["latent_sweep"][init] = _latent_sweep(z.astype(np.float64), data.labels)
            row, est = _cluster(z.astype(np.float64), data.labels, preset.cluster_r2)
            results["latent"].append({"init": init, "codes": LEARNED_CODES} | row)
            _figure(exp, f"latent_clustering_{init}", est, data.labels, data.label_names,
                    f"learned codes, {init} init, q = {q}: τ = {row['tau']:.3g} for R² = {row['r2']:.4f}")
        if "projection" in inits:  # the projection before any training: P m for every sample
            z0 = initial_codes(exp, "projection", q, seed)
            row, est = _cluster(z0, data.labels, preset.cluster_r2)
            results["latent"].append({"init": "projection", "codes": INITIAL_CODES} | row)
            results["latent_sweep"]["projection, initial P m"] = _latent_sweep(z0, data.labels)
            _figure(exp, "latent_clustering_projection_initial", est, data.labels, data.label_names,
                    f"initial codes P m (before training), q = {q}: τ = {row['tau']:.3g}")
        results["trajectory"]["data"] = _trajectories(
            exp, "data", data.motor, data.labels, data.label_names, preset.trajectory_r2
        )
        lasa = import_lasa(length=preset.lasa_length)
        results["trajectory"]["lasa"] = _trajectories(
            exp, "lasa", lasa.motor, lasa.labels, lasa.label_names, preset.trajectory_r2
        )
    exp.write_results("clustering", results)
    figures.draw_latent_accuracy(exp.path)
    return results

