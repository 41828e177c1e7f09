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
(:mod:`primspace.experiments.figures`). Each set of points goes through the same pipeline
as ``primspace cluster`` (:func:`primspace.cluster.cluster_points`: fit, scores, τ sweep
over the one R² grid, figures drawn from its result).
"""

from __future__ import annotations

import numpy as np

from primspace.experiments import figures
from primspace.experiments.intra import run_intra
from primspace.experiments.runs import focus_runs, initial_codes, load_codes
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import INITIAL_CODES, LEARNED_CODES

__all__ = ["run_clustering", "rescaled_rows", "rescale", "RESCALINGS", "LEARNED_CODES", "INITIAL_CODES"]


def _clustered(X: np.ndarray, labels: np.ndarray, label_names, r2_target: float):
    """The shared pipeline (:func:`primspace.cluster.cluster_points`, as ``primspace cluster``):
    one fit at ``r2_target`` and the sweep over :data:`primspace.cluster.sweep.R2_GRID`, on one SVD."""
    from primspace.cluster import LowRankSubspaceClustering, cluster_points

    k = len(np.unique(labels[labels >= 0]))
    estimator = LowRankSubspaceClustering(n_clusters=k, r2_target=r2_target, random_state=0)
    return cluster_points(X, estimator, labels_true=labels, label_names=label_names, sweep_param="r2_target")


def _figure(exp: ExperimentDir, name: str, result, title: str) -> None:
    from primspace import plots
    from primspace.cluster import clustering_figure

    plots.save_figure(clustering_figure(result, title=title), exp.figure(name))


def _trajectories(exp: ExperimentDir, name: str, motor, labels, label_names, r2_target: float) -> dict:
    """τ sweep and one clustering at ``r2_target`` of raw trajectories."""
    from primspace import plots
    from primspace.cluster import sweep_figure
    from primspace.cluster.inputs import trajectory_matrix

    result = _clustered(trajectory_matrix(motor), labels, label_names, r2_target)
    plots.save_figure(
        sweep_figure(result, title=f"{name}: τ sweep of raw trajectories"), exp.figure(f"trajectory_sweep_{name}")
    )
    chosen = result.summary()
    _figure(
        exp,
        f"trajectory_clustering_{name}",
        result,
        f"{name}: raw trajectories, τ = {chosen['tau']:.3g} (R² = {chosen['r2']:.3f})",
    )
    return {
        "n": result.n_samples,
        "dim": result.n_features,
        "k": int(len(np.unique(labels[labels >= 0]))),
        "r2_target": r2_target,
        "chosen": chosen,
        "sweep": result.to_dict()["sweep"],
    }


def _other_seeds(exp: ExperimentDir, intra: dict, q: int, focus_seed: int) -> dict:
    """The learned codes (and P m) of the other seeds at q, clustered as the focus seed's
    (no figures): ``{seed: [row, ...]}``, for the spread over seeds."""
    data = exp.dataset()
    r2 = exp.preset.cluster_r2
    out: dict = {}
    for run in sorted(intra["runs"], key=lambda r: (r["seed"], r["init"])):
        if run["latent_dim"] != q or run["seed"] == focus_seed:
            continue
        z, _ = load_codes(exp, run["init"], q, run["seed"])
        row = _clustered(z.astype(np.float64), data.labels, data.label_names, r2).summary()
        rows = out.setdefault(str(run["seed"]), [])
        rows.append({"init": run["init"], "codes": LEARNED_CODES} | row)
        if run["init"] == "projection":
            z0 = initial_codes(exp, "projection", q, run["seed"])
            rows.append(
                {"init": "projection", "codes": INITIAL_CODES}
                | _clustered(z0, data.labels, data.label_names, r2).summary()
            )
    return out


#: How :func:`rescaled_rows` puts every run's codes on one scale before clustering them again:
#: the codes centred and divided by their root mean square distance to the mean (one factor per
#: run), or standardised per dimension (one factor per dimension).
RESCALINGS = ("common scale", "standardised per dimension")


def rescale(z: np.ndarray, how: str) -> np.ndarray:
    """Codes ``z`` (N, q) on one scale (:data:`RESCALINGS`)."""
    centred = z - z.mean(axis=0)
    if how == RESCALINGS[0]:
        return centred / max(float(np.sqrt((centred**2).sum(axis=1).mean())), 1e-300)
    return centred / np.maximum(centred.std(axis=0), 1e-300)


def rescaled_rows(exp: ExperimentDir, intra: dict, q: int) -> list[dict]:
    """Every seed's learned codes at ``q`` clustered again after each of :data:`RESCALINGS`
    (issue 42: do zero- and projection-initialised codes cluster differently because of their
    scale?), each row with the codes' RMS size before rescaling."""
    data = exp.dataset()
    rows = []
    for run in sorted(intra["runs"], key=lambda r: (r["seed"], r["init"])):
        if run["latent_dim"] != q:
            continue
        z, _ = load_codes(exp, run["init"], q, run["seed"])
        z = z.astype(np.float64)
        size = float(np.sqrt(((z - z.mean(axis=0)) ** 2).sum(axis=1).mean()))
        for how in RESCALINGS:
            row = _clustered(rescale(z, how), data.labels, data.label_names, exp.preset.cluster_r2).summary()
            rows.append({"init": run["init"], "seed": run["seed"], "rescaling": how, "rms": size} | row)
    return rows


def run_clustering(exp: ExperimentDir) -> dict:
    """Cluster the codes of every init at the preset's q, and the raw trajectories (data, LASA)."""
    from primspace.data import import_lasa

    preset = exp.preset
    intra = exp.read_results("intra") or run_intra(exp)
    data = exp.dataset()
    q, seed, inits = focus_runs(exp, intra)
    results: dict = {
        "latent_dim": q,
        "seed": seed,
        "r2_target": preset.cluster_r2,
        "latent": [],
        "trajectory": {},
        "latent_sweep": {},
    }
    with exp.stage("clustering"):
        for init in inits:
            z, _ = load_codes(exp, init, q, seed)
            result = _clustered(z.astype(np.float64), data.labels, data.label_names, preset.cluster_r2)
            row = result.summary()
            results["latent_sweep"][init] = result.to_dict()["sweep"]
            results["latent"].append({"init": init, "codes": LEARNED_CODES} | row)
            _figure(
                exp,
                f"latent_clustering_{init}",
                result,
                f"learned codes, {init} init, q = {q}: τ = {row['tau']:.3g} for R² = {row['r2']:.4f}",
            )
        if "projection" in inits:  # the projection before any training: P m for every sample
            z0 = initial_codes(exp, "projection", q, seed)
            result = _clustered(z0, data.labels, data.label_names, preset.cluster_r2)
            row = result.summary()
            results["latent"].append({"init": "projection", "codes": INITIAL_CODES} | row)
            results["latent_sweep"]["projection, initial P m"] = result.to_dict()["sweep"]
            _figure(
                exp,
                "latent_clustering_projection_initial",
                result,
                f"initial codes P m (before training), q = {q}: τ = {row['tau']:.3g}",
            )
        results["by_seed"] = _other_seeds(exp, intra, q, seed)
        results["rescaled"] = rescaled_rows(exp, intra, q)
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
