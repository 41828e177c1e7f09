"""Figure: the first frames of eight samples of the ``paper-varied`` preset (docs/data.md).

Eight samples spread over the preset's 1715 (one or two per primitive), generated as
``primspace generate --preset paper-varied --seed 0`` makes them (the same draws: a
sample's scene depends on the seed and its index alone), their first 48 x 64 frames laid
out 2 x 4 and enlarged 3 x (nearest neighbour).

Usage::

    python benchmarks/figure_varied_scenes.py --out docs/figures/varied-scenes.png
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before anything imports mujoco

import numpy as np  # noqa: E402


def first_frames(seed: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The first frames (count, 48, 64, 3) of ``count`` samples spread over ``paper-varied``, and their indices."""
    from primspace.sim.generate import PRESETS, generate_shard

    config = PRESETS["paper-varied"]
    indices = np.linspace(0, config.n_samples - 1, count).round().astype(int)
    frames = [generate_shard(config, seed, [int(i)])["images"][0, 0] for i in indices]
    return np.stack(frames), indices


def grid(frames: np.ndarray, columns: int, scale: int, gap: int = 2) -> np.ndarray:
    """The frames laid out in rows of ``columns``, each enlarged ``scale`` times, on white."""
    n, h, w, _ = frames.shape
    rows = -(-n // columns)
    big = frames.repeat(scale, axis=1).repeat(scale, axis=2)
    out = np.full((rows * (h * scale + gap) - gap, columns * (w * scale + gap) - gap, 3), 255, np.uint8)
    for k, frame in enumerate(big):
        r, c = divmod(k, columns)
        out[r * (h * scale + gap) : r * (h * scale + gap) + h * scale, c * (w * scale + gap) :][:, : w * scale] = frame
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/figures/varied-scenes.png")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    from PIL import Image

    frames, indices = first_frames(args.seed, 8)
    Image.fromarray(grid(frames, columns=4, scale=3)).save(args.out, optimize=True)
    print(f"wrote {args.out}: first frames of samples {indices.tolist()} of paper-varied, seed {args.seed}")


if __name__ == "__main__":
    main()
