"""Online prediction under the prior (not a test): latency per arriving step of PriorPredictor online, against offline.

On one CPU core (torch and numpy's BLAS at one thread), in one process:

1. fit the paper-sized decoder of ``bench_online.py`` (q = 40, layers 32/12, T = 61, 9
   joints, motor only) on its synthetic primitives, here 7 families x 49 fitted motions
   (latency does not depend on the quality of the fit, so the fit is short);
2. fit :class:`primspace.predict.prior.PriorPredictor` on the fitted demonstrations (the
   prior's family, 2000 draws per primitive decoded) and time it, then its K-fold choice of
   the noise and temperature for a prefix of t = 25 % of T (timed apart);
3. online (:meth:`~primspace.predict.prior.PriorPredictor.predict_online`, a sequential
   Kalman update per primitive) for ONE held-out motion (the robot's case) and for the
   batch of ``--samples``, with the primitive given (``labels=``) and with the posterior
   over the primitives: latency per arriving step (median, mean, p95 over every step of
   ``--repeats`` streams; and the process CPU time per step);
4. offline, the same predictor's ``forecast`` from the same prefix
   (``Observation.build(t)``): its time (median of ``--repeats``), printed as the ratio
   online step / offline, and its error of the remaining steps, which the online error
   after step t equals (the same maths: the ratio is 1 within float tolerance);
5. the default offline predictor (:func:`primspace.predict.predict`, the mixture) from the
   same prefix: its error, and the prior's online error as a ratio to it.

Timings are wall-clock and depend on what else the machine runs: the load average is printed.

Usage::

    python benchmarks/bench_prior_online.py [--samples 20] [--repeats 3] [--fit-epochs 100] [--json PATH]
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import numpy as np
import torch
from bench_online import J, Q, T, _fit
from threadpoolctl import threadpool_limits

from primspace.predict import fit_predictor, predict, unobserved_mse
from primspace.predict.prior import PriorPredictor
from primspace.train.observe import Observation
from primspace.utils.files import atomic_write_json

K = 7  # the paper's primitives


def _online(predictor, scaled, lengths, labels, t: int, repeats: int) -> dict:
    """Latency per arriving step over ``repeats`` streams, and the error after step ``t``."""
    latency, cpu = [], []
    for _ in range(repeats):
        c0 = time.process_time()
        result = predictor.predict_online(scaled, lengths, labels, prediction_after=t)
        cpu.append((time.process_time() - c0) / len(result.steps))  # the stream, bookkeeping included
        latency.append(result.latency)
    latency = np.concatenate(latency)
    return {
        "step_median_ms": 1e3 * float(np.median(latency)),
        "step_mean_ms": 1e3 * float(np.mean(latency)),
        "step_p95_ms": 1e3 * float(np.percentile(latency, 95)),
        "cpu_ms_per_step": 1e3 * float(np.median(cpu)),
        "error": result.error_at(t),
    }


def _offline(predictor, scaled, lengths, labels, t: int, repeats: int) -> dict:
    """Time (median of ``repeats``) and error of ``forecast`` from the first ``t`` steps."""
    rule = Observation.build(t)
    spent = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        forecast = predictor.forecast(scaled, rule, labels, lengths)
        spent.append(time.perf_counter() - t0)
    observed = rule.masks(lengths, scaled.shape[1])[0]
    errors = unobserved_mse(forecast.motor, scaled, observed, lengths)
    return {"ms": 1e3 * float(np.median(spent)), "error": float(np.nanmean(errors))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=20, help="held-out motions of the batch")
    parser.add_argument("--train-samples", type=int, default=7 * 49, help="fitted motions (7 primitives)")
    parser.add_argument("--fit-epochs", type=int, default=100, help="the decoder's fit (latency does not depend on it)")
    parser.add_argument("--draws", type=int, default=2000, help="codes drawn and decoded per primitive")
    parser.add_argument("--repeats", type=int, default=3, help="streams (and offline forecasts) timed per case")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()
    torch.set_num_threads(1)
    threadpool_limits(1)  # numpy's BLAS too: the filter is numpy
    t = math.ceil(0.25 * T)

    run, held, train = _fit(False, args, K=K)
    t0 = time.perf_counter()
    prior = fit_predictor(PriorPredictor(run, n_samples=args.draws), run, train)
    fit_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    choice = prior.choice(Observation.build(t))  # shared with .asked(...): chosen once
    choose_s = time.perf_counter() - t0
    family = prior.prior_choice_["family"]
    print(
        f"prior: {K} primitives x {len(train) // K} fitted codes, family {family[0]} {family[1]:g}, "
        f"{args.draws} draws per primitive decoded: fit {fit_s:.1f} s; K-fold choice for t = {t}: {choose_s:.1f} s "
        f"(r given {choice['noise_given']:g}, r {choice['noise']:g}, T {choice['temperature']:g})"
    )
    figures = {
        "threads": 1,
        "T": T,
        "J": J,
        "q": Q,
        "primitives": K,
        "fitted": len(train),
        "draws": args.draws,
        "t": t,
        "fit_s": fit_s,
        "choice_s": choose_s,
        "choice": {k: v for k, v in choice.items() if k != "cv"},
    }

    scaled = run.scaler.transform(held.motor).astype(np.float64)
    lengths, labels = held.valid_lengths, held.labels
    t0 = time.perf_counter()
    mixture = predict(run, held, observe=t, fitted_data=train, progress=False).errors["motor_mse"]
    mixture_s = time.perf_counter() - t0
    print(
        f"default offline predictor (mixture) from {t} steps: error {np.nanmean(mixture):.2e} "
        f"({mixture_s:.1f} s, its fit included)"
    )
    figures["mixture"] = {"error": float(np.nanmean(mixture)), "seconds": mixture_s}

    print(f"\none core, {args.repeats} streams of {T} steps per case, load average {os.getloadavg()[0]:.1f}")
    head = (
        f"{'motions':>7} {'primitive':>9} {'med ms':>7} {'mean ms':>7} {'p95 ms':>7} {'cpu ms':>7} "
        f"{'offline ms':>10} {'step/off':>8}  {'err@' + str(t):>9} {'x offline':>9} {'x mixture':>9}"
    )
    print(head)
    rows = []
    for motions in (1, len(held)):
        idx = np.arange(motions)
        for mode, predictor in (("given", prior.asked(given=True)), ("posterior", prior)):
            lab = labels[idx] if mode == "given" else None
            on = _online(predictor, scaled[idx], lengths[idx], lab, t, args.repeats)
            off = _offline(predictor, scaled[idx], lengths[idx], lab, t, max(args.repeats, 5))
            mix = float(np.nanmean(mixture[idx]))
            row = {
                "motions": motions,
                "primitive": mode,
                **on,
                "offline_ms": off["ms"],
                "offline_error": off["error"],
                "step_over_offline": on["step_median_ms"] / off["ms"],
                "error_over_offline": on["error"] / off["error"],
                "mixture_error": mix,
                "error_over_mixture": on["error"] / mix,
            }
            rows.append(row)
            print(
                f"{motions:>7} {mode:>9} {row['step_median_ms']:>7.2f} {row['step_mean_ms']:>7.2f} "
                f"{row['step_p95_ms']:>7.2f} {row['cpu_ms_per_step']:>7.2f} {row['offline_ms']:>10.2f} "
                f"{row['step_over_offline']:>8.2f}  {row['error']:>9.2e} {row['error_over_offline']:>9.6f} "
                f"{row['error_over_mixture']:>9.2f}"
            )
    figures["online"] = rows
    worst = max(r["step_median_ms"] for r in rows if r["motions"] == 1)
    print(f"one motion, worst case: {worst:.2f} ms per arriving step (target <= 20 ms on one core)")
    if args.json:
        atomic_write_json(args.json, figures)


if __name__ == "__main__":
    main()
