"""Scene-only success of the scene policy with learned features against the block's colour (issue 52).

A measurement, not a test. For one seed of an act experiment on a simulated preset (its fit
and infer runs; the evaluation scenes chosen as ``experiment act`` chooses them,
``predicted_subset`` of the infer run's samples, 280 at most), fits on the run's fitted
demonstrations and their first frames, predicts each evaluation motion from its first frame,
first joints and primitive, executes it in MuJoCo and judges it, for each of ``--features``:

* ``learned`` / ``blob`` / ``pca``: :class:`~primspace.act.scene_policy.ScenePolicy` reading
  :class:`~primspace.act.frame_features.LearnedKeypoints`, ``ColourBlob`` or ``PixelPCA``;
* ``promp-learned`` (etc.): the contextual ProMP peer on those features.

Prints and writes (``--json``) the success over all scenes and per primitive, and each fit's
wall time; then times ``policy.see`` (one frame's features) and ``policy.replan`` (one
re-plan of a push, continued from 7 executed steps) of each scene policy, 200 calls after 5,
torch and the BLAS at one thread.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/measure_learned_features.py EXPERIMENT_DIR --seed 0 \\
        [--q 40] [--features learned,blob,promp-learned] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np


def _timed(fn, calls: int = 200, warmup: int = 5) -> dict:
    for _ in range(warmup):
        fn()
    spent = []
    for _ in range(calls):
        start = time.perf_counter()
        fn()
        spent.append(time.perf_counter() - start)
    ms = 1e3 * np.array(spent)
    return {"median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("experiment", help="an act experiment folder (data.h5, runs/intra/projection-q*-s*)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--q", type=int, default=40)
    parser.add_argument("--features", default="learned,blob,promp-learned")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    import torch
    from threadpoolctl import threadpool_limits

    from primspace.act.scene_peers import ContextualProMPPeer
    from primspace.act.scene_policy import ScenePolicy
    from primspace.data import MotionDataset
    from primspace.experiments.prediction import PREDICT_MAX_SAMPLES, predicted_subset
    from primspace.sim.success import evaluate_dataset
    from primspace.train import load_run

    torch.set_num_threads(1)
    threadpool_limits(1)
    root = f"{args.experiment}/runs/intra/projection-q{args.q}-s{args.seed}"
    data = MotionDataset.load(f"{args.experiment}/data.h5")
    fit, eval_idx = load_run(f"{root}/fit"), load_run(f"{root}/infer").indices
    test_idx = predicted_subset(eval_idx, data.labels[eval_idx], PREDICT_MAX_SAMPLES, int(fit.train_config.seed))
    fitted, test = data.subset(fit.indices).load_images(), data.subset(test_idx).load_images()
    motor, truth = fit.scaler.transform(fitted.motor), fit.scaler.transform(test.motor)
    fit_args = (motor, fitted.labels, fitted.lengths, fitted.images)
    first = np.repeat((np.arange(truth.shape[1]) < 1)[None], len(test), axis=0)
    names = np.array([test.label_names[int(label)] for label in test.labels])
    out = {"seed": args.seed, "n_fitted": len(fit.indices), "n_test": len(test_idx)}
    for name in args.features.split(","):
        start = time.perf_counter()
        if name.startswith("promp-"):
            predictor = ContextualProMPPeer(features=name[len("promp-") :]).fit(*fit_args)
        else:
            seed = int(fit.train_config.seed)
            predictor = ScenePolicy(features=name, label_names=fitted.label_names, random_state=seed).fit(*fit_args)
        fit_s = time.perf_counter() - start
        forecast = predictor.forecast(truth, first, test.labels, test.lengths, test.images).motor
        plans = fit.scaler.inverse_transform(forecast.astype(np.float32))
        ok = np.array([r.success for r in evaluate_dataset(test.without_images(), plans)], dtype=float)
        row = {"success": float(ok.mean()), "fit_s": fit_s}
        row["by_primitive"] = {n: float(ok[names == n].mean()) for n in test.label_names if (names == n).any()}
        if isinstance(predictor, ScenePolicy):
            k = predictor.primitives_.resolve("push") if "push" in predictor.primitives_.names else 0
            i = int(predictor.primitives_.members(k)[0])
            frame, executed = fitted.images[i, 0], motor[i, :7].astype(np.float64)
            belief = predictor.see(frame[None])[0]
            row["see"] = _timed(lambda: predictor.see(frame[None]))
            row["replan"] = _timed(lambda: predictor.replan(k, belief, executed))
        out[name] = row
        print(name, json.dumps(row), flush=True)
    out["load_average"] = os.getloadavg()[0]
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(out, handle, indent=1)


if __name__ == "__main__":
    main()
