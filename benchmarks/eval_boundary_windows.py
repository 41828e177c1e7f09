"""Evaluation: boundary F1 of a finished composite experiment under three matching windows.

The composite experiment scores a found boundary as right within ±W steps of the true one,
which the simulator puts at the first step of the transition before a primitive (counted as
the next primitive). This re-scores, on the stored runs of ``EXP`` (each seed's held-out
demonstrations), primspace's segmentation of the inferred codes and a few peers, within
``±W`` (as scored), ``[−W, L + W]`` (±W around a transition of L = W steps, the
composite-demo's) and ``±2W``, and prints the share of true boundaries whose nearest found
one is W+1 to 2W steps late. Not a test; the numbers are in docs/sequences.md ("What the peers and
the bounds say").

    python benchmarks/eval_boundary_windows.py comp-demo3 [--seeds 0,1,2]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.composite.experiment import segment_codes
from primspace.experiments.composite.peers import held_out_sequences
from primspace.segmentation import boundaries_from_segments, boundary_f1
from primspace.segmentation.peers import PEERS
from primspace.train import load_run

INITS = ("projection", "pca", "zero")
COMPARED = ("pelt-normal-bic", "binseg-rbf-elbow", "dynp-normal-count", "dynp-rbf-count", "hmm-full")


def _late(truth, found, window: int) -> float:
    late = []
    for t, f in zip(truth, found):
        for b in t:
            if len(f):
                d = np.asarray(f) - b
                late.append(window < d[np.argmin(np.abs(d))] <= 2 * window)
    return float(np.mean(late))


def scores(exp: Path, seed: int, window: int = 8, q: int = 8) -> dict:
    data = MotionDataset.load(exp / "data.h5")
    held_idx = load_run(exp / "runs" / "composite" / f"projection-q{q}-s{seed}" / "infer").indices
    held, seqs = held_out_sequences(data, held_idx)
    truth = boundaries_from_segments(held.step_segments, held.lengths)
    found = {
        f"primspace {i}": segment_codes(
            load_run(exp / "runs" / "composite" / f"{i}-q{q}-s{seed}" / "infer").latents, held, window, q
        )[0].boundaries
        for i in INITS
    }
    n = len(data.label_names)
    found |= {p: PEERS[p].run(seqs, n, window, [len(b) for b in truth], seed).boundaries for p in COMPARED}
    half = window // 2  # [−W, 2W] = within 1.5 W of (t + W / 2)
    return {
        k: (
            boundary_f1(truth, f, window)["f1"],
            boundary_f1(truth, [np.asarray(x) - half for x in f], window + half)["f1"],
            boundary_f1(truth, f, 2 * window)["f1"],
            _late(truth, f, window),
        )
        for k, f in found.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("experiment", type=Path)
    parser.add_argument("--seeds", default="0,1,2")
    args = parser.parse_args()
    table: dict = {}
    for seed in (int(s) for s in args.seeds.split(",")):
        for k, v in scores(args.experiment, seed).items():
            table.setdefault(k, []).append(v)
    print("mean ± sample std over seeds (ddof 1)")
    print("| method | F1 within ±W | within [−W, +2W] | within ±2W | nearest found W+1 to 2W steps late |")
    print("|---|---|---|---|---|")
    for k, v in table.items():
        v = np.asarray(v)
        print(f"| {k} | " + " | ".join(f"{m:.2f} ± {s:.2f}" for m, s in zip(v.mean(0), v.std(0, ddof=1))) + " |")


if __name__ == "__main__":
    main()
