"""The cost of attention in the image path: seconds per training epoch with frames, without
keypoints (``--keypoints 0``, today's frames path) and with K keypoints, in the same run.

Fits synthetic data of the demo's shape (T = 61, 9 joints, 48x64 frames; random content:
speed does not depend on it) with the image head, the vision loss on ``--vision-frames``
drawn frames per sequence (the presets' CPU setting, 8; 0: every frame), alternating the
two configurations ``--repeat`` times so that load on the machine affects both alike, and
prints the median seconds per epoch (after a warm-up epoch) and their ratio. The target
(issue 51): at most 1.5x.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/bench_keypoints_epoch.py [--keypoints 8] [--samples 64]
        [--epochs 3] [--repeat 2] [--threads 1] [--vision-frames 8] [--device cpu]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

T, J, H, W = 61, 9, 48, 64


def _epoch_seconds(run) -> float:
    return statistics.median(h["seconds"] for h in run.history if h["epoch"] > 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keypoints", type=int, default=8)
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--epochs", type=int, default=3, help="timed epochs (after one warm-up epoch)")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--vision-frames", type=int, default=8)
    parser.add_argument("--latent-dim", type=int, default=8)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()

    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, configure_process, fit

    rng = np.random.default_rng(0)
    motor = np.sin(np.linspace(0, 3, T)[None, :, None] * rng.uniform(0.5, 2, (args.samples, 1, J)))
    frames = rng.integers(0, 256, (args.samples, T, H, W, 3), dtype=np.uint8)
    data = MotionDataset(motor.astype(np.float32), images=frames)
    tc = TrainConfig(
        epochs=args.epochs + 1,
        batch_size=16,
        threads=args.threads,
        log_initial=False,
        vision_frames=args.vision_frames or None,
        device=args.device,
    )
    configure_process(tc)
    print(
        f"{args.samples} motions, T = {T}, frames {H}x{W}, q = {args.latent_dim}, batch 16, "
        f"vision frames {args.vision_frames or 'all'}, {args.threads} thread(s), {args.device}, "
        f"median of {args.epochs} epochs x {args.repeat} repeats"
    )
    seconds: dict[int, list[float]] = {0: [], args.keypoints: []}
    for _ in range(args.repeat):
        for k in seconds:
            mc = ModelConfig(latent_dim=args.latent_dim, keypoints=k)
            seconds[k].append(_epoch_seconds(fit(data, model_config=mc, train_config=tc, progress=False)))
    base = statistics.median(seconds[0])
    for k, s in seconds.items():
        print(f"keypoints {k:>2}: {statistics.median(s):.3f} s/epoch  ({statistics.median(s) / base:.2f}x)")


if __name__ == "__main__":
    start = time.perf_counter()
    main()
    print(f"({time.perf_counter() - start:.0f} s)")
