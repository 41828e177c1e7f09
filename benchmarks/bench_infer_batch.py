"""Inference batch size: same codes, less time.

With θ frozen every code steps on its own sample's gradient (docs/model.md), so the
batch size of ``infer`` should change the speed only. This fits a small motor-only run,
then infers the same new samples with batch 32 (the fit's) and 256 (the experiments'),
and prints the largest relative difference of the final codes and the speed ratio,
both from this run. (Before 0.2 the codes stepped on the batch-mean gradient: at 300
samples the final codes of batch 32 and 256 differed by 19-24 %.)

Usage::

    python benchmarks/bench_infer_batch.py [DATA.h5] [--n-fit 100] [--n-infer 300] [--epochs 100]

Without DATA the demo preset is simulated into a temporary folder (its 126 motions cap
the sample counts).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", nargs="?")
    parser.add_argument("--n-fit", type=int, default=100)
    parser.add_argument("--n-infer", type=int, default=300)
    parser.add_argument("--epochs", type=int, default=100)
    args = parser.parse_args()

    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, configure_process, fit, infer

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        path = args.data
        if path is None:
            from primspace.sim.generate import generate_dataset

            path = tmp / "demo.h5"
            generate_dataset("demo", seed=0, out=path, progress=False, workers=1)
        data = MotionDataset.load(path).without_images()
        order = np.random.default_rng(0).permutation(len(data))
        n_fit = min(args.n_fit, len(data) // 2)
        fit_idx, new_idx = np.sort(order[:n_fit]), np.sort(order[n_fit : n_fit + args.n_infer])
        tc = TrainConfig(epochs=args.epochs, batch_size=32, threads=1, final_lr_fraction=0.1)
        configure_process(tc)
        fit(
            data,
            tmp / "fit",
            model_config=ModelConfig(latent_dim=20),
            train_config=tc,
            init="projection",
            indices=fit_idx,
            images=False,
            progress=False,
        )
        codes, seconds = {}, {}
        for batch in (32, 256):
            start = time.perf_counter()
            run = infer(
                tmp / "fit",
                data,
                tmp / f"infer-b{batch}",
                epochs=args.epochs,
                indices=new_idx,
                batch_size=batch,
                progress=False,
            )
            seconds[batch] = time.perf_counter() - start
            codes[batch] = run.latents.astype(np.float64)
            moved = np.linalg.norm(run.latents - run.initial_latents, axis=1).mean()
        diff = np.linalg.norm(codes[32] - codes[256], axis=1) / np.linalg.norm(codes[32], axis=1)
        print(
            f"{len(new_idx)} samples, {args.epochs} epochs, q = 20 (fit on {n_fit}); codes moved {moved:.3g} on average"
        )
        print(f"final codes, batch 256 vs 32: max relative difference {diff.max():.2e}, mean {diff.mean():.2e}")
        print(
            f"time: batch 32 {seconds[32]:.1f} s, batch 256 {seconds[256]:.1f} s: {seconds[32] / seconds[256]:.2f}x faster"
        )


if __name__ == "__main__":
    main()
