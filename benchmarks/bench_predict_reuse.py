"""The predictor chosen once and kept (not a test): the time ``predict`` spends before predicting, on its
first call on a run (the candidates scored by K-fold prediction of the fitted demonstrations, the chosen
one fitted) against a second call on the same run and data (the choice and the chosen predictor's own
settings read from ``RUN/selection/``, the chosen one fitted with them).

A small run is trained here, in a temporary folder: ``--per-primitive`` motions of each of three
primitives (smooth two-parameter families, ``--steps`` steps, 7 joints), ``--epochs`` epochs of a small
decoder. Each call is :func:`primspace.predict.predict` as ``primspace predict`` makes it (``auto``, the
default), split into the time before predicting (the run loaded, the predictor fitted, chosen and the
chosen one fitted) and the prediction itself, for each task: without a primitive and with one. The ratio
is measured in the same process, one after the other; for scale, the time before predicting of the fixed
predictor the default was before (the mixture without a primitive, the prior with one: fitted, its own
choice made on one motion) is measured first. The decoded draws of the prior kept by the first task are
read by the second task's first call. The load average is printed.

Usage::

    python benchmarks/bench_predict_reuse.py [--per-primitive 20] [--steps 61] [--epochs 30] [--observe 0.25] [--json PATH]
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from primspace.data import MotionDataset  # noqa: E402
from primspace.model.decoder import ModelConfig  # noqa: E402
from primspace.predict import PredictRequest, fit_predictor, make_predictor, run_predictor  # noqa: E402
from primspace.train import TrainConfig, fit, load_run  # noqa: E402
from primspace.train.observe import Observation  # noqa: E402
from primspace.utils.files import atomic_write_json  # noqa: E402

NAMES = ["reach", "push", "lift"]


def motions(per: int, steps: int, seed: int, joints: int = 7) -> MotionDataset:
    """Three primitives, each a smooth family of two parameters (a reach to an end posture linear in
    them, plus an oscillation of the primitive whose amplitude grows with the first)."""
    fixed = np.random.default_rng(1234)
    ends, waves, freq = fixed.normal(0, 1, (3, joints, 3)), fixed.normal(0, 0.4, (3, joints)), fixed.uniform(1, 3, 3)
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, steps)
    s = 10 * t**3 - 15 * t**4 + 6 * t**5
    motor, labels = [], []
    for k in range(3):
        xy = rng.uniform(0, 1, (per, 2))
        end = np.c_[xy, np.ones(per)] @ ends[k].T
        osc = np.sin(np.pi * freq[k] * t)[None, :, None] * waves[k][None, None, :] * (0.5 + xy[:, :1, None])
        motor.append(s[None, :, None] * end[:, None, :] + osc)
        labels += [k] * per
    return MotionDataset(np.concatenate(motor).astype(np.float32), labels=np.array(labels), label_names=NAMES)


def one_call(run_dir: Path, data: MotionDataset, observe: float, primitive, init: str = "auto") -> dict:
    """One ``predict`` call's times: before predicting (load, fit, choose, fit the chosen) and predicting;
    ``init``: a predictor named instead (fitted alone, nothing kept)."""
    start = time.perf_counter()
    run = load_run(run_dir)
    request = PredictRequest.of(init=init, primitive=primitive, progress=False)
    predictor = fit_predictor(make_predictor(run, request=request), run)
    rule = Observation.build(observe)
    selection = predictor.select(rule) if init == "auto" else {"chosen": init, "reused": False}
    if init != "auto":
        predictor.forecast(run.scaler.transform(data.motor[:1]), rule, data.labels[:1], data.valid_lengths[:1])
    ready = time.perf_counter()
    forecast = run_predictor(predictor, run, data, rule)
    done = time.perf_counter()
    assert np.isfinite(forecast.motor).all()
    return {
        "before_s": ready - start,
        "predict_s": done - ready,
        "chosen": selection["chosen"],
        "reused": bool(selection.get("reused")),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-primitive", type=int, default=20)
    parser.add_argument("--steps", type=int, default=61)
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--observe", type=float, default=0.25)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp) / "run"
        train = motions(args.per_primitive, args.steps, seed=0)
        train.save(Path(tmp) / "train.h5")
        start = time.perf_counter()
        fit(
            MotionDataset.load(Path(tmp) / "train.h5"),
            run_dir,
            model_config=ModelConfig(latent_dim=6, layer_sizes=(32, 16), taus=(2.0, 8.0), p_hidden=64, motor_hidden=64),
            train_config=TrainConfig(epochs=args.epochs, batch_size=16, threads=1),
            init="projection",
            progress=False,
        )
        print(
            f"trained {len(train)} motions of {args.steps} steps, {args.epochs} epochs: {time.perf_counter() - start:.1f} s"
        )
        data = motions(5, args.steps, seed=100)
        for primitive, fixed in ((None, "mixture"), ("push", "prior")):
            alone = one_call(run_dir, data, args.observe, primitive, init=fixed)
            first, second = (one_call(run_dir, data, args.observe, primitive) for _ in range(2))
            assert not first["reused"] and second["reused"] and first["chosen"] == second["chosen"]
            row = {
                "task": "no primitive" if primitive is None else f"primitive {primitive}",
                "chosen": first["chosen"],
                "fixed": fixed,
                "fixed_before_s": alone["before_s"],
                "first_before_s": first["before_s"],
                "second_before_s": second["before_s"],
                "ratio": first["before_s"] / second["before_s"],
                "predict_s": second["predict_s"],
            }
            rows.append(row)
            print(
                f"{row['task']:<17} chosen {row['chosen']:<8} before predicting: first call {row['first_before_s']:6.2f} s, "
                f"second {row['second_before_s']:5.2f} s ({row['ratio']:.0f}x less); predicting {row['predict_s']:.2f} s; "
                f"the earlier fixed default ({fixed}) alone {row['fixed_before_s']:.2f} s"
            )
    if args.json is not None:
        atomic_write_json(args.json, {"observe": args.observe, "per_primitive": args.per_primitive, "rows": rows})


if __name__ == "__main__":
    main()
