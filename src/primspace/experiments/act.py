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

**Closed loop** (:mod:`primspace.act`): the block is moved by a seeded 2-4 cm at each fraction of
the motion of ``move_at`` (:data:`~primspace.act.episode.MOVE_AT`: 20 % and 30 %, declared before
the runs; one draw per sample and seed, the same for every row and fraction) and each planner
executes in MuJoCo: ``closed loop`` (the scene policy asked every ``every`` steps with the current
frame), ``open loop`` (its first plan replayed), ``ProMP re-conditioned`` (a ProMP of the
primitive conditioned on every executed step; it does not see), ``contextual ProMP re-planned
(sees)`` (:class:`~primspace.act.planners.SeeingProMPPlanner`: the contextual ProMP on the
block features, re-planned from each due frame and conditioned on the executed joints), one row
each per fraction (``closed loop, moved at 20 %``), and ``closed loop (no move)``. The closed
loop's settings (threshold, horizon, ``every``, the surprise's floor, ``visible``) are chosen on
the fitted demonstrations only (:class:`~primspace.act.tuning.LoopTuner`, recorded under
``loop_tuning``); the two ProMP planners look as often as the closed loop.

**What the model contributes.** Every row's entries carry ``model_share``, the share of its motion
that comes through the run's decoder (:func:`primspace.predict.registry.model_share`): 1 for the
rows that decode codes (``scene policy (code)``, ``reproduction``), 0 for the others, the scene
policy's own rows included (its map predicts the motion, not a code).
"""

from __future__ import annotations

import numpy as np

from primspace.act.episode import MOVE_AT
from primspace.act.planner import check_every
from primspace.act.planners import DEFAULT_EVERY, PLANNERS, SEEING_PROMP
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
    "MOVE_AT",
    "loop_rows",
    "loop_successes",
    "per_primitive",
    "tuned_planners",
    "check_move_at",
    "run_act",
    "run_act_point",
    "act_summary",
    "act_tables",
    "act_table",
]

#: Steps between two looks in closed loop (:data:`primspace.act.planners.DEFAULT_EVERY`).
ACT_EVERY = DEFAULT_EVERY
#: Bumped when a grid point's content changes: points of another version are not reused.
ACT_VERSION = 5
POLICY, POLICY_CODE = "scene policy", "scene policy (code)"
KERNEL_RIDGE = "kernel ridge (blob, K-fold)"
PROMP_PIXELS, PROMP_BLOB = "contextual ProMP (pixels)", "contextual ProMP (blob)"
NEAREST, MEAN_MOTION, REPRODUCTION = "nearest first frame", "mean motion (labels)", "reproduction (whole motion)"
#: The scene-only rows, in order.
SCENE_ROWS = (POLICY, POLICY_CODE, KERNEL_RIDGE, PROMP_PIXELS, PROMP_BLOB, NEAREST, MEAN_MOTION, REPRODUCTION)
CLOSED, OPEN, PROMP_LOOP = PLANNERS
CLOSED_STILL = f"{CLOSED} (no move)"
#: The planners whose rows are repeated for each fraction of the move.
MOVED_PLANNERS = (CLOSED, OPEN, PROMP_LOOP, SEEING_PROMP)


def moved_row(planner: str, at: float) -> str:
    """The row of ``planner`` with the block moved at fraction ``at``: ``"closed loop, moved at 20 %"``."""
    return f"{planner}, moved at {100 * float(at):g} %"


def loop_rows(move_at=MOVE_AT) -> tuple[str, ...]:
    """The closed-loop rows, in order: every moved planner per fraction, then the closed loop without a move."""
    return tuple(moved_row(p, a) for a in move_at for p in MOVED_PLANNERS) + (CLOSED_STILL,)


#: The closed-loop rows at the declared fractions (:data:`MOVE_AT`).
LOOP_ROWS = loop_rows(MOVE_AT)

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


def per_primitive(test: MotionDataset, success: np.ndarray, mse: np.ndarray | None, share: float) -> dict:
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


def loop_successes(fit, test: MotionDataset, settings: dict, seed: int, planners, move_at) -> tuple[dict, dict]:
    """{row: success (n,) bool} of the closed-loop rows, and the latencies (ms) of the closed loop's
    plans; ``planners``: the tuned policy, the ProMP peer and the contextual ProMP peer, fitted."""
    from primspace.act import PolicyPlanner, ProMPPlanner, run_episode
    from primspace.act.episode import drawn_move
    from primspace.act.planners import SeeingProMPPlanner
    from primspace.sim.execute import Executor
    from primspace.sim.scene import Scene

    policy, promp, seeing = planners
    scaler, length, every = fit.scaler, test.motor.shape[1], int(settings["every"])
    scene = Scene()
    success = {row: np.zeros(len(test), bool) for row in loop_rows(move_at)}
    latencies = []
    for i in range(len(test)):
        label, (x, y, size) = int(test.labels[i]), test.params[i, :3]
        k = int(policy.primitives_.for_labels(np.array([label]))[0])
        runs = {CLOSED_STILL: (PolicyPlanner(policy, k, every), None)}
        for at in move_at:  # the same draw at every fraction: only its step differs
            move = drawn_move(at, np.random.default_rng([int(seed), 40, i]), x, y, size, length)
            runs |= {
                moved_row(CLOSED, at): (PolicyPlanner(policy, k, every), move),
                moved_row(OPEN, at): (PolicyPlanner(policy, k, None), move),
                moved_row(PROMP_LOOP, at): (ProMPPlanner(promp, label, length, every), move),
                moved_row(SEEING_PROMP, at): (SeeingProMPPlanner(seeing, label, length, every, policy.visible), move),
            }
        for row, (planner, moved) in runs.items():
            with Executor(label, x, y, size, length, scene=scene) as executor:
                episode = run_episode(planner, executor, test.motor[i, 0], scaler, length, moved)
            success[row][i] = episode.success
            if isinstance(planner, PolicyPlanner) and planner.every is not None:
                latencies.extend(episode.latencies_ms)
    lat = np.asarray(latencies)
    return success, {"median": float(np.median(lat)), "p95": float(np.percentile(lat, 95)), "max": float(lat.max())}


def tuned_planners(fit, fitted: MotionDataset, every: int | None, seed: int):
    """The closed loop's policy with its settings chosen on ``fitted`` alone (``every`` None:
    :class:`~primspace.act.tuning.LoopTuner`; a number: the grid's centre with that ``every``, no
    tuning), the ProMP peer and the contextual ProMP peer on the block features, and the tuning's
    record (None without tuning)."""
    from primspace.act.scene_peers import ContextualProMPPeer
    from primspace.act.scene_policy import ScenePolicy
    from primspace.act.tuning import LOOP_CENTRE, LoopTuner, configured
    from primspace.predict.peers import ProMPPeer

    def fit_policy(motor, labels, frames, steps):
        policy = ScenePolicy(steps=steps, label_names=fitted.label_names, random_state=seed)
        return policy.fit(motor, labels, None, frames)

    record = None
    if every is None:
        record = LoopTuner(seed=seed).tune(fitted, fit.scaler, fit_policy, indices=fit.indices)
        settings = record.chosen
    else:
        settings = dict(LOOP_CENTRE, every=int(every))
    motor, length = fit.scaler.transform(fitted.motor).astype(np.float64), fitted.motor.shape[1]
    policy = fit_policy(motor, fitted.labels, fitted.images, tuple(range(0, length - 1, int(settings["every"]))))
    policy = configured(policy, settings)
    promp = ProMPPeer().fit(motor, fitted.labels, fitted.lengths)
    seeing = ContextualProMPPeer(features="blob").fit(motor, fitted.labels, fitted.lengths, fitted.images)
    return (policy, promp, seeing), settings, record


def run_act_point(
    run_dir,
    data_path: str,
    fit_dir: str,
    infer_dir: str,
    every: int | None,
    max_samples: int | None,
    move_at=MOVE_AT,
) -> dict:
    """One seed (the grid point's directory ``run_dir`` unused): the scene-only rows and the
    closed-loop rows on the run's evaluation samples; ``every`` None: the closed loop's settings
    tuned on the fitted demonstrations (:func:`tuned_planners`)."""
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

    policy, _ = fit_planners(fit, fitted, DEFAULT_EVERY)  # the scene-only row: the first frame's map
    rows, shares, chosen = _scene_rows(fit, fitted, test, test_idx, infer_dir, policy)
    truth, first = fit.scaler.transform(test.motor), _first_step(len(test), test.motor.shape[1])
    plain = test.without_images()
    scene = {}
    for name, motor in rows.items():
        success = np.array([r.success for r in evaluate_dataset(plain, motor)], dtype=float)
        mse = unobserved_mse(fit.scaler.transform(motor), truth, first, test.lengths)
        scene[name] = per_primitive(test, success, mse, shares[name])
    planners, settings, tuning = tuned_planners(fit, fitted, every, seed)
    move_at = tuple(float(a) for a in move_at)
    loop, latency = loop_successes(fit, test, settings, seed, planners, move_at)
    loop_share = {
        row: planners[0].model_share() if row.startswith(CLOSED) or row.startswith(OPEN) else 0.0 for row in loop
    }
    return {
        "scene": scene,
        "loop": {row: per_primitive(test, ok.astype(float), None, loop_share[row]) for row, ok in loop.items()},
        "where_open_fails": _where_open_fails(test, loop, loop_share, move_at),
        "kernel_ridge_settings": chosen,
        "loop_settings": dict(settings),
        "loop_tuning": None if tuning is None else tuning.to_dict(),
        "move_at": list(move_at),
        "per_sample": {row: ok.astype(int).tolist() for row, ok in loop.items()},
        "test_indices": [int(i) for i in test_idx],
        "latency_ms": latency,
        "n_fitted": int(len(fit.indices)),
        "n_test": int(len(test_idx)),
        "has_image_head": bool(fit.model_config.has_images),
    }


def _where_open_fails(test: MotionDataset, loop: dict, share: dict, move_at) -> dict:
    """Per fraction, the moved rows on the episodes whose open loop's replay fails under that move."""
    out = {}
    for at in move_at:
        rescued = ~loop[moved_row(OPEN, at)]
        if not rescued.any():
            continue
        kept = test.subset(np.flatnonzero(rescued))
        for planner in MOVED_PLANNERS:
            row = moved_row(planner, at)
            if planner != OPEN:
                out[row] = per_primitive(kept, loop[row][rescued].astype(float), None, share[row])
    return out


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


def run_act(exp: ExperimentDir, every: int | None = None, move_at=MOVE_AT) -> dict:
    """The act grid over the intra runs' seeds at the focus q (runs intra first if needed).

    ``every`` None (the default): the closed loop's settings are tuned per seed on its fitted
    demonstrations (:func:`tuned_planners`); a number: the grid's centre with that ``every``.
    ``move_at``: the fractions of the motion at which the block is moved (:data:`MOVE_AT`).

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
    move_at = check_move_at(move_at)
    every = None if every is None else check_every(every)
    how = "tuned" if every is None else f"k{every}"
    moves = "-".join(f"{100 * a:g}" for a in move_at)
    intra = exp.read_results("intra") or run_intra(exp)
    q, _, _ = focus_runs(exp, intra)
    seeds = projection_seeds(intra, q)
    if not seeds:
        raise UserError(f"experiment act uses the intra projection runs at q = {q}, and there are none")
    points = [
        GridPoint(
            f"act{ACT_VERSION}/projection-q{q}-s{s}-{how}-m{moves}",
            (
                str(exp.data_path),
                str(phase_dir(exp.path, "projection", q, s, "fit")),
                str(phase_dir(exp.path, "projection", q, s, "infer")),
                every,
                PREDICT_MAX_SAMPLES,
                move_at,
            ),
        )
        for s in seeds
    ]
    with exp.stage("act"):
        grid = exp.grid(run_act_point, points, "act")
    by_seed = {str(s): grid.results[p.key] for s, p in zip(seeds, points) if p.key in grid.results}
    results = {
        "latent_dim": q,
        "every": "tuned" if every is None else int(every),
        "move_at": list(move_at),
        "perturbation": {"at": list(move_at), "distance_m": [0.02, 0.04]},
        "scene_rows": list(SCENE_ROWS),
        "loop_rows": list(loop_rows(move_at)),
        "by_seed": by_seed,
        "failures": grid.failures,
        "table": act_summary(by_seed),
    }
    if by_seed:
        first = by_seed.get(str(seeds[0])) or next(iter(by_seed.values()))
        _animate(exp, q, seeds[0], int(first.get("loop_settings", {}).get("every", ACT_EVERY)))
    exp.write_results("act", results)
    return results


def check_move_at(move_at) -> tuple[float, ...]:
    """``move_at`` (a sequence or ``"0.2,0.3"``) as distinct fractions in (0, 1), in order; one UserError otherwise."""
    if isinstance(move_at, str):
        parts = [p.strip() for p in move_at.split(",") if p.strip()]
        try:
            move_at = [float(p) for p in parts]
        except ValueError:
            raise UserError(f"--move-at {move_at!r}: give fractions of the motion, e.g. 0.2,0.3") from None
    values = tuple(float(a) for a in move_at)
    if not values or len(set(values)) != len(values) or not all(0.0 < a < 1.0 for a in values):
        raise UserError(f"--move-at must be distinct fractions of the motion between 0 and 1, got {list(values)}")
    return values


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
