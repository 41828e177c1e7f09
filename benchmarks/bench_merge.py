"""Benchmark: merging generation shards into one file (per sample, 48 x 64 frames, T = 61).

Real simulator frames (32 samples of the paper grid, all primitives) are written as one
shard file (gzip 4, as a generation job writes it), then copied ``--copies`` times into
one data set file three ways, per sample:

1. ``copy_from``, raw: the compressed image chunks are copied as stored
   (``read_direct_chunk`` / ``write_direct_chunk``), what ``generate --out`` does.
2. decode + recompress: the shard's images are read (decompressed) and written (gzip 4),
   what ``copy_from`` falls back to when the storage differs.
3. compress only: in-memory arrays written (gzip 4), what the driver did before shard
   files (workers sent raw arrays; the driver compressed every sample).

Usage (the machine is shared: serialise benchmarks)::

    flock /tmp/primspace-bench.lock python benchmarks/bench_merge.py
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def make_shard(path: Path, n: int) -> None:
    """A shard file of ``n`` samples spread over the paper grid (every primitive)."""
    from primspace.data import DatasetWriter
    from primspace.data.schema import arrays_of
    from primspace.sim.generate import PRESETS, _file_settings, generate_shard

    config = PRESETS["paper"]
    shard = generate_shard(config, 0, range(0, config.n_samples, config.n_samples // n)[:n])
    with DatasetWriter(path, **_file_settings(config, 0, n)) as writer:  # as write_shard does
        writer.write(0, **arrays_of(shard))


def time_merge(shard: Path, copies: int, how: str, tmp: Path) -> float:
    """Seconds per sample to fill a file of ``copies`` shards ``how``."""
    from primspace.data import DatasetWriter, MotionDataset
    from primspace.data.schema import arrays_of
    from primspace.sim.generate import PRESETS, _file_settings

    src = MotionDataset.load(shard)
    n = len(src)
    arrays = np.asarray(src.images) if how == "compress only" else None
    out = tmp / f"merged-{how.replace(' ', '-')}.h5"
    t0 = time.perf_counter()
    with DatasetWriter(out, overwrite=True, **_file_settings(PRESETS["paper"], 0, n * copies)) as writer:
        for c in range(copies):
            if how == "raw chunks":
                writer.copy_from(c * n, shard)
            else:
                images = arrays if arrays is not None else np.asarray(src.images)  # decode every time
                writer.write(c * n, **dict(arrays_of(src), images=images))
    took = time.perf_counter() - t0
    merged = MotionDataset.load(out)
    np.testing.assert_array_equal(merged.images[-1], src.images[-1])
    return took / (n * copies)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, default=32, help="samples in the shard")
    ap.add_argument("--copies", type=int, default=8, help="times the shard is merged")
    args = ap.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f} (1 min)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        shard = tmp / "shard.h5"
        make_shard(shard, args.samples)
        size = shard.stat().st_size / args.samples
        print(f"shard: {args.samples} samples, 61 x 48 x 64 x 3 frames, {size / 1024:.1f} KiB a sample compressed")
        times = {
            how: time_merge(shard, args.copies, how, tmp)
            for how in ("raw chunks", "decode + recompress", "compress only")
        }
    raw = times["raw chunks"]
    for how, sec in times.items():
        print(f"  {how:<20} {sec * 1e3:7.2f} ms a sample  ({sec / raw:5.1f}x raw)")
    print(
        f"paper preset (1715 samples): raw merge {1715 * raw:.1f} s, decode + recompress "
        f"{1715 * times['decode + recompress']:.1f} s"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
