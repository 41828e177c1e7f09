"""Benchmark: simulated data generation speed (trajectories per second with 48 x 64 images).

Two measurements in one run:

1. Where a trajectory's time goes, in this process: script + inverse kinematics, replay
   (block motion, contact distances) + success judge, rendering the T frames, and
   gzip-compressed HDF5 writing (through ``DatasetWriter``), over a few samples of each
   primitive.
2. End to end: ``generate_dataset`` of a preset with N worker processes into an HDF5 file
   (spawn, shards, writing included), as ``primspace generate`` runs it.

Usage (the machine is shared: serialise benchmarks)::

    flock /tmp/primspace-bench.lock python benchmarks/bench_generate.py --preset paper --workers 2

Target (the issue): the 1715-trajectory ``paper`` preset in at most 3 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def stage_profile(per_primitive: int) -> dict[str, float]:
    """Seconds per trajectory spent in each stage (one process)."""
    from primspace.data import DatasetWriter
    from primspace.sim.generate import PRESETS, sample_params
    from primspace.sim.ik import solve_path
    from primspace.sim.primitives import PRIMITIVES, R_DOWN, finger_geometry, script_motion
    from primspace.sim.render import Camera
    from primspace.sim.rollout import replay
    from primspace.sim.scene import JOINT_NAMES, Scene
    from primspace.sim.success import judge_rollout

    config = PRESETS["paper"]
    scene = Scene()
    home = finger_geometry(scene).home
    stride = max(1, config.n_per_primitive // per_primitive)
    indices = [p * config.n_per_primitive + k * stride for p in range(len(PRIMITIVES)) for k in range(per_primitive)]
    totals = dict.fromkeys(("script + IK", "replay + judge", "render", "HDF5 write"), 0.0)
    frames = np.empty((len(indices), config.length, config.height, config.width, 3), dtype=np.uint8)
    motors = np.empty((len(indices), config.length, 9), dtype=np.float32)
    with Camera(scene, config.height, config.width) as camera:
        camera.render()  # compile shaders outside the timing
        for j, index in enumerate(indices):
            label, x, y, size = sample_params(config, 0, index)
            t0 = time.perf_counter()
            script = script_motion(scene, label, x, y, size, config.length)
            ik = solve_path(scene, script.tcp, R_DOWN, home)
            motor = np.column_stack([ik.q, script.fingers, script.fingers])
            t1 = time.perf_counter()
            rollout = replay(scene, motor, (x, y), size, script.push_axis, script.push_sign)
            assert judge_rollout(PRIMITIVES[label], rollout).success
            t2 = time.perf_counter()
            for t in range(config.length):
                scene.set_joints(motor[t])
                scene.data.mocap_pos[scene.block_mocap] = rollout.block[t]
                camera.render(out=frames[j, t])
            t3 = time.perf_counter()
            motors[j] = motor
            totals["script + IK"] += t1 - t0
            totals["replay + judge"] += t2 - t1
            totals["render"] += t3 - t2
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        with DatasetWriter(
            Path(tmp) / "w.h5",
            n_samples=len(indices),
            length=config.length,
            joint_names=JOINT_NAMES,
            image_size=(config.height, config.width),
        ) as writer:
            for start in range(0, len(indices), 32):
                writer.write(start, motor=motors[start : start + 32], images=frames[start : start + 32])
        totals["HDF5 write"] = time.perf_counter() - t0
    return {k: v / len(indices) for k, v in totals.items()}


def end_to_end(preset: str, workers: int, seed: int) -> tuple[int, float, int]:
    """(trajectories, seconds, file bytes) of a full ``generate_dataset`` run."""
    from primspace.sim.generate import generate_dataset

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / f"{preset}.h5"
        t0 = time.perf_counter()
        ds = generate_dataset(preset, seed=seed, workers=workers, out=out, progress=False)
        took = time.perf_counter() - t0
        return len(ds), took, out.stat().st_size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="paper", help="preset for the end-to-end run (paper, demo)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--per-primitive", type=int, default=10, help="samples per primitive in the stage profile")
    ap.add_argument("--skip-full", action="store_true", help="only the stage profile")
    args = ap.parse_args()

    print(f"load average before: {os.getloadavg()[0]:.2f} (1 min), usable cores: {len(os.sched_getaffinity(0))}")
    stages = stage_profile(args.per_primitive)
    total = sum(stages.values())
    print(f"\nper trajectory, one process (T=61, 48x64 images), {7 * args.per_primitive} samples:")
    for name, sec in stages.items():
        print(f"  {name:<15} {sec * 1e3:7.1f} ms  {sec / total:6.1%}")
    print(f"  {'total':<15} {total * 1e3:7.1f} ms  -> {1 / total:.1f} trajectories/s per core")
    if args.skip_full:
        return
    n, took, size = end_to_end(args.preset, args.workers, seed=0)
    rate = n / took
    print(
        f"\nend to end: preset {args.preset}, {args.workers} workers: {n} trajectories in {took:.1f} s "
        f"= {rate:.1f} trajectories/s ({size / 2**20:.1f} MiB file)"
    )
    print(
        f"  paper preset (1715) at this rate: {1715 / rate:.0f} s (target <= 180 s: "
        f"{'met' if 1715 / rate <= 180 else 'NOT met'}); speed-up over one process: "
        f"{rate * total:.2f}x with {args.workers} workers"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
