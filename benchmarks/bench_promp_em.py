"""The ProMP's EM (not a test): movement-primitives' ``ProMP.imitate`` against
:func:`primspace.predict.peers.imitate_promp`, the same EM computed once per demonstration length.

On one CPU core (numpy's BLAS at one thread), in one process: ``--demos`` smooth random
trajectories of 61 steps and 9 joints (the paper preset's shape; with ``--lengths 2`` half of
them 50 steps), learned by both with ``--basis`` basis functions per joint; printed per basis
count: each one's time (median of ``--repeats``), the ratio, and the largest difference of their
weight means and covariances (they are the same EM, so it is rounding). The tuned ProMP peer
(:class:`primspace.predict.gaussian_peers.TunedProMPPeer`) fits one ProMP per fold, basis count
and group: that is what the ratio multiplies.

Timings are wall-clock and depend on what else the machine runs: the load average is printed.

Usage::

    python benchmarks/bench_promp_em.py [--demos 49] [--basis 10,20,40] [--lengths 1] [--repeats 1] [--json PATH]
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from primspace.predict.peers import imitate_promp, phase, promp_class  # noqa: E402
from primspace.utils.files import atomic_write_json


def _demos(count: int, lengths: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        steps = 61 if lengths == 1 or i % 2 == 0 else 50
        walk = np.cumsum(rng.normal(size=(steps, 9)), axis=0)
        out.append(np.tanh(walk / np.sqrt(steps)))
    return out


def _median_time(fn, repeats: int):
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demos", type=int, default=49)
    parser.add_argument("--basis", default="10,20,40")
    parser.add_argument("--lengths", type=int, choices=(1, 2), default=1)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    demos = _demos(args.demos, args.lengths)
    print(f"{args.demos} demonstrations, {args.lengths} length(s), 9 joints; load average {os.getloadavg()[0]:.2f}")
    rows = []
    for basis in (int(b) for b in args.basis.split(",")):

        def package(basis=basis):
            promp = promp_class()(9, basis)
            promp.imitate([phase(len(y)) for y in demos], demos)
            return promp

        t_package, ref = _median_time(package, args.repeats)
        t_ours, ours = _median_time(lambda basis=basis: imitate_promp(9, basis, demos), args.repeats)
        diff = max(np.abs(ours.weight_mean - ref.weight_mean).max(), np.abs(ours.weight_cov - ref.weight_cov).max())
        rows.append(
            {"basis": basis, "package_s": t_package, "ours_s": t_ours, "ratio": t_package / t_ours, "diff": diff}
        )
        print(
            f"basis {basis:3d}: imitate {t_package:8.2f} s  imitate_promp {t_ours:6.3f} s  "
            f"ratio {t_package / t_ours:7.1f}x  largest difference {diff:.1e}",
            flush=True,
        )
    if args.json:
        atomic_write_json(args.json, {"demos": args.demos, "lengths": args.lengths, "rows": rows})


if __name__ == "__main__":
    main()
