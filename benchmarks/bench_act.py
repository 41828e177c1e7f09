"""Closed-loop acting (not a test): the latency of one look / re-plan of ``primspace act``, one core.

On one CPU core (torch and numpy's BLAS at one thread; the renderer, Mesa llvmpipe, at one
thread as :mod:`primspace.sim` sets it), in one process, for a trained run and its data file:

1. fit the planners of ``primspace act`` (:func:`primspace.act.command.fit_planners`: the
   scene policy with maps at steps 0, ``every``, 2 ``every``, ... and the ProMP peer) on the
   run's fitted demonstrations and their camera frames, and a second scene policy in code
   space (``ScenePolicy(run, space="code")``, step 0 only); their fits are timed once;
2. take one fitted demonstration of ``--primitive`` (its block, its joints) as the scene, and
   time each part of a look, ``--calls`` times each after ``--warmup`` untimed calls, with
   ``time.perf_counter``:

   a. the frame's features (``policy.see``: with ``--features blob``, the default, the
      block's colour moments; with ``--features learned``, the keypoints of the encoder
      fitted on the demonstrations' first frames, :class:`~primspace.act.frame_features.LearnedKeypoints`);
   b. the surprise check at step ``every`` with no surprise (``policy.correct`` given the
      features it predicts: it keeps the plan);
   c. a re-plan in motion space (``policy.replan``: the Gaussian process to the whole
      motion, continued from the ``every + 1`` executed steps);
   d. a re-plan in code space (the Gaussian process to the code, the run's decoder to the
      motion, continued the same way);
   e. rendering one camera frame (``Executor.frame()`` after a step: the arm replays the
      demonstration's joints, a frame after each step; the first frame of an executor,
      which makes the OpenGL context, is not timed);
   f. a ProMP re-conditioning on a 30-step prefix (``ProMPPlanner.plan``).

Prints median, 95th percentile and mean per part; a closed-loop look that keeps its plan
costs (e) + (a) + (b), one that re-plans (e) + (a) + (b) + (c). Timings are wall-clock and
depend on what else the machine runs: the load average is printed.

Usage::

    python benchmarks/bench_act.py --run RUN_DIR --data DATA.h5 [--primitive push] [--every 6]
        [--features blob|learned|pca] [--calls 200] [--json PATH]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from primspace.utils.files import atomic_write_json

PREFIX = 30  # the executed steps ProMP is conditioned on


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _timed(fn, calls: int, warmup: int) -> np.ndarray:
    """Seconds of ``calls`` calls of ``fn()`` after ``warmup`` untimed ones."""
    for _ in range(warmup):
        fn()
    spent = np.empty(calls)
    for i in range(calls):
        start = time.perf_counter()
        fn()
        spent[i] = time.perf_counter() - start
    return spent


def _frames_timed(label, params, joints, calls: int) -> np.ndarray:
    """Seconds of ``calls`` ``Executor.frame()`` calls, each after one step of ``joints``
    (physical, (T, J)); a new executor (one scene shared) when the steps run out."""
    from primspace.sim.execute import Executor
    from primspace.sim.scene import Scene

    scene, spent, length = Scene(), [], len(joints)
    while len(spent) < calls:
        with Executor(label, *params, length, scene=scene) as executor:
            executor.step(joints[0])
            executor.frame()  # the OpenGL context is made here: not timed
            for s in range(1, length):
                executor.step(joints[s])
                start = time.perf_counter()
                executor.frame()
                spent.append(time.perf_counter() - start)
    return np.asarray(spent[:calls])


def _row(name: str, spent: np.ndarray) -> dict:
    ms = 1e3 * spent
    return {
        "part": name,
        "calls": int(ms.size),
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "mean_ms": float(ms.mean()),
    }


def _planners(run, fitted, every: int, features: str):
    """``primspace act``'s planners (:func:`~primspace.act.command.fit_planners`); with other
    ``features`` than the blob, the same scene policy reading those."""
    from primspace.act.command import fit_planners
    from primspace.act.scene_policy import ScenePolicy
    from primspace.predict.peers import ProMPPeer

    if features == "blob":
        return fit_planners(run, fitted, every)
    motor = run.scaler.transform(fitted.motor)
    policy = ScenePolicy(
        steps=tuple(range(0, motor.shape[1] - 1, every)),
        features=features,
        label_names=fitted.label_names,
        random_state=int(run.train_config.seed),
    ).fit(motor, fitted.labels, fitted.lengths, fitted.images)
    return policy, ProMPPeer().fit(motor, fitted.labels, fitted.lengths)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, required=True, help="a trained run directory (its fit)")
    parser.add_argument("--data", type=Path, required=True, help="the data file it was fitted on, with frames")
    parser.add_argument("--primitive", default="push", help="the scene's primitive (name or label)")
    parser.add_argument("--every", type=int, default=6, help="re-plan interval of the closed loop (act's default)")
    parser.add_argument("--features", default="blob", help="what the policies read of a frame (blob, learned, pca)")
    parser.add_argument("--calls", type=int, default=200, help="timed calls per part (>= 200 for the p95)")
    parser.add_argument("--warmup", type=int, default=5, help="untimed calls before each part")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()
    torch.set_num_threads(1)
    threadpool_limits(1)

    from primspace.act.planners import ProMPPlanner
    from primspace.act.scene_policy import ScenePolicy
    from primspace.data import MotionDataset
    from primspace.train import load_run
    from primspace.train.starts import fitted_samples
    from primspace.utils.errors import UserError

    try:
        run = load_run(args.run)
        fitted = fitted_samples(run, MotionDataset.load(args.data))
    except UserError as exc:
        sys.exit(f"bench_act: {exc}")
    if not fitted.has_images:
        sys.exit(f"bench_act: the run's fitted data ({args.data}) has no camera frames: the scene policy reads them")
    fitted = fitted.load_images()
    m, length, joints = fitted.motor.shape
    q = int(run.model_config.code_size)

    t0 = time.perf_counter()
    try:
        policy, promp = _planners(run, fitted, args.every, args.features)
    except UserError as exc:
        sys.exit(f"bench_act: {exc}")
    fit_s = time.perf_counter() - t0
    scaled = run.scaler.transform(fitted.motor)
    t0 = time.perf_counter()
    code_policy = ScenePolicy(
        run,
        features=args.features,
        space="code",
        label_names=fitted.label_names,
        random_state=int(run.train_config.seed),
    ).fit(scaled, fitted.labels, fitted.lengths, fitted.images)
    code_fit_s = time.perf_counter() - t0

    k = policy.primitives_.resolve(args.primitive)
    label = int(policy.primitives_.labels[k])
    i = int(policy.primitives_.members(k)[0])
    params = tuple(float(v) for v in fitted.params[i, :3])
    frame = fitted.images[i, 0]
    belief = policy.see(frame[None])[0]
    executed = np.asarray(scaled[i, : args.every + 1], dtype=np.float64)
    expected = policy.expected_[args.every, k](belief)[0]  # what the policy predicts it will see: no surprise
    if policy.correct(k, args.every, belief, expected) is not None:
        sys.exit("bench_act: the predicted features surprised the policy (expected no correction)")
    promp_planner = ProMPPlanner(promp, label, length, args.every)
    prefix = np.asarray(scaled[i, :PREFIX], dtype=np.float64)

    load = os.getloadavg()[0]
    print(
        f"run {args.run}: q = {q}, T = {length}, J = {joints}, {m} fitted demonstrations with frames "
        f"{fitted.image_size}; features {args.features}; planners fitted in {fit_s:.1f} s (closed loop, every {args.every}) "
        f"+ {code_fit_s:.1f} s (code space)"
    )
    print(
        f"scene: fitted sample {i} ({policy.primitives_.names[k]}, block x {params[0]:.3f} y {params[1]:.3f} "
        f"size {params[2]:.4f} m); one core ({_cpu_model()}), {args.calls} calls per part, load average {load:.1f}"
    )
    parts = [
        ("(a) features: policy.see", lambda: policy.see(frame[None])),
        ("(b) surprise check, none: policy.correct", lambda: policy.correct(k, args.every, belief, expected)),
        ("(c) re-plan, motion space: policy.replan", lambda: policy.replan(k, belief, executed)),
        ("(d) re-plan, code space (GP + decoder)", lambda: code_policy.replan(k, belief, executed)),
    ]
    rows = [_row(name, _timed(fn, args.calls, args.warmup)) for name, fn in parts]
    rows.append(
        _row("(e) render: Executor.frame() after a step", _frames_timed(label, params, fitted.motor[i], args.calls))
    )
    rows.append(
        _row(
            f"(f) ProMP re-conditioning, {PREFIX}-step prefix",
            _timed(lambda: promp_planner.plan(PREFIX - 1, frame, prefix), args.calls, args.warmup),
        )
    )
    width = max(len(r["part"]) for r in rows)
    print(f"{'part':<{width}} {'median ms':>10} {'p95 ms':>8} {'mean ms':>8}")
    for r in rows:
        print(f"{r['part']:<{width}} {r['median_ms']:>10.3f} {r['p95_ms']:>8.3f} {r['mean_ms']:>8.3f}")
    by = {r["part"][:3]: r["median_ms"] for r in rows}
    keep = by["(e)"] + by["(a)"] + by["(b)"]
    print(f"a closed-loop look, medians: {keep:.2f} ms keeping the plan, {keep + by['(c)']:.2f} ms re-planning")
    if args.json:
        figures = {
            "setting": {
                "run": str(args.run),
                "data": str(args.data),
                "q": q,
                "T": int(length),
                "J": int(joints),
                "fitted": int(m),
                "image_size": list(fitted.image_size),
                "cpu": _cpu_model(),
                "threads": 1,
                "load_average": load,
                "every": args.every,
                "features": args.features,
                "prefix": PREFIX,
                "scene": {"sample": i, "primitive": policy.primitives_.names[k], "block": list(params)},
                "calls": args.calls,
                "warmup": args.warmup,
            },
            "fit_s": {"planners": fit_s, "code_policy": code_fit_s},
            "parts": rows,
            "look_ms": {"keep": keep, "replan": keep + by["(c)"]},
        }
        atomic_write_json(args.json, figures)


if __name__ == "__main__":
    main()
