"""Online inference as predictive coding (not a test): latency per arriving step and the forecast against offline.

On one CPU core (``torch.set_num_threads(1)``), in one process:

1. fit a paper-sized decoder (q = 40, layers 32/12, T = 61, 9 joints, motor only) on
   synthetic primitives: K families of smooth reaches (minimum-jerk to an end posture,
   plus a family-specific oscillation), two parameters each, like the tests' data;
2. offline inference of held-out samples from the first t steps,
   ``infer(observe=t, epochs=--offline-epochs)`` (the run's start and ``latent_lr``; 600
   epochs, the paper's evaluation, by default), at t = 25 % and 50 % of T,
   and its error of the remaining steps (:func:`primspace.predict.metrics.unobserved_mse`, scaled units);
3. online inference (:func:`primspace.predict.online.infer_online`) of the same samples
   from the same start for each k: latency per arriving step (mean, p95, ms; and the
   process CPU time per step, which a busy machine does not inflate) and the error of
   the remaining steps after the same t, as a ratio to the offline one; at the run's
   ``latent_lr`` and at the others of ``--online-lrs``; ``--carried``: also with one Adam
   along the stream (moments carried) instead of a fresh one per step;
4. for each rate, the smallest k whose error is within 10 % of the offline one at both t,
   and its latency;
5. the mixture online (:meth:`primspace.predict.MixturePredictor.predict_online`, no
   gradient): latency per step, and its error as a ratio to its own offline prediction
   from the same prefix (1.0 by construction) and to the gradient inference's;
6. ``--images``: the latency with 48x64 frames and an image head (the vision term on
   the observed frames; a short fit, as only the time is measured), timed on single
   steps at the same t (a whole stream is minutes per k on one core).

Timings are wall-clock and depend on what else the machine runs: the load average is
printed with them.

Usage::

    python benchmarks/bench_online.py [--samples 20] [--iterations 1,2,5,10,20] [--online-lrs run,0.1]
        [--carried] [--images] [--json PATH]
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from primspace.data import MotionDataset
from primspace.model.config import ModelConfig
from primspace.predict.online import OnlineInference, infer_online, offline_errors
from primspace.train import TrainConfig, fit
from primspace.utils.files import atomic_write_json

T, J, Q, H, W = 61, 9, 40, 48, 64
WITHIN = 1.10  # "reaches the offline error within 10 %"


def primitives(n_per: int, *, seed: int, K: int = 3, images: bool = False) -> MotionDataset:
    """K primitive families of smooth joint trajectories of the paper's shape (T x J), each with
    two parameters (x, y): a minimum-jerk reach to an end posture linear in (x, y) plus an
    oscillation whose amplitude grows with x. The families are fixed; ``seed`` draws the (x, y).
    ``images``: a bright square whose position follows the first two joints (H x W)."""
    fixed = np.random.default_rng(1234)
    A, B, w = fixed.normal(0, 1, (K, J, 3)), fixed.normal(0, 0.4, (K, J)), fixed.uniform(1, 3, K)
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)
    s = 10 * t**3 - 15 * t**4 + 6 * t**5
    motor = []
    for k in range(K):
        xy = rng.uniform(0, 1, (n_per, 2))
        end = np.c_[xy, np.ones(n_per)] @ A[k].T
        osc = np.sin(np.pi * w[k] * t)[None, :, None] * B[k][None, None, :] * (0.5 + xy[:, :1, None])
        motor.append(s[None, :, None] * end[:, None, :] + osc)
    motor = np.concatenate(motor).astype(np.float32)
    labels = np.repeat(np.arange(K), n_per)
    frames = None
    if images:
        lo, hi = motor[..., :2].min(), motor[..., :2].max()
        pos = ((motor[..., :2] - lo) / (hi - lo) * [H - 8, W - 8]).astype(int)
        frames = np.zeros((len(motor), T, H, W, 3), dtype=np.uint8)
        for i, step in np.ndindex(len(motor), T):
            r, c = pos[i, step]
            frames[i, step, r : r + 8, c : c + 8] = 255
    return MotionDataset(motor, images=frames, labels=labels)


def _fit(images: bool, args, K: int = 3) -> tuple:
    """The paper-sized decoder fitted on ``args.train_samples`` of ``K`` primitives (the first
    ``args.samples`` of as many held out): ``(run, held, train)``."""
    n_train = args.train_samples if not images else args.image_train_samples
    train = primitives(math.ceil(n_train / K), seed=0, K=K, images=images)
    held = primitives(math.ceil(args.samples / K), seed=100, K=K, images=images).subset(np.arange(args.samples))
    mc = ModelConfig(latent_dim=Q, layer_sizes=(32, 12), image_size=(H, W) if images else None)
    tc = TrainConfig(
        epochs=args.image_fit_epochs if images else args.fit_epochs,
        batch_size=32,
        seed=0,
        vision_frames=8 if images else None,
    )
    t0 = time.perf_counter()
    run = fit(train, model_config=mc, train_config=tc, init="projection", progress=False)
    last = run.history[-1]
    print(
        f"fit: {len(train)} samples, {tc.epochs} epochs, {time.perf_counter() - t0:.1f} s, "
        f"final motor MSE {last['motor']:.2e}" + (f", vision {last['vision']:.2e}" if images else "")
    )
    return run, held, train


def mixture_bench(run, held, train, ts, off, figures: dict) -> None:
    """The mixture online (no gradient): latency per step; its error against its own offline
    prediction from the same prefix (equal by construction) and against gradient inference."""
    from primspace.predict import MixturePredictor, fit_predictor, predict

    t0 = time.perf_counter()
    predictor = fit_predictor(MixturePredictor(run, condition=False), run, train)
    for t in range(1, T + 1):
        predictor.online_noise(t)
    prepared = time.perf_counter() - t0
    cpu = time.process_time()
    result = predictor.predict_online(run.scaler.transform(held.motor), held.lengths)
    cpu = (time.process_time() - cpu) / len(result.steps)
    errors = [result.error_at(t) for t in ts]
    own = [
        float(
            np.nanmean(
                predict(
                    run,
                    held,
                    observe=t,
                    init="mixture",
                    fitted_data=train,
                    frames=False,
                    condition=False,
                    continuity=True,
                ).errors["motor_mse"]
            )
        )
        for t in ts
    ]
    row = {
        "latency_mean_ms": 1e3 * result.latency_mean,
        "latency_p95_ms": 1e3 * result.latency_p95,
        "cpu_ms_per_step": 1e3 * cpu,
        "prepare_s": prepared,
        "errors": errors,
        "offline_mixture": own,
        "ratios_to_own_offline": [e / o for e, o in zip(errors, own)],
        "ratios_to_gradient_offline": [e / o for e, o in zip(errors, off["mean_error"])],
    }
    figures["mixture_online"] = row
    print(
        f"\nmixture online (no gradient; sigma² per prefix prepared from the fitted data in {prepared:.1f} s): "
        f"{row['latency_mean_ms']:.2f} ms mean, {row['latency_p95_ms']:.2f} ms p95, {row['cpu_ms_per_step']:.2f} ms CPU "
        "per step; error "
        + ", ".join(
            f"{e:.4f} (x{a:.2f} its offline, x{b:.2f} gradient offline)"
            for e, a, b in zip(errors, row["ratios_to_own_offline"], row["ratios_to_gradient_offline"])
        )
    )


def motor_bench(args, figures: dict) -> None:
    run, held, train = _fit(False, args)
    ts = [math.ceil(f * T) for f in (0.25, 0.5)]
    t0 = time.perf_counter()
    off = offline_errors(run, held, ts, epochs=args.offline_epochs, batch_size=len(held))
    print(
        f"offline: infer(observe=t, {args.offline_epochs} epochs, latent_lr {run.train_config.latent_lr:g}) "
        f"at t = {ts}: remaining-step MSE "
        + ", ".join(f"{e:.4f}" for e in off["mean_error"])
        + f"  ({time.perf_counter() - t0:.1f} s)"
    )
    figures["offline"] = {"steps": ts, "epochs": args.offline_epochs, "mean_error": off["mean_error"].tolist()}
    print(f"\nonline, {len(held)} held-out samples as one batch, load average {os.getloadavg()[0]:.1f}")
    print(
        f"{'latent_lr':>9} {'moments':>8} {'k':>4} {'mean ms':>8} {'p95 ms':>8} {'cpu ms':>7}   "
        + "   ".join(f"err@{t} (x offline)" for t in ts)
    )
    variants = [(lr, False) for lr in args.online_lrs] + ([(None, True)] if args.carried else [])
    rows = []
    for lr, carry in variants:
        for k in args.iterations:
            cpu = time.process_time()
            result = infer_online(run, held, iterations=k, latent_lr=lr, carry_moments=carry)
            cpu = (time.process_time() - cpu) / len(result.steps)  # the whole stream, bookkeeping included
            errors = [result.error_at(t) for t in ts]
            r = {
                "latent_lr": result.latent_lr,
                "moments": "carried" if carry else "fresh",
                "k": k,
                "latency_mean_ms": 1e3 * result.latency_mean,
                "latency_p95_ms": 1e3 * result.latency_p95,
                "cpu_ms_per_step": 1e3 * cpu,
                "errors": errors,
                "ratios": [e / o for e, o in zip(errors, off["mean_error"])],
            }
            rows.append(r)
            print(
                f"{r['latent_lr']:>9g} {r['moments']:>8} {k:>4} {r['latency_mean_ms']:>8.2f} "
                f"{r['latency_p95_ms']:>8.2f} {r['cpu_ms_per_step']:>7.2f}   "
                + "   ".join(f"{e:.4f} ({q:5.2f})" for e, q in zip(errors, r["ratios"]))
            )
    figures["online"] = rows
    mixture_bench(run, held, train, ts, off, figures)
    figures["smallest_k"] = {}
    for lr in sorted({r["latent_lr"] for r in rows if r["moments"] == "fresh"}):
        mine = [r for r in rows if r["moments"] == "fresh" and r["latent_lr"] == lr]
        within = [r for r in mine if max(r["ratios"]) <= WITHIN]
        figures["smallest_k"][str(lr)] = within[0]["k"] if within else None
        if within:
            best = within[0]
            print(
                f"latent_lr {lr:g}: smallest k within 10 % of offline at t = {ts}: k = {best['k']}, latency "
                f"{best['latency_mean_ms']:.1f} ms mean, {best['latency_p95_ms']:.1f} ms p95, "
                f"{best['cpu_ms_per_step']:.1f} ms CPU (target < 20 ms)"
            )
        else:
            near = min(mine, key=lambda r: max(r["ratios"]))
            print(
                f"latent_lr {lr:g}: no k of {args.iterations} within 10 % of offline at t = {ts}; closest k = "
                f"{near['k']} (x{max(near['ratios']):.2f}), latency {near['latency_mean_ms']:.1f} ms mean, "
                f"{near['cpu_ms_per_step']:.1f} ms CPU"
            )


def image_bench(args, figures: dict) -> None:
    print("\n=== with images (48x64 frames, image head)")
    run, held, _ = _fit(True, args)
    ts = [math.ceil(f * T) for f in (0.25, 0.5)]
    print(
        f"single steps at t = {ts} ({len(held)} samples, {args.repeats} repeats each), "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    print(f"{'k':>4} " + " ".join(f"{'ms @' + str(t):>10}" for t in ts))
    rows = []
    for k in args.image_iterations:
        times = []
        for t in ts:
            spent = []
            for _ in range(args.repeats):
                online = OnlineInference(run, held, iterations=k, start_step=t)
                t0 = time.perf_counter()
                online.step()
                spent.append(time.perf_counter() - t0)
            times.append(1e3 * float(np.median(spent)))
        rows.append({"k": k, "steps": ts, "latency_ms": times})
        print(f"{k:>4} " + " ".join(f"{ms:>10.1f}" for ms in times))
    figures["images"] = rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=20, help="held-out samples inferred online (one batch)")
    parser.add_argument("--iterations", default="1,2,5,10,20", help="k values, comma separated")
    parser.add_argument("--train-samples", type=int, default=102)
    parser.add_argument("--fit-epochs", type=int, default=200)
    parser.add_argument("--offline-epochs", type=int, default=600, help="the paper's inference epochs")
    parser.add_argument(
        "--online-lrs",
        default="run,0.1",
        help="online latent learning rates, comma separated ('run': the run's latent_lr)",
    )
    parser.add_argument("--carried", action="store_true", help="also run one Adam along the stream (run's rate)")
    parser.add_argument("--images", action="store_true", help="also time the steps with 48x64 frames")
    parser.add_argument("--image-train-samples", type=int, default=30)
    parser.add_argument("--image-fit-epochs", type=int, default=10)
    parser.add_argument("--image-iterations", default="1,2,5")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()
    args.iterations = [int(k) for k in args.iterations.split(",")]
    args.image_iterations = [int(k) for k in args.image_iterations.split(",")]
    args.online_lrs = [None if v == "run" else float(v) for v in args.online_lrs.split(",")]
    torch.set_num_threads(1)
    threadpool_limits(1)  # numpy's BLAS too (the mixture): one core, and no spinning threads on a busy machine
    figures = {"threads": 1, "T": T, "J": J, "q": Q, "samples": args.samples}
    motor_bench(args, figures)
    if args.images:
        image_bench(args, figures)
    if args.json:
        atomic_write_json(args.json, figures)


if __name__ == "__main__":
    main()
