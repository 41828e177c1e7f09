"""The vision loss on K drawn frames: how much faster a training epoch with images runs.

Fits the demo preset's simulated data (126 motions, T = 61, 48x64 frames) with the image
head for a few epochs, once on every frame (the exact loss) and once with
``vision_frames = K`` for each K asked, alternating the runs so that load on the machine
affects both alike, and prints seconds per epoch and the ratio measured in this run.
Also times inference (θ frozen) the same way.

Usage::

    python benchmarks/bench_vision_frames.py [DATA.h5] [--ks 8,16] [--epochs 3] [--threads 2] [--repeat 2]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path


def _epoch_seconds(run) -> float:
    return statistics.median(h["seconds"] for h in run.history if h["epoch"] > 0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", nargs="?")
    parser.add_argument("--ks", default="8,16")
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--latent-dim", type=int, default=40)
    args = parser.parse_args()

    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, configure_process, fit, infer

    ks = [int(k) for k in args.ks.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        path = args.data
        if path is None:
            from primspace.sim.generate import generate_dataset

            path = Path(tmp) / "demo.h5"
            generate_dataset("demo", seed=0, out=path, progress=False, workers=1)
        data = MotionDataset.load(path).load_images()
        print(
            f"{len(data)} motions, T = {data.length}, frames {data.image_size}, q = {args.latent_dim}, "
            f"{args.threads} threads, {args.epochs} epochs per timing, median epoch of {args.repeat} repeats"
        )
        fit_s: dict = {k: [] for k in [None, *ks]}
        infer_s: dict = {k: [] for k in [None, *ks]}
        for _ in range(args.repeat):
            for k in [None, *ks]:
                tc = TrainConfig(
                    epochs=args.epochs,
                    batch_size=16,
                    threads=args.threads,
                    log_initial=False,
                    vision_frames=k,
                    device="cpu",
                )
                configure_process(tc)
                run = fit(data, model_config=ModelConfig(latent_dim=args.latent_dim), train_config=tc, progress=False)
                fit_s[k].append(_epoch_seconds(run))
                inferred = infer(run, data, epochs=args.epochs, batch_size=256, progress=False)
                infer_s[k].append(_epoch_seconds(inferred))
        full_fit, full_infer = statistics.median(fit_s[None]), statistics.median(infer_s[None])
        print(f"{'frames per sequence':>22} {'fit s/epoch':>12} {'speed-up':>9} {'infer s/epoch':>14} {'speed-up':>9}")
        for k in [None, *ks]:
            f, i = statistics.median(fit_s[k]), statistics.median(infer_s[k])
            name = f"all {data.length}" if k is None else f"K = {k}"
            print(f"{name:>22} {f:>12.3f} {full_fit / f:>8.2f}x {i:>14.3f} {full_infer / i:>8.2f}x")


if __name__ == "__main__":
    start = time.perf_counter()
    main()
    print(f"({time.perf_counter() - start:.0f} s)")
