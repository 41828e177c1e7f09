"""Acting from the scene, in open and closed loop (issue 40; docs/act.md): ``experiment act``.

For each seed, the intra experiment's projection fit at the focus q (θ frozen; the split:
its fitted demonstrations and evaluation samples, at most
:data:`~primspace.experiments.prediction.PREDICT_MAX_SAMPLES`, stratified by label). Every
evaluation sample is a scene: its block (position and size), its first joints, its first
camera frame, and its primitive (the label, given).

**Scene only** (the first frame and the first joints; the primitive given): each row's motion
is scored by the MSE of the steps after the first (scaled units) and by the simulator's judge:

* ``scene policy`` (ours, :class:`~primspace.act.scene_policy.ScenePolicy`, the block's
  colour moments to the motion, per primitive) and ``scene policy (code)`` (the same map to
  the run's codes, decoded);
* ``kernel ridge (blob, K-fold)``: the scene policy's kind of map (a Gaussian process's mean)
  from the same features to the motion, its length scale and penalty chosen by K-fold on the
  fitted demonstrations (:class:`~primspace.act.scene_kernel.KernelRidgePeer`);
* ``contextual ProMP (pixels)`` (the issue's peer: ridge from the PCA of the first frame's
  pixels to the ProMP weights of the primitive) and ``contextual ProMP (blob)`` (the same
  with our features: what the features alone buy);
* ``nearest first frame`` (the demonstration of the primitive with the nearest first frame,
  replayed), ``mean motion (labels)``;
* ``reproduction (whole motion)``: the run's codes inferred from the whole motion, decoded
  (the ceiling of anything decoded by this run).

**Closed loop** (:mod:`primspace.act`): the block is moved by a seeded 2-4 cm at 30 % of the
motion (:class:`~primspace.sim.execute.Perturbation`; one draw per sample and seed, the same
for every row) and each planner executes in MuJoCo: ``closed loop`` (the scene policy asked
every :data:`ACT_EVERY` steps with the current frame), ``open loop`` (its first plan replayed),
``ProMP re-conditioned`` (a ProMP of the primitive conditioned on every executed step, every
:data:`ACT_EVERY` steps; it does not see), and ``closed loop (no move)``: the closed loop
without the perturbation.

**What the model contributes.** Every row's entries carry ``model_share``, the share of its motion
that comes through the run's decoder (:func:`primspace.predict.registry.model_share`): 1 for the
rows that decode codes (``scene policy (code)``, ``reproduction``), 0 for the others, the scene
policy's own rows included (its map predicts the motion, not a code).
"""

from __future__ import annotations

import numpy as np

from primspace.act.planners import DEFAULT_EVERY, PLANNERS
from primspace.data import MotionDataset
from primspace.experiments.intra import run_intra
from primspace.experiments.prediction import PREDICT_MAX_SAMPLES, judgeable, predicted_subset, projection_seeds
from primspace.experiments.prediction_table import mean_std_count
from primspace.experiments.runs import focus_runs
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir
from primspace.predict.metrics import finite_mean
from primspace.results.act import ALL, act_table, act_tables
from primspace.results.layout import figures_dir, phase_dir
from primspace.utils.errors import UserError

__all__ = [
    "ACT_EVERY",
    "ACT_VERSION",
    "SCENE_ROWS",
    "KERNEL_RIDGE",
    "LOOP_ROWS",
    "run_act",
    "run_act_point",
    "act_summary",
    "act_tables",
    "act_table",
]

#: Steps between two looks in closed loop (:data:`primspace.act.planners.DEFAULT_EVERY`).
ACT_EVERY = DEFAULT_EVERY
#: Bumped when a grid point's content changes: points of another version are not reused.
ACT_VERSION = 4
POLICY, POLICY_CODE = "scene policy", "scene policy (code)"
KERNEL_RIDGE = "kernel ridge (blob, K-fold)"
PROMP_PIXELS, PROMP_BLOB = "contextual ProMP (pixels)", "contextual ProMP (blob)"
NEAREST, MEAN_MOTION, REPRODUCTION = "nearest first frame", "mean motion (labels)", "reproduction (whole motion)"
#: The scene-only rows, in order.
SCENE_ROWS = (POLICY, POLICY_CODE, KERNEL_RIDGE, PROMP_PIXELS, PROMP_BLOB, NEAREST, MEAN_MOTION, REPRODUCTION)
CLOSED, OPEN, PROMP_LOOP = PLANNERS
CLOSED_STILL = f"{CLOSED} (no move)"
#: The closed-loop rows (the first three with the block moved), in order.
LOOP_ROWS = (CLOSED, OPEN, PROMP_LOOP, CLOSED_STILL)

_NO_FRAMES = "experiment act reads camera frames: its data has none (simulate with images)"


def _first_step(n: int, length: int) -> np.ndarray:
    return np.repeat((np.arange(length) < 1)[None], n, axis=0)


def _scene_rows(fit, fitted: MotionDataset, test: MotionDataset, test_idx: np.ndarray, infer_dir: str, policy):
    """The scene-only rows: {row: motor (n, T, J) physical}, {row: model share} and the kernel ridge's
    chosen settings by primitive; ``policy``: the closed loop's, fitted (its first frame's map is the
    scene-only plan)."""
    from primspace.act.scene_kernel import KernelRidgePeer
    from primspace.act.scene_peers import ContextualProMPPeer, NearestFramePeer
    from primspace.act.scene_policy import ScenePolicy
    from primspace.predict.peers import MeanMotionPeer
    from primspace.predict.registry import built_on_run, model_share
    from primspace.train import load_run, reconstruct

    scaler = fit.scaler
    motor, truth = scaler.transform(fitted.motor), scaler.transform(test.motor)
    args = (motor, fitted.labels, fitted.lengths, fitted.images)
    query = (truth, _first_step(len(test), truth.shape[1]), test.labels, test.lengths, test.images)
    seed = int(fit.train_config.seed)
    predictors = {
        POLICY: policy,
        POLICY_CODE: ScenePolicy(fit, space="code", label_names=fitted.label_names).fit(*args),
        KERNEL_RIDGE: KernelRidgePeer(features="blob", random_state=seed).fit(*args),
        PROMP_PIXELS: ContextualProMPPeer(features="pca").fit(*args),
        PROMP_BLOB: ContextualProMPPeer(features="blob").fit(*args),
        NEAREST: NearestFramePeer().fit(*args),
        MEAN_MOTION: MeanMotionPeer().fit(*args),
    }
    out, shares = {}, {}
    for name, predictor in predictors.items():
        forecast = predictor.forecast(*query)
        out[name] = scaler.inverse_transform(forecast.motor.astype(np.float32))
        shares[name] = model_share(forecast.details, built_on_run(predictor))
    inferred = load_run(infer_dir)
    where = {int(i): k for k, i in enumerate(inferred.indices)}
    out[REPRODUCTION] = reconstruct(inferred, inferred.latents[[where[int(i)] for i in test_idx]], images=False)[0]
    shares[REPRODUCTION] = 1.0  # the run's codes, decoded
    names = fitted.label_names or []
    chosen = {
        (names[k] if k is not None and k < len(names) else str(k)): choice
        for k, choice in predictors[KERNEL_RIDGE].choices_.items()
    }
    return out, shares, chosen


def _per_primitive(test: MotionDataset, success: np.ndarray, mse: np.ndarray | None, share: float) -> dict:
    """{label name or "all": {"n", "success", "mse", "model_share"}} (``share``: the row's model share)."""
    names = np.array([test.label_names[int(label)] for label in test.labels])
    out = {}
    for name in [n for n in test.label_names if n in set(names)] + [ALL]:
        own = np.ones(len(names), bool) if name == ALL else names == name
        entry = {"n": int(own.sum()), "success": float(success[own].mean())}
        if mse is not None:
            entry["mse"] = finite_mean(mse[own])
        out[name] = entry | {"model_share": float(share)}
    return out


def _loop_rows(fit, test: MotionDataset, every: int, seed: int, policy, promp) -> tuple[dict, dict]:
    """{row: success (n,) bool} of the closed-loop rows, and the latencies (ms) of the closed loop's
    plans; ``policy`` and ``promp`` fitted by :func:`primspace.act.command.fit_planners`."""
    from primspace.act import PolicyPlanner, ProMPPlanner, run_episode
    from primspace.act.episode import BlockMove
    from primspace.sim.execute import Executor, Perturbation
    from primspace.sim.scene import Scene

    scaler, length = fit.scaler, test.motor.shape[1]
    perturbation, scene = Perturbation(), Scene()
    success = {row: np.zeros(len(test), bool) for row in LOOP_ROWS}
    latencies = []
    for i in range(len(test)):
        label, (x, y, size) = int(test.labels[i]), test.params[i]
        rng = np.random.default_rng([int(seed), 40, i])
        _, dx, dy = perturbation.draw(rng, x, y, size)
        move = BlockMove(perturbation.step_index(length), dx, dy)
        k = int(policy.primitives_.for_labels(np.array([label]))[0])
        planners = {
            CLOSED: (PolicyPlanner(policy, k, every), move),
            OPEN: (PolicyPlanner(policy, k, None), move),
            PROMP_LOOP: (ProMPPlanner(promp, label, length, every), move),
            CLOSED_STILL: (PolicyPlanner(policy, k, every), None),
        }
        for row, (planner, moved) in planners.items():
            with Executor(label, x, y, size, length, scene=scene) as executor:
                episode = run_episode(planner, executor, test.motor[i, 0], scaler, length, moved)
            success[row][i] = episode.success
            if row == CLOSED:
                latencies.extend(episode.latencies_ms)
    lat = np.asarray(latencies)
    return success, {"median": float(np.median(lat)), "p95": float(np.percentile(lat, 95)), "max": float(lat.max())}


def run_act_point(run_dir, data_path: str, fit_dir: str, infer_dir: str, every: int, max_samples: int | None) -> dict:
    """One seed (the grid point's directory ``run_dir`` unused): the scene-only rows and the
    closed-loop rows on the run's evaluation samples."""
    from primspace.predict.metrics import unobserved_mse
    from primspace.sim.success import evaluate_dataset
    from primspace.train import TrainConfig, configure_process, load_run

    configure_process(TrainConfig(device="cpu", threads=1))
    data = MotionDataset.load(data_path)
    fit, eval_idx = load_run(fit_dir), load_run(infer_dir).indices
    seed = int(fit.train_config.seed)
    test_idx = predicted_subset(eval_idx, data.labels[eval_idx], max_samples, seed)
    fitted, test = data.subset(fit.indices).load_images(), data.subset(test_idx).load_images()
    from primspace.act.command import fit_planners

    policy, promp = fit_planners(fit, fitted, int(every))  # once: the scene-only row and the loops
    rows, shares, chosen = _scene_rows(fit, fitted, test, test_idx, infer_dir, policy)
    truth, first = fit.scaler.transform(test.motor), _first_step(len(test), test.motor.shape[1])
    plain = test.without_images()
    scene = {}
    for name, motor in rows.items():
        success = np.array([r.success for r in evaluate_dataset(plain, motor)], dtype=float)
        mse = unobserved_mse(fit.scaler.transform(motor), truth, first, test.lengths)
        scene[name] = _per_primitive(test, success, mse, shares[name])
    loop, latency = _loop_rows(fit, test, int(every), seed, policy, promp)
    loop_share = {row: 0.0 if row == PROMP_LOOP else policy.model_share() for row in loop}  # ProMP reads no run
    rescued = ~loop[OPEN]  # the episodes the open loop's replay fails under the move
    return {
        "scene": scene,
        "loop": {row: _per_primitive(test, ok.astype(float), None, loop_share[row]) for row, ok in loop.items()},
        "where_open_fails": {
            row: _per_primitive(test.subset(np.flatnonzero(rescued)), ok[rescued].astype(float), None, loop_share[row])
            for row, ok in loop.items()
            if row != OPEN and rescued.any()
        },
        "kernel_ridge_settings": chosen,
        "per_sample": {row: ok.astype(int).tolist() for row, ok in loop.items()},
        "test_indices": [int(i) for i in test_idx],
        "latency_ms": latency,
        "n_fitted": int(len(fit.indices)),
        "n_test": int(len(test_idx)),
        "has_image_head": bool(fit.model_config.has_images),
    }


def _check_fitted_per_primitive(exp: ExperimentDir, data) -> None:
    """One line before any training when a seed's fitted split leaves a primitive fewer than the
    2 demonstrations the scene policy's map per primitive needs."""
    from primspace.experiments.intra import split_indices

    for seed in exp.preset.seeds:
        train, _ = split_indices(data.labels, exp.preset.train_fraction, seed)
        counts = np.bincount(data.labels[train], minlength=len(data.label_names))
        for k in np.flatnonzero(counts[: len(data.label_names)] < 2):
            if np.any(data.labels == k):
                raise UserError(
                    f"experiment act needs at least 2 fitted demonstrations per primitive: "
                    f"{data.label_names[k]} has {counts[k]} in seed {seed}'s fitted split "
                    f"(train fraction {exp.preset.train_fraction:g}); give --train-fraction or more demonstrations"
                )


def run_act(exp: ExperimentDir, every: int = ACT_EVERY) -> dict:
    """The act grid over the intra runs' seeds at the focus q (runs intra first if needed).

    Raises
    ------
    UserError
        When the data has no frames or cannot be judged (one line).
    """
    data = exp.dataset()
    if not data.has_images:
        raise UserError(_NO_FRAMES)
    if not judgeable(data):
        raise UserError("experiment act executes motions in the simulator: its data must be simulated")
    _check_fitted_per_primitive(exp, data)
    intra = exp.read_results("intra") or run_intra(exp)
    q, _, _ = focus_runs(exp, intra)
    seeds = projection_seeds(intra, q)
    if not seeds:
        raise UserError(f"experiment act uses the intra projection runs at q = {q}, and there are none")
    points = [
        GridPoint(
            f"act{ACT_VERSION}/projection-q{q}-s{s}-k{int(every)}",
            (
                str(exp.data_path),
                str(phase_dir(exp.path, "projection", q, s, "fit")),
                str(phase_dir(exp.path, "projection", q, s, "infer")),
                int(every),
                PREDICT_MAX_SAMPLES,
            ),
        )
        for s in seeds
    ]
    with exp.stage("act"):
        grid = exp.grid(run_act_point, points, "act")
    by_seed = {str(s): grid.results[p.key] for s, p in zip(seeds, points) if p.key in grid.results}
    results = {
        "latent_dim": q,
        "every": int(every),
        "perturbation": {"at": 0.3, "distance_m": [0.02, 0.04]},
        "scene_rows": list(SCENE_ROWS),
        "loop_rows": list(LOOP_ROWS),
        "by_seed": by_seed,
        "failures": grid.failures,
        "table": act_summary(by_seed),
    }
    if by_seed:
        _animate(exp, q, seeds[0], int(every))
    exp.write_results("act", results)
    return results


def _animate(exp: ExperimentDir, q: int, seed: int, every: int) -> None:
    """figures/act_push.gif: ``primspace act`` on the first evaluation push of ``seed`` with the block
    moved (the report's animation of a perturbed push); skipped when the data has no push."""
    from primspace.act.command import act, write_animation
    from primspace.train import load_run

    path = figures_dir(exp.path) / "act_push.gif"
    data = exp.dataset()
    names = list(data.label_names or [])
    if path.exists() or "push" not in names:
        return
    fit_dir = phase_dir(exp.path, "projection", q, seed, "fit")
    eval_idx = load_run(phase_dir(exp.path, "projection", q, seed, "infer")).indices
    pushes = [int(i) for i in eval_idx if int(data.labels[i]) == names.index("push")]
    if not pushes:
        return
    outcome = act(fit_dir, "push", f"{exp.data_path}:{pushes[0]}", perturb=True, every=every, seed=seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_animation(path, outcome)


def act_summary(by_seed: dict) -> dict:
    """{"scene" | "loop": {row: {primitive or "all": {metric: [mean, std, seeds]}}}} over seeds,
    and the closed loop's latency."""
    table: dict = {"scene": {}, "loop": {}, "where_open_fails": {}}
    for result in by_seed.values():
        for part in table:
            for row, primitives in result.get(part, {}).items():
                for name, entry in primitives.items():
                    cell = table[part].setdefault(row, {}).setdefault(name, {})
                    for key, value in entry.items():
                        if value is not None:
                            cell.setdefault(key, []).append(value)
    out = {
        part: {
            r: {p: {k: mean_std_count(v) for k, v in c.items()} for p, c in prims.items()} for r, prims in rows.items()
        }
        for part, rows in table.items()
    }
    lat = [r["latency_ms"]["median"] for r in by_seed.values()]
    out["latency_ms"] = mean_std_count(lat) if lat else None
    return out
