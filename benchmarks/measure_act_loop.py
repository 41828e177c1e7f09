"""The closed loop measured fairly on one seed of an act experiment directory: its settings chosen
on the seed's fitted demonstrations (:class:`primspace.act.tuning.LoopTuner`), then the closed
loop, its open loop, ProMP re-conditioned and the seeing contextual ProMP on the first scenes of
the act experiment's stratified evaluation subset, the block moved at 20 % and at 30 %
(:data:`primspace.act.episode.MOVE_AT`), and the closed loop without the move.

A cheaper one-off than ``primspace experiment act`` (which also runs the scene-only rows on 280
scenes per seed); the JSON holds the tuning's record, each row's success per primitive, the
closed loop's plan latency and the seconds spent.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/measure_act_loop.py DIR --seed 0 --per-primitive 10 --json OUT.json

``DIR`` is an experiment directory with the intra projection runs at q = 40 (``paper-p39``).
"""

from __future__ import annotations

import argparse
import json
import time

from primspace.act.episode import MOVE_AT
from primspace.data import MotionDataset
from primspace.experiments.act import loop_successes, per_primitive, tuned_planners
from primspace.experiments.prediction import predicted_subset
from primspace.train import TrainConfig, configure_process, load_run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("directory")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--q", type=int, default=40)
    parser.add_argument("--per-primitive", type=int, default=10, help="evaluation scenes per primitive")
    parser.add_argument("--json", required=True)
    args = parser.parse_args()
    configure_process(TrainConfig(device="cpu", threads=1))
    root, s = args.directory, args.seed
    data = MotionDataset.load(f"{root}/data.h5")
    fit = load_run(f"{root}/runs/intra/projection-q{args.q}-s{s}/fit")
    eval_idx = load_run(f"{root}/runs/intra/projection-q{args.q}-s{s}/infer").indices
    test_idx = predicted_subset(eval_idx, data.labels[eval_idx], args.per_primitive * len(data.label_names), s)
    fitted, test = data.subset(fit.indices).load_images(), data.subset(test_idx).load_images()
    start = time.perf_counter()
    planners, settings, tuning = tuned_planners(fit, fitted, None, s)
    tuned = time.perf_counter()
    loop, latency = loop_successes(fit, test, settings, s, planners, MOVE_AT)
    result = {
        "settings": settings,
        "tuning": tuning.to_dict(),
        "test_indices": [int(i) for i in test_idx],
        "loop": {row: per_primitive(test, ok.astype(float), None, 0.0) for row, ok in loop.items()},
        "latency_ms": latency,
        "seconds": {"tuning": tuned - start, "loop": time.perf_counter() - tuned},
    }
    with open(args.json, "w") as f:
        json.dump(result, f, indent=1)
    for row, entry in result["loop"].items():
        print(row, {k: round(v["success"], 3) for k, v in entry.items()})


if __name__ == "__main__":
    main()
