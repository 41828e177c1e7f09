"""Acting from the scene only (issue 25, item 4; :mod:`primspace.predict.scene`): "see the block,
do a push", success per primitive, on the intra split, over seeds.

For each seed, the intra experiment's projection fit at the focus q (θ frozen) and its
evaluation samples (at most :data:`~primspace.experiments.prediction.PREDICT_MAX_SAMPLES`,
stratified by label: :func:`~primspace.experiments.prediction.predicted_subset`). Each
sample gives only its first camera frame and its first joints, and asks for the cluster
of the fitted codes whose majority label is its own (:func:`primspace.predict.scene.run_scene_point`):
the code is searched inside that cluster's affine subspace, :data:`SCENE_EPOCHS` epochs,
and the decoder's whole motion is the prediction. Beside it, on the same samples:

* ``mean motion (labels)``: the mean motion of the sample's primitive over the fitted
  demonstrations (:class:`primspace.predict.peers.MeanMotionPeer`, given the label), the peer
  that also sees no step of the new motion;
* ``reproduction (whole motion)``: the same run's codes inferred from the whole
  motion (the intra experiment's ``infer`` run), decoded: what the model does when it
  has seen everything, the ceiling of the scene-only code.

Per primitive (label name) and over all: the samples, the MSE of the steps after the
first (scaled units, :func:`primspace.predict.metrics.unobserved_mse`) and, on simulator data,
the success judged by replaying the motion (:func:`primspace.sim.success.evaluate_dataset`).
A sample whose label no cluster holds is not acted (``unassigned``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.utils.errors import UserError
from primspace.experiments.intra import run_intra
from primspace.experiments.prediction import (
    PREDICT_MAX_SAMPLES,
    epochs_tail,
    judgeable,
    predicted_subset,
    projection_seeds,
)
from primspace.experiments.prediction_table import mean_std_count
from primspace.predict.metrics import finite_mean
from primspace.experiments.runs import focus_runs, phase_dir
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir

__all__ = ["SCENE_EPOCHS", "SCENE_METHODS", "run_scene", "run_scene_only_point", "scene_summary"]

#: Optimisation epochs of the subspace coordinates (:func:`primspace.predict.scene.infer_in_subspace`).
#: 100: the code moves inside a subspace of a few directions, fitted to one step and one
#: frame; half of the prediction grid's 200 gradient epochs, which fit a whole prefix.
SCENE_EPOCHS = 100
#: Bumped when a grid point's content changes: points of another version are not reused.
SCENE_VERSION = 1
SCENE = "scene only"
MEAN_MOTION = "mean motion (labels)"
REPRODUCTION = "reproduction (whole motion)"
#: The rows of each primitive, in order.
SCENE_METHODS = (SCENE, MEAN_MOTION, REPRODUCTION)
#: The key of the row over all primitives.
ALL = "all"

_NO_FRAMES = "experiment scene needs runs with an image head (an experiment without --no-images, on data with frames)"


def _first_step(data: MotionDataset) -> np.ndarray:
    """(n, T) bool: what the scene mode observes of the joints, the first step."""
    from primspace.train.observe import FIRST, Observation, observation_masks

    return observation_masks(Observation.build(1, FIRST), data)[0]


def _per_primitive(
    test: MotionDataset, scaled: np.ndarray, truth: np.ndarray, acted: np.ndarray, motor: np.ndarray | None
) -> dict:
    """{label name or "all": {"n", "mse", "success" (when ``motor`` is given: judged)}} of the
    ``acted`` samples; ``scaled`` / ``truth`` in scaled units, ``motor`` physical."""
    from primspace.predict.metrics import unobserved_mse

    rows = np.flatnonzero(acted)
    if not rows.size:
        return {}
    sub = test.subset(rows)
    mse = unobserved_mse(scaled[rows], truth[rows], _first_step(sub), sub.lengths)
    success = None
    if motor is not None:
        from primspace.sim.success import evaluate_dataset

        success = np.array([r.success for r in evaluate_dataset(sub, motor[rows])], dtype=float)
    names = np.array([test.label_names[int(label)] for label in sub.labels])
    out = {}
    for name in [n for n in test.label_names if n in set(names)] + [ALL]:
        own = np.ones(len(rows), bool) if name == ALL else names == name
        entry = {"n": int(own.sum()), "mse": finite_mean(mse[own])}
        if success is not None:
            entry["success"] = float(success[own].mean())
        out[name] = entry
    return out


def _reproduction(infer_dir: str, test_idx: np.ndarray) -> np.ndarray:
    """The inferred codes of ``test_idx`` (whole motion observed) decoded: motor (n, T, J), physical."""
    from primspace.train import load_run, reconstruct

    inferred = load_run(infer_dir)
    where = {int(i): k for k, i in enumerate(inferred.indices)}
    codes = inferred.latents[[where[int(i)] for i in test_idx]]
    return reconstruct(inferred, codes, images=False)[0]


def run_scene_only_point(
    run_dir: Path,
    data_path: str,
    fit_dir: str,
    infer_dir: str,
    epochs: int,
    judge: bool,
    max_samples: int | None = PREDICT_MAX_SAMPLES,
) -> dict:
    """One seed: the scene-only motions of the run's evaluation samples (at most ``max_samples``),
    the mean motion of each sample's primitive and the reproduction, per primitive."""
    from primspace.predict.peers import MeanMotionPeer
    from primspace.predict.scene import run_scene_point
    from primspace.train import TrainConfig, configure_process, load_run

    configure_process(TrainConfig(device="cpu", threads=1))
    data = MotionDataset.load(data_path)
    fit, eval_idx = load_run(fit_dir), load_run(infer_dir).indices
    labels = None if data.labels is None else data.labels[eval_idx]
    test_idx = predicted_subset(eval_idx, labels, max_samples, fit.train_config.seed)
    fitted, test = data.without_images().subset(fit.indices), data.subset(test_idx).load_images()
    scene = run_scene_point(fit, fitted, test, int(epochs))
    test = test.without_images()
    scaler, acted = fit.scaler, scene["cluster"] >= 0
    truth = scaler.transform(test.motor)
    mean = (
        MeanMotionPeer()
        .fit(scaler.transform(fitted.motor), fitted.labels, fitted.lengths)
        .predict(truth, _first_step(test), test.labels, test.lengths)
    )
    reproduced = _reproduction(infer_dir, test_idx)
    predictions = {
        SCENE: (scene["scaled"], scene["motor"], acted),
        MEAN_MOTION: (mean, scaler.inverse_transform(mean).astype(np.float32), np.ones(len(test), bool)),
        REPRODUCTION: (scaler.transform(reproduced), reproduced, np.ones(len(test), bool)),
    }
    methods = {
        name: _per_primitive(test, scaled, truth, rows, motor if judge else None)
        for name, (scaled, motor, rows) in predictions.items()
    }
    clusters = dict(scene["clusters"], ranks={str(k): int(v) for k, v in scene["clusters"]["ranks"].items()})
    return {
        "methods": methods,
        "clusters": clusters,
        "unassigned": int((~acted).sum()),
        "epochs": int(epochs),
        "n_fitted": int(len(fit.indices)),
        "n_test": int(len(test_idx)),
        "n_eval": int(len(eval_idx)),
    }


def _check_frames(exp: ExperimentDir) -> None:
    """One line, before any training, when the experiment's runs cannot read a first frame."""
    preset = exp.preset
    if not (preset.images and preset.train.vision_weight > 0 and exp.dataset().has_images):
        raise UserError(_NO_FRAMES)


def run_scene(exp: ExperimentDir, epochs: int = SCENE_EPOCHS) -> dict:
    """The scene-only grid over the intra runs' seeds at the focus q (runs intra first if needed).

    Raises
    ------
    UserError
        When the experiment trains no image head or its data has no frames (one line).
    """
    from primspace.train import load_run

    _check_frames(exp)
    intra = exp.read_results("intra") or run_intra(exp)
    q, _, _ = focus_runs(exp, intra)
    seeds = projection_seeds(intra, q)
    if not seeds:
        raise UserError(
            f"experiment scene uses the intra projection runs at q = {q}, and there are none "
            "(an experiment whose --inits include projection)"
        )
    if not load_run(phase_dir(exp.path, "projection", q, seeds[0], "fit")).model_config.has_images:
        raise UserError(_NO_FRAMES)
    judge = judgeable(exp.dataset())
    tail = epochs_tail(epochs, SCENE_EPOCHS)
    points = [
        GridPoint(
            f"scene{SCENE_VERSION}/projection-q{q}-s{s}{tail}",
            (
                str(exp.data_path),
                str(phase_dir(exp.path, "projection", q, s, "fit")),
                str(phase_dir(exp.path, "projection", q, s, "infer")),
                int(epochs),
                judge,
                PREDICT_MAX_SAMPLES,
            ),
        )
        for s in seeds
    ]
    with exp.stage("scene"):
        grid = exp.grid(run_scene_only_point, points, "scene only")
    by_seed = {str(s): grid.results[p.key] for s, p in zip(seeds, points) if p.key in grid.results}
    results = {
        "latent_dim": q,
        "epochs": int(epochs),
        "judged": judge,
        "methods": list(SCENE_METHODS),
        "by_seed": by_seed,
        "failures": grid.failures,
        "table": scene_summary(by_seed),
    }
    exp.write_results("scene", results)
    return results


def scene_summary(by_seed: dict) -> dict:
    """{method: {primitive or "all": {"n", "mse", "success" (judged)}: [mean, std, seeds]}} over seeds."""
    table: dict = {}
    for result in by_seed.values():
        for method, primitives in result["methods"].items():
            for name, entry in primitives.items():
                cell = table.setdefault(method, {}).setdefault(name, {"n": [], "mse": [], "success": []})
                for key in cell:
                    if entry.get(key) is not None:
                        cell[key].append(entry[key])
    return {
        m: {p: {k: mean_std_count(v) for k, v in cell.items() if v} for p, cell in prims.items()}
        for m, prims in table.items()
    }
