"""Benchmark: affine low-rank subspace clustering at 1e4, 1e5, 1e6 points (not a test).

Data: 7 affine subspaces of dimension 3 in 40-D (random orthonormal bases, offsets ~ N(0, I)),
coordinates in the subspace ~ N(0, 1), isotropic Gaussian noise (default sigma 0.05), labels
drawn uniformly. tau by R^2 target 0.999 (what a user does without labels; it keeps the 28
homogeneous dimensions of the 7 subspaces).

Every size runs in a fresh subprocess so that its peak memory is its own: the peak is the
process's high-water RSS (VmHWM, which sees BLAS scratch space that tracemalloc cannot),
reset after the data are generated, so "fit peak" is what the fit adds on top of the data
and "process peak" includes the data and the interpreter. BLAS/OpenMP threads are limited to
--threads (default 2) with threadpoolctl. The fit is timed once end to end; a second run of
the same steps reports where the time goes. At --sklearn-n points (default 1e4) the same run
also times scikit-learn's SpectralClustering(affinity="precomputed") on the same affinity
W = Q* o Q* (given W; building W is not counted against it) and prints the ratio.

``--sweep`` times :func:`primspace.cluster.sweep` instead (same data, labels given, the
command's default R^2 grid or ``--sweep-grid``): end to end, and the SVD alone, so the cost
per grid value shows; a sweep computes its SVD once. To compare with an older checkout, run
the same script with ``PYTHONPATH=OLD/src``.

Run (the machine is shared; the lock keeps benchmarks apart)::

    flock /tmp/primspace-bench.lock python benchmarks/bench_cluster.py
    python benchmarks/bench_cluster.py --sizes 1e4,1e5 --threads 1
    python benchmarks/bench_cluster.py --sweep --sizes 1e4,1e5 --repeat 3
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

TARGETS = {"n": 1_000_000, "seconds": 90.0, "peak_gb": 3.0, "accuracy": 0.99, "speedup": 20.0}


def make_data(n: int, noise: float, seed: int = 0, ambient: int = 40, k: int = 7, dim: int = 3):
    """n points on k affine dim-subspaces of R^ambient plus Gaussian noise; rows = points."""
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, k, n)
    x = np.empty((n, ambient))
    for j in range(k):
        basis = np.linalg.qr(rng.standard_normal((ambient, dim)))[0]
        offset = rng.standard_normal(ambient)
        idx = np.flatnonzero(labels == j)
        x[idx] = offset + rng.standard_normal((idx.size, dim)) @ basis.T
    x += noise * rng.standard_normal((n, ambient))
    return x, labels


def _vm_hwm_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def _vm_rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def _reset_peak() -> None:
    with open("/proc/self/clear_refs", "w") as fh:  # Linux: VmHWM := VmRSS
        fh.write("5")


def worker(args) -> dict:
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=args.threads)
    x, y = make_data(args.worker, args.noise)
    if args.sweep:
        return sweep_worker(args, x, y)
    return fit_worker(args, x, y)


def sweep_worker(args, x, y) -> dict:
    """Time ``sweep`` over the grid (best of ``--repeat``), and the one SVD it needs."""
    from primspace.cluster import self_representation_svd, sweep

    grid = [float(v) for v in args.sweep_grid.split(",")] if args.sweep_grid else None
    times, rows = [], None
    for _ in range(args.repeat):
        t = time.perf_counter()
        rows = sweep(x, 7, r2_targets=grid, labels_true=y, n_init=args.n_init, random_state=0)
        times.append(time.perf_counter() - t)
    t = time.perf_counter()
    self_representation_svd(x)
    svd_seconds = time.perf_counter() - t
    return {
        "n": args.worker,
        "sweep_seconds": min(times),
        "sweep_times": times,
        "svd_seconds": svd_seconds,
        "grid_values": len(rows),
        "accuracy": [r.get("accuracy") for r in rows],
        "threads": args.threads,
    }


def fit_worker(args, x, y) -> dict:
    """One end-to-end fit (time, peak memory, accuracy), then its phases timed one by one."""
    from primspace.cluster import LowRankSubspaceClustering, clustering_accuracy, njw_labels, self_representation_svd
    from primspace.cluster.spectral import choose_spectral_method, spectral_embedding

    n = args.worker
    rss_data = _vm_rss_mb()
    _reset_peak()
    model = LowRankSubspaceClustering(7, r2_target=args.r2, n_init=args.n_init, random_state=0)
    t0 = time.perf_counter()
    model.fit(x)
    seconds = time.perf_counter() - t0
    peak = _vm_hwm_mb()
    out = {
        "n": n,
        "seconds": seconds,
        "process_peak_mb": peak,
        "fit_peak_mb": peak - rss_data,
        "data_mb": x.nbytes / 2**20,
        "accuracy": clustering_accuracy(y, model.labels_),
        "rank": model.rank_,
        "tau_relative": model.tau_relative_,
        "r2": model.r2_,
        "method": model.spectral_method_,
        "threads": args.threads,
    }
    # where the time goes: the same steps, timed one by one
    phases = {}
    t = time.perf_counter()
    svd = self_representation_svd(x)
    phases["svd"] = time.perf_counter() - t
    t = time.perf_counter()
    tau = svd.tau_for_r2(args.r2)
    factor = svd.factor(tau)
    phases["tau+factor"] = time.perf_counter() - t
    t = time.perf_counter()
    method = choose_spectral_method(n, factor.shape[1], "squared", "auto")
    emb = spectral_embedding(factor, 7, method=method, random_state=0) if method != "dense" else None
    if emb is None:  # dense route: count the n x n matrices as the eigen step
        from primspace.cluster.spectral import affinity_from_factor, spectral_embedding_dense

        emb = spectral_embedding_dense(affinity_from_factor(factor), 7, random_state=0)
    phases["eigen (" + emb.method + ")"] = time.perf_counter() - t
    t = time.perf_counter()
    njw_labels(emb.vectors, 7, n_init=args.n_init, random_state=0)
    phases[f"kmeans x{args.n_init}"] = time.perf_counter() - t
    out["phases"] = phases
    if n == args.sklearn_n:
        from sklearn.cluster import SpectralClustering

        from primspace.cluster import affinity_from_factor

        w = affinity_from_factor(model.representation_factor_, "squared")
        sk = SpectralClustering(n_clusters=7, affinity="precomputed", n_init=args.n_init, random_state=0)
        t = time.perf_counter()
        sk.fit(w)
        out["sklearn_seconds"] = time.perf_counter() - t
        out["sklearn_accuracy"] = clustering_accuracy(y, sk.labels_)
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="1e4,1e5,1e6", help="comma-separated n")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--noise", type=float, default=0.05)
    p.add_argument("--r2", type=float, default=0.999, help="R^2 target that picks tau")
    p.add_argument("--n-init", type=int, default=20)
    p.add_argument("--sklearn-n", type=float, default=1e4, help="size at which sklearn is compared (0: never)")
    p.add_argument("--sweep", action="store_true", help="time sweep() over an R^2 grid instead of one fit")
    p.add_argument(
        "--sweep-grid", default="", help="comma-separated R^2 targets for --sweep (default: the command's grid)"
    )
    p.add_argument("--repeat", type=int, default=1, help="--sweep: runs per size; the best is reported")
    p.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    args.sklearn_n = int(args.sklearn_n)
    if args.worker is not None:
        print(json.dumps(worker(args)))
        return
    print(
        f"load before: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} "
        f"(1/5/15 min), {os.cpu_count()} CPUs, threads {args.threads}, noise {args.noise}, R^2 target {args.r2}"
    )
    results = []
    for size in [int(float(s)) for s in args.sizes.split(",")]:
        r = run_worker(size, args)
        results.append(r)
        print_sweep(r) if args.sweep else print_fit(r)
    print(f"load after: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
    if not args.sweep:
        print_targets(results)


def run_worker(size: int, args) -> dict:
    """One size in a fresh subprocess (its own peak memory and thread settings)."""
    cmd = [
        sys.executable,
        __file__,
        "--worker",
        str(size),
        "--threads",
        str(args.threads),
        "--noise",
        str(args.noise),
        "--r2",
        str(args.r2),
        "--n-init",
        str(args.n_init),
        "--sklearn-n",
        str(args.sklearn_n),
        "--repeat",
        str(args.repeat),
        "--sweep-grid",
        args.sweep_grid,
    ] + (["--sweep"] if args.sweep else [])
    env = {**os.environ, "OMP_NUM_THREADS": str(args.threads), "OPENBLAS_NUM_THREADS": str(args.threads)}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        print(f"n={size}: worker failed\n{proc.stderr}", file=sys.stderr)
        sys.exit(1)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def print_sweep(r: dict) -> None:
    times = " ".join(f"{t:.2f}" for t in r["sweep_times"])
    per_value = (r["sweep_seconds"] - r["svd_seconds"]) / r["grid_values"]
    accuracy = " ".join("-" if a is None else f"{a:.3f}" for a in r["accuracy"])
    print(
        f"n={r['n']:>9,}  sweep of {r['grid_values']} values {r['sweep_seconds']:7.2f} s (best of: {times})  "
        f"svd {r['svd_seconds']:.2f} s, {per_value:.2f} s per value  | accuracy {accuracy}",
        flush=True,
    )


def print_fit(r: dict) -> None:
    phases = "  ".join(f"{k} {v:.2f}" for k, v in r["phases"].items())
    print(
        f"n={r['n']:>9,}  fit {r['seconds']:7.2f} s  peak {r['process_peak_mb']:7.0f} MB (fit +{r['fit_peak_mb']:.0f}, "
        f"data {r['data_mb']:.0f})  accuracy {r['accuracy']:.4f}  rank {r['rank']}  {r['method']}  | {phases}",
        flush=True,
    )
    if "sklearn_seconds" in r:
        print(
            f"           sklearn SpectralClustering(precomputed W) {r['sklearn_seconds']:.2f} s, accuracy "
            f"{r['sklearn_accuracy']:.4f}; ours {r['seconds']:.2f} s: {r['sklearn_seconds'] / r['seconds']:.1f}x faster",
            flush=True,
        )


def print_targets(results: list[dict]) -> None:
    big = [r for r in results if r["n"] == TARGETS["n"]]
    if big:
        r = big[0]
        ok = (
            r["seconds"] <= TARGETS["seconds"]
            and r["process_peak_mb"] / 1024 <= TARGETS["peak_gb"]
            and r["accuracy"] >= TARGETS["accuracy"]
        )
        print(f"target n=1e6: <= 90 s, <= 3 GB, accuracy >= 0.99: {'met' if ok else 'MISSED'}")
    cmp = [r for r in results if "sklearn_seconds" in r]
    if cmp:
        r = cmp[0]
        ratio = r["sklearn_seconds"] / r["seconds"]
        ok = ratio >= TARGETS["speedup"] and r["accuracy"] >= r["sklearn_accuracy"]
        print(
            f"target n={r['n']:.0e}: >= 20x faster than sklearn at equal accuracy: {'met' if ok else 'MISSED'} ({ratio:.1f}x)"
        )


if __name__ == "__main__":
    main()
