"""Boundaries by synthesis on long demonstrations, scored on the composite experiment's splits.

For each seed s: the held-out demonstrations of ``experiment composite``'s split s
(``split_sequences(N, train_fraction, s)``) are segmented by a single-primitive run (one
code per demonstration, trained on single primitives: e.g. the paper or demo preset's
``intra`` fit of seed s) with :func:`primspace.segmentation.synthesis.segment_by_synthesis`,
and scored as the composite experiment scores its methods: boundary precision / recall / F1
within ``--tolerance`` steps and the per-step labelling accuracy (Hungarian), as many
clusters as primitives. Prints a Markdown table (mean ± sample std over seeds, ddof 1, per-seed values) and
writes the numbers as JSON.

    python benchmarks/eval_segment_synthesis.py --data comp-demo/data.h5 \\
        --runs 'paper-seeds/runs/intra/{init}-q40-s{seed}/fit' --inits projection,zero --seeds 0,1,2 --out synth.json
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits

from primspace.data import MotionDataset
from primspace.experiments.composite.experiment import split_sequences
from primspace.segmentation import segmentation_scores
from primspace.segmentation.synthesis import segment_by_synthesis
from primspace.train import load_run
from primspace.utils.files import atomic_write_json
from primspace.utils.stats import sample_std


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="long demonstrations with step fields (a composite data.h5)")
    ap.add_argument("--runs", required=True, help="single-primitive fit runs, a pattern with {init} and {seed}")
    ap.add_argument("--inits", default="projection")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--train-fraction", type=float, default=0.3, help="the composite preset's (demo 0.3)")
    ap.add_argument("--tolerance", type=int, default=8)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    data = MotionDataset.load(args.data)
    k = len(data.label_names)
    rows = {}
    for init in args.inits.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            held = data.subset(split_sequences(len(data), args.train_fraction, seed)[1])
            run = load_run(args.runs.format(init=init, seed=seed))
            start = time.perf_counter()
            with threadpool_limits(1):
                result = segment_by_synthesis(run, held, k)
            scores = segmentation_scores(result, held, args.tolerance)
            scores["seconds"] = time.perf_counter() - start
            rows.setdefault(init, []).append({"seed": seed, **scores})
            b = scores["boundary"]
            print(
                f"{init} seed {seed}: F1 {b['f1']:.3f} (P {b['precision']:.3f}, R {b['recall']:.3f}), "
                f"accuracy {scores['accuracy']:.3f}, {scores['segments_found']} / {scores['segments_true']} segments, "
                f"{scores['seconds']:.1f} s",
                flush=True,
            )
    print(
        "\n| single-primitive run | boundary precision / recall / F1 | step labelling accuracy | per seed (F1 / accuracy) |"
    )
    print("|---|---|---|---|")
    for init, seeds in rows.items():
        f1 = [r["boundary"]["f1"] for r in seeds]
        acc = [r["accuracy"] for r in seeds]
        p = np.mean([r["boundary"]["precision"] for r in seeds])
        rc = np.mean([r["boundary"]["recall"] for r in seeds])
        per = ", ".join(f"{a:.2f} / {b:.2f}" for a, b in zip(f1, acc))
        print(
            f"| {init} | {p:.2f} / {rc:.2f} / {np.mean(f1):.2f} ± {sample_std(f1):.2f} | "
            f"{np.mean(acc):.2f} ± {sample_std(acc):.2f} | {per} |"
        )
    if args.out:
        atomic_write_json(args.out, {"args": vars(args), "rows": rows})


if __name__ == "__main__":
    main()
