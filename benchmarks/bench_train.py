"""Training speed of the MTRNN decoder (not a test): samples/s and FLOP rate vs dense matmul.

Measures, on the CPU and (when present) on a CUDA GPU, in one process:

1. the rate of a dense float32 matmul (2048 x 2048, the reference);
2. one epoch (after a warm-up epoch) of ``fit`` and of ``infer`` on the paper's
   configuration: 1715 samples, T = 61, 9 joints, 48 x 64 images, q = 40, layers 32/12
   (synthetic data of that shape, in memory); FLOPs per sample counted with
   ``torch.utils.flop_counter.FlopCounterMode`` over a real forward + backward step
   (matmuls, batched matmuls, convolutions; elementwise work is not counted);
3. the paper's schedule (800 epochs fit on 20 % = 343 samples, 600 epochs infer on the
   other 1372) extrapolated from the measured epoch times;
4. ``--demo``: epoch times for demo-sized runs (126 samples; 48x64, 24x32 and no images;
   1 and 2 threads);
5. ``--schedule``: the paper's schedule itself, run and timed (not extrapolated) on the GPU
   (or the CPU with ``--schedule-device cpu``): fit 800 epochs on 343 samples at the preset's
   batch 32, then infer 600 epochs on 1372 samples at the preset's infer batch 256, with
   ``--vision-frames K`` (the preset's CPU runs use 8; omit for every frame). The elapsed
   time and epochs done are printed every 30 s, so a time-boxed run still reports how far
   it got.
6. ``--device cpu|cuda`` (issue 41; the modes above are then not run): per training path
   (``--paths eager compiled captured packed``: ``TrainConfig.step``, or ``--pack 1 4 16`` runs
   trained packed, their step captured on a GPU) the
   four cases fit / infer x motor only / images at K = 8 drawn frames (``--k-frames``), each in
   a fresh process on the paper's sizes (q = 40, layers 32/12, T = 61, J = 9; fit 343 samples
   at batch 32, infer 1372 at batch 256): samples/s over ``--epochs`` timed epochs after one
   warm-up epoch, the share of the same run's fp32 matmul rate (counted FLOPs per sample as
   in 2. x samples/s over the 2048^3 rate), peak memory (RSS on the CPU, the allocator's
   peak on a GPU) and the paper's schedule per run and per grid (12 runs, ``--workers`` at a
   time) extrapolated from the epoch times; ``--profile`` adds torch.profiler's operators of
   one fit epoch (CPU), motor only and with images, grouped into matmul / conv, elementwise,
   autograd engine and optimizer.

Usage::

    flock /tmp/primspace-bench.lock python benchmarks/bench_train.py [--samples 1715] [--demo] [--no-cpu]
    OMP_NUM_THREADS=1 python benchmarks/bench_train.py --device cpu --threads 1 --epochs 3 --profile --json OUT
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from primspace.data import MotionDataset
from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.train import TrainConfig, configure_process, fit, infer
from primspace.utils.files import atomic_write_json

T, J, H, W, Q = 61, 9, 48, 64, 40
PAPER_FIT_SAMPLES, PAPER_INFER_SAMPLES, PAPER_FIT_EPOCHS, PAPER_INFER_EPOCHS = 343, 1372, 800, 600


def synthetic(n: int, image_size: tuple[int, int] | None, seed: int = 0) -> MotionDataset:
    """Smooth random joint curves and random frames of the paper's shape (speed does not
    depend on the content)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)[None, :, None]
    motor = rng.normal(size=(n, 1, J)) * np.sin(np.pi * t * rng.uniform(0.5, 2, (n, 1, J))) + rng.normal(size=(n, 1, J))
    images = None
    if image_size is not None:
        images = rng.integers(0, 256, (n, T, *image_size, 3), dtype=np.uint8)
    return MotionDataset(motor.astype(np.float32), images=images)


def matmul_rate(device: torch.device, dtype=torch.float32, n: int = 2048, reps: int = 20) -> float:
    """FLOP/s of an n x n x n matmul on ``device`` (best of three timed groups)."""
    a = torch.randn(n, n, device=device, dtype=dtype)
    b = torch.randn(n, n, device=device, dtype=dtype)
    for _ in range(3):
        a @ b
    _sync(device)
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(reps):
            a @ b
        _sync(device)
        best = min(best, (time.perf_counter() - t0) / reps)
    return 2 * n**3 / best


def step_shape_rates(reps: int = 2000) -> dict:
    """FLOP/s of the recurrent step's own matrix products (eager, one at a time, as training
    calls them): the lower layer's ``addmm`` (batch 32 x 416 x 32: the outer product d ⊗ [u, 1]
    times the packed [A | W]), the top layer's ``baddbmm`` (32 x (1 x 12 x 12)) and the
    infer batch's (256 rows)."""
    shapes = {
        "addmm 32x416x32 (lower layer, fit batch)": (32, 416, 32),
        "addmm 256x416x32 (lower layer, infer batch)": (256, 416, 32),
        "baddbmm 32x(1x12x12) (top layer, fit batch)": None,
    }
    out = {}
    for label, shape in shapes.items():
        if shape is None:
            c, d, m = torch.randn(32, 1, 12), torch.randn(32, 1, 12), torch.randn(32, 12, 12)
            flops, fn = 2 * 32 * 12 * 12, lambda: torch.baddbmm(c, d, m)
        else:
            b, k, n = shape
            c, x, w = torch.randn(n), torch.randn(b, k), torch.randn(k, n)
            flops, fn = 2 * b * k * n, lambda: torch.addmm(c, x, w)
        for _ in range(50):
            fn()
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        seconds = (time.perf_counter() - t0) / reps
        out[label] = {"us": seconds * 1e6, "flops": flops / seconds}
        print(f"  {label}: {seconds * 1e6:.1f} us, {flops / seconds / 1e9:.1f} GFLOP/s", flush=True)
    return out


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def train_flops_per_sample(cfg: ModelConfig, *, frozen: bool, batch: int = 8) -> float:
    """Counted FLOPs of one training step (forward + backward) per sample."""
    model = MTRNNDecoder(cfg)
    model.requires_grad_(not frozen)
    z = torch.randn(batch, cfg.latent_dim, requires_grad=True)
    with FlopCounterMode(display=False) as counter:
        out = model(z)
        loss = out.motor.square().mean() + (out.images.square().mean() if out.images is not None else 0)
        loss.backward()
    return counter.get_total_flops() / batch


def timed_epochs(dataset, cfg: ModelConfig, tc: TrainConfig, workdir: Path, *, epochs: int = 2) -> dict:
    """Run fit then infer for ``epochs`` each; return the last epoch's seconds of each."""
    configure_process(tc)  # threads, heap tuning, cuDNN autotune: what the CLI applies
    run = fit(dataset, workdir / "fit", model_config=cfg, train_config=tc, overwrite=True, progress=False)
    ev = infer(workdir / "fit", dataset, workdir / "infer", epochs=epochs, overwrite=True, progress=False)
    return {"fit_s": run.history[-1]["seconds"], "infer_s": ev.history[-1]["seconds"]}


def bench_device(device: torch.device, args, workdir: Path) -> dict:
    print(
        f"\n=== {device} "
        + (f"({torch.get_num_threads()} threads)" if device.type == "cpu" else torch.cuda.get_device_name(device))
    )
    rate = matmul_rate(device)
    print(f"dense fp32 matmul 2048^3: {rate / 1e9:.1f} GFLOP/s")
    if device.type == "cuda":
        bf16 = matmul_rate(device, torch.bfloat16, n=4096)
        print(f"dense bf16 matmul 4096^3: {bf16 / 1e12:.1f} TFLOP/s")
    n = args.samples
    data = synthetic(n, (H, W))
    cfg = ModelConfig(latent_dim=Q, image_size=(H, W), n_joints=J, length=T)
    fit_flops = train_flops_per_sample(cfg, frozen=False)
    infer_flops = train_flops_per_sample(cfg, frozen=True)
    print(
        f"counted FLOPs per sample: fit step {fit_flops / 1e9:.3f} GFLOP, infer step {infer_flops / 1e9:.3f} GFLOP "
        f"(analytic forward {2 * MTRNNDecoder(cfg).macs_per_sample() / 1e9:.3f} GFLOP)"
    )
    results = {}
    variants = [("fp32", False, args.batch_size)]
    if device.type == "cuda":  # the recurrent loop is launch-bound on a GPU: larger batches amortise it
        variants += [("amp bf16", True, args.batch_size), ("amp bf16, batch 128", True, 128)]
    for name, amp, batch_size in variants:
        tc = TrainConfig(
            epochs=args.epochs,
            batch_size=batch_size,
            device=str(device),
            amp=amp,
            log_initial=False,
            threads=args.threads if device.type == "cpu" else None,
        )
        t = timed_epochs(data, cfg, tc, workdir, epochs=args.epochs)
        fit_sps, infer_sps = n / t["fit_s"], n / t["infer_s"]
        fit_rate, infer_rate = fit_flops * fit_sps, infer_flops * infer_sps
        print(
            f"[{name}] fit epoch ({n} samples, batch {batch_size}): {t['fit_s']:.2f} s = {fit_sps:.1f} samples/s, "
            f"{fit_rate / 1e9:.1f} GFLOP/s = {fit_rate / rate:.1%} of the fp32 matmul rate"
        )
        print(
            f"[{name}] infer epoch: {t['infer_s']:.2f} s = {infer_sps:.1f} samples/s, "
            f"{infer_rate / 1e9:.1f} GFLOP/s = {infer_rate / rate:.1%} of the fp32 matmul rate"
        )
        schedule = PAPER_FIT_EPOCHS * PAPER_FIT_SAMPLES / fit_sps + PAPER_INFER_EPOCHS * PAPER_INFER_SAMPLES / infer_sps
        print(
            f"[{name}] paper schedule (800 epochs fit x 343 + 600 epochs infer x 1372 samples), extrapolated: "
            f"{schedule / 60:.1f} min (target on one H100: <= 5 min)"
        )
        results[name] = {
            "fit_samples_per_s": fit_sps,
            "infer_samples_per_s": infer_sps,
            "fit_fraction_of_matmul": fit_rate / rate,
            "infer_fraction_of_matmul": infer_rate / rate,
            "schedule_min": schedule / 60,
        }
    return {"matmul_flops": rate, "fit_flops_per_sample": fit_flops, "infer_flops_per_sample": infer_flops, **results}


def bench_demo(workdir: Path) -> None:
    print("\n=== demo sizing: fit / infer epoch seconds, 126 samples, T=61, J=9, q=20, batch 32, CPU")
    cases = [
        ((48, 64), (64, 32, 16)),
        ((48, 64), (32, 16, 8)),
        ((24, 32), (64, 32, 16)),
        ((24, 32), (32, 16, 8)),
        (None, (64, 32, 16)),
    ]
    for threads in (1, 2):
        for size, channels in cases:
            data = synthetic(126, size, seed=1)
            cfg = ModelConfig(latent_dim=20, image_channels=channels)
            tc = TrainConfig(epochs=3, batch_size=32, device="cpu", threads=threads, log_initial=False)
            configure_process(tc)
            run = fit(
                data,
                workdir / "demo",
                model_config=cfg,
                train_config=tc,
                overwrite=True,
                progress=False,
                images=size is not None,
            )
            ev = infer(workdir / "demo", data, workdir / "demo_e", epochs=3, overwrite=True, progress=False)
            fit_s = statistics.median(h["seconds"] for h in run.history[1:])
            infer_s = statistics.median(h["seconds"] for h in ev.history[1:])
            label = (
                "no images" if size is None else f"{size[0]}x{size[1]} images, channels {','.join(map(str, channels))}"
            )
            print(f"  threads {threads}, {label:>36}: fit {fit_s:.3f} s/epoch, infer {infer_s:.3f} s/epoch")


def _watch(metrics: Path, label: str, stop: threading.Event, every: float = 30.0) -> None:
    """Print the epochs done (lines of ``metrics.jsonl``, epoch 0 excluded) every ``every`` s."""
    t0 = time.perf_counter()
    while not stop.wait(every):
        done = max(0, len(metrics.read_text().splitlines()) - 1) if metrics.exists() else 0
        print(f"  [{label}] {time.perf_counter() - t0:.0f} s: {done} epochs done", flush=True)


def run_schedule(
    device: str, vision_frames: int | None, workdir: Path, fit_epochs: int = PAPER_FIT_EPOCHS, step: str = "eager"
) -> dict:
    """The paper's schedule run and timed: fit 800 epochs x 343, infer 600 epochs x 1372."""
    data = synthetic(PAPER_FIT_SAMPLES + PAPER_INFER_SAMPLES, (H, W))
    fitted, inferred = data.subset(np.arange(PAPER_FIT_SAMPLES)), data.subset(np.arange(PAPER_FIT_SAMPLES, len(data)))
    cfg = ModelConfig(latent_dim=Q, image_size=(H, W), n_joints=J, length=T, layer_sizes=(32, 12), taus=(2.0, 8.0))
    tc = TrainConfig(
        epochs=fit_epochs,
        batch_size=32,
        device=device,
        final_lr_fraction=0.1,
        vision_frames=vision_frames,
        log_initial=False,
        step=step,
    )
    configure_process(tc)
    label = f"schedule on {device}, vision frames {vision_frames or 'all 61'}, fit epochs {fit_epochs}, step {step}"
    print(f"\n=== {label}", flush=True)
    seconds = {}
    for phase in ("fit", "infer"):
        stop = threading.Event()
        watcher = threading.Thread(target=_watch, args=(workdir / phase / "metrics.jsonl", phase, stop), daemon=True)
        watcher.start()
        t0 = time.perf_counter()
        if phase == "fit":
            fit(fitted, workdir / "fit", model_config=cfg, train_config=tc, overwrite=True, progress=False)
        else:
            infer(
                workdir / "fit",
                inferred,
                workdir / "infer",
                epochs=PAPER_INFER_EPOCHS,
                batch_size=256,
                overwrite=True,
                progress=False,
                step=step,
            )
        _sync(torch.device(device))
        seconds[phase] = time.perf_counter() - t0
        stop.set()
        print(f"  {phase}: {seconds[phase]:.1f} s measured", flush=True)
    total = sum(seconds.values())
    print(
        f"[{label}] the paper's schedule, measured: {total / 60:.2f} min (fit {seconds['fit']:.0f} s, "
        f"infer {seconds['infer']:.0f} s; target on one H100: <= 2 min)",
        flush=True,
    )
    return {
        "device": device,
        "vision_frames": vision_frames,
        "fit_s": seconds["fit"],
        "infer_s": seconds["infer"],
        "total_min": total / 60,
    }


# ---------------------------------------------------------------- issue 41: per device, per path, per case
CASES = ("fit-motor", "fit-images", "infer-motor", "infer-images")
PATHS = ("eager", "compiled", "captured", "packed")
GRID_RUNS = 12  # 4 inits x 3 seeds
MATMUL = ("addmm", "mm", "bmm", "baddbmm", "matmul", "linear", "conv", "convolution")


def _case_setup(case: str, k_frames: int):
    """The data, model and train configs of one case (the paper's sizes and batches)."""
    phase, what = case.split("-")
    images = what == "images"
    data = synthetic(PAPER_FIT_SAMPLES + (PAPER_INFER_SAMPLES if phase == "infer" else 0), (H, W) if images else None)
    cfg = ModelConfig(
        latent_dim=Q, image_size=(H, W) if images else None, n_joints=J, length=T, layer_sizes=(32, 12), taus=(2.0, 8.0)
    )
    return phase, images, data, cfg


def case_flops_per_sample(cfg: ModelConfig, *, frozen: bool, images: bool, k_frames: int, batch: int = 8) -> float:
    """Counted FLOPs (matmuls, batched matmuls, convolutions) of one forward + backward step
    per sample, images decoded at ``k_frames`` drawn steps (the docs' definition)."""
    model = MTRNNDecoder(cfg)
    model.requires_grad_(not frozen)
    z = torch.randn(batch, cfg.latent_dim, requires_grad=True)
    steps = torch.stack([torch.randperm(T)[:k_frames] for _ in range(batch)]) if images else None
    with FlopCounterMode(display=False) as counter:
        out = model(z, images=images, frame_steps=steps)
        loss = out.motor.square().mean() + (out.images.square().mean() if out.images is not None else 0)
        loss.backward()
    return counter.get_total_flops() / batch


def run_case(
    case: str, device: str, threads: int, epochs: int, k_frames: int, path: str = "eager", pack: int = 1
) -> dict:
    """One case in a fresh process: one warm-up epoch (it holds a compile or a capture), then
    ``epochs`` timed epochs. ``path``: ``TrainConfig.step`` (eager, compiled, captured), or
    ``packed``: ``pack`` runs of different seeds trained packed (``primspace.train.packed``;
    their step captured on a GPU), samples/s counting every run's samples."""
    import resource

    from primspace.train.packed import fit_packed, infer_packed

    phase, images, data, cfg = _case_setup(case, k_frames)
    step = path if path != "packed" else ("captured" if device == "cuda" else "eager")
    tcs = [
        TrainConfig(
            epochs=1 + epochs if phase == "fit" else 1,
            batch_size=32,
            device=device,
            final_lr_fraction=0.1,
            vision_frames=k_frames if images else None,
            log_initial=False,
            threads=threads if device == "cpu" else None,
            step=step,
            seed=seed,
        )
        for seed in range(pack)
    ]
    configure_process(tcs[0])
    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    fitted = data.subset(np.arange(PAPER_FIT_SAMPLES))
    with tempfile.TemporaryDirectory(prefix="bench_train_case_") as tmp:
        fits = [
            dict(dataset=fitted, out_dir=Path(tmp) / f"fit{r}", model_config=cfg, train_config=tc, overwrite=True)
            for r, tc in enumerate(tcs)
        ]
        runs = fit_packed(fits, progress=False) if path == "packed" else [fit(**fits[0], progress=False)]
        if phase == "infer":
            inferred = data.subset(np.arange(PAPER_FIT_SAMPLES, len(data)))
            infers = [
                dict(run=Path(tmp) / f"fit{r}", dataset=inferred, out_dir=Path(tmp) / f"infer{r}", epochs=1 + epochs)
                for r in range(pack)
            ]
            for job in infers:
                job.update(batch_size=256, overwrite=True, step=step)  # the presets' infer batch
            runs = infer_packed(infers, progress=False) if path == "packed" else [infer(**infers[0], progress=False)]
    n = PAPER_FIT_SAMPLES if phase == "fit" else PAPER_INFER_SAMPLES
    seconds = [h["seconds"] for h in runs[0].history[1:]]  # the first epoch is the warm-up
    median = statistics.median(seconds)
    if device == "cuda":
        peak = torch.cuda.max_memory_allocated() / 2**20
    else:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
    flops = case_flops_per_sample(cfg, frozen=phase == "infer", images=images, k_frames=k_frames)
    return {
        "case": case,
        "path": path,
        "pack": pack,
        "samples": n,
        "batch": 32 if phase == "fit" else 256,
        "epoch_s": seconds,
        "warmup_s": runs[0].history[0]["seconds"],
        "samples_per_s": pack * n / median,
        "flops_per_sample": flops,
        "peak_mib": peak,
    }


def _in_child(fn, *fn_args):
    """Run ``fn`` in a fresh (spawned) process: its peak memory is its own."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn")) as pool:
        return pool.submit(fn, *fn_args).result()


def _category(name: str) -> str:
    low = name.lower()
    if low.startswith("autograd::") or "backward0" in low or "backward1" in low or low.startswith("torch::autograd"):
        return "autograd overhead"
    op = low.split("::")[-1]
    if low.startswith("aten::") and (op in MATMUL or "conv" in op or "mkldnn" in op):
        return "matmul / conv"
    if low.startswith("aten::"):
        return "elementwise and other aten"
    if low.startswith("optimizer."):
        return "optimizer (python)"
    return "other (python, profiler)"


def profile_fit_epoch(images: bool, threads: int, k_frames: int, top: int) -> dict:
    """Profile one fit epoch (after a warm-up fit) on the CPU with torch.profiler."""
    from torch.profiler import ProfilerActivity, profile

    _, _, data, cfg = _case_setup("fit-images" if images else "fit-motor", k_frames)
    tc = TrainConfig(
        epochs=1,
        batch_size=32,
        device="cpu",
        final_lr_fraction=0.1,
        vision_frames=k_frames if images else None,
        log_initial=False,
        threads=threads,
    )
    configure_process(tc)
    warm = fit(data, None, model_config=cfg, train_config=tc, progress=False)
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        run = fit(data, None, model_config=cfg, train_config=tc, progress=False)
    events = [e for e in prof.key_averages() if e.self_cpu_time_total > 0]
    total = sum(e.self_cpu_time_total for e in events)
    shares: dict[str, float] = {}
    for e in events:
        shares[_category(e.key)] = shares.get(_category(e.key), 0.0) + e.self_cpu_time_total / total
    rows = sorted(events, key=lambda e: -e.self_cpu_time_total)[:top]
    return {
        "images": images,
        "epoch_s_unprofiled": warm.history[-1]["seconds"],
        "epoch_s_profiled": run.history[-1]["seconds"],
        "self_cpu_total_s": total / 1e6,
        "shares": shares,
        "top": [
            {
                "op": e.key,
                "self_cpu_s": e.self_cpu_time_total / 1e6,
                "share": e.self_cpu_time_total / total,
                "calls": e.count,
                "category": _category(e.key),
            }
            for e in rows
        ],
    }


def _bench_path(path: str, pack: int, label: str, device: str, threads: int, workers: int, rate: float, args) -> dict:
    """The cases of one path (and pack size), and the paper's schedule per run and per grid."""
    rows = {}
    for case in args.cases:
        try:
            r = _in_child(run_case, case, device, threads, args.epochs, args.k_frames, path, pack)
        except Exception as exc:  # a path that fails on this machine is reported, the others still run
            print(f"[{label}] {case}: failed: {type(exc).__name__}: {exc}", flush=True)
            rows[case] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
        r["fraction_of_matmul"] = r["flops_per_sample"] * r["samples_per_s"] / rate
        rows[case] = r
        print(
            f"[{label}] {case:>12}: {r['samples_per_s']:8.1f} samples/s (median of {len(r['epoch_s'])} epochs, "
            f"{statistics.median(r['epoch_s']):.2f} s each; warm-up {r['warmup_s']:.1f} s), "
            f"{r['flops_per_sample'] / 1e6:.1f} MFLOP/sample, {r['fraction_of_matmul']:.1%} of the matmul rate, "
            f"peak {r['peak_mib']:.0f} MiB",
            flush=True,
        )
    schedules = {}
    for what in ("motor", "images"):
        f, i = rows.get(f"fit-{what}", {}), rows.get(f"infer-{what}", {})
        if "samples_per_s" not in f or "samples_per_s" not in i:
            continue
        # one run's (or one pack's) schedule at the measured pace; a pack trains `pack` runs in that time
        run_s = pack * (PAPER_FIT_EPOCHS * PAPER_FIT_SAMPLES / f["samples_per_s"])
        run_s += pack * (PAPER_INFER_EPOCHS * PAPER_INFER_SAMPLES / i["samples_per_s"])
        at_once = pack if path == "packed" else (workers if device == "cpu" else 1)
        # a pack larger than the grid trains the grid's runs in one pack, taken at the measured pace
        grid_s = -(-GRID_RUNS // at_once) * run_s * (min(pack, GRID_RUNS) / pack)
        schedules[what] = {"run_min": run_s / 60 / pack if path == "packed" else run_s / 60, "grid_min": grid_s / 60}
        print(
            f"[{label}] paper schedule, {what}: {run_s / 60:.1f} min per {'pack' if path == 'packed' else 'run'}, "
            f"{grid_s / 60:.1f} min per grid ({GRID_RUNS} runs, {at_once} at a time) -- extrapolated from the "
            "epoch times, not run"
        )
    return {"cases": rows, "schedule": schedules}


def bench_issue41(args) -> dict:
    """Per device and path, the four cases; the paper's schedule per run and per grid."""
    device = args.device
    if device == "cuda" and not torch.cuda.is_available():
        print("no GPU: CUDA is not available on this machine, --device cuda skipped")
        return {}
    threads = args.threads or 1
    torch.set_num_threads(threads)
    workers = args.workers or max(1, (os.cpu_count() or 1) // threads)
    rate = matmul_rate(torch.device(device))
    where = f"{threads} thread(s)" if device == "cpu" else torch.cuda.get_device_name()
    print(f"\n=== {device} ({where}): dense fp32 matmul 2048^3 in this run: {rate / 1e9:.1f} GFLOP/s")
    out = {"device": device, "threads": threads, "workers": workers, "matmul_flops": rate, "paths": {}}
    for path in args.paths:
        for pack in args.pack if path == "packed" else [1]:
            label = f"packed x{pack}" if path == "packed" else path
            out["paths"][label] = _bench_path(path, pack, label, device, threads, workers, rate, args)
    if args.profile and device == "cpu":
        print("\nthe recurrent step's matrix products, alone (the ceiling of the motor-only epoch's share):")
        out["step_shapes"] = step_shape_rates()
        out["profile"] = {}
        for images in (False, True):
            p = _in_child(profile_fit_epoch, images, threads, args.k_frames, args.top)
            label = "images" if images else "motor"
            out["profile"][label] = p
            print(
                f"\nprofile, one fit epoch, {label} ({p['epoch_s_unprofiled']:.2f} s unprofiled, "
                f"{p['epoch_s_profiled']:.2f} s profiled, {p['self_cpu_total_s']:.2f} s self CPU):"
            )
            for k, v in sorted(p["shares"].items(), key=lambda kv: -kv[1]):
                print(f"  {k:>28}: {v:.1%}")
            for e in p["top"]:
                print(
                    f"  {e['op']:>48} {e['self_cpu_s']:7.3f} s {e['share']:6.1%} {e['calls']:7d} calls  {e['category']}"
                )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1715)
    parser.add_argument("--epochs", type=int, default=2, help="epochs per measurement; the last one is timed")
    parser.add_argument("--batch-size", type=int, default=32)
    parser.add_argument("--threads", type=int, default=None, help="CPU threads (default: torch's)")
    parser.add_argument("--demo", action="store_true", help="also time demo-sized runs")
    parser.add_argument("--no-cpu", action="store_true", help="skip the CPU paper-configuration epoch")
    parser.add_argument("--demo-only", action="store_true", help="only the demo sizing")
    parser.add_argument("--schedule", action="store_true", help="run and time the paper's schedule itself")
    parser.add_argument("--schedule-device", default="cuda", help="device of --schedule (cuda or cpu)")
    parser.add_argument("--vision-frames", type=int, default=None, help="K drawn frames in --schedule (default: all)")
    parser.add_argument(
        "--schedule-fit-epochs",
        type=int,
        default=PAPER_FIT_EPOCHS,
        help="fit epochs of --schedule (fewer: to time the infer phase within a time box)",
    )
    parser.add_argument("--schedule-step", default="eager", help="TrainConfig.step of --schedule")
    parser.add_argument("--no-epochs", action="store_true", help="skip the epoch measurements (with --schedule)")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    issue41 = parser.add_argument_group("issue 41 (per device, path and case; chosen by --device)")
    issue41.add_argument("--device", choices=("cpu", "cuda"), default=None, help="measure the four cases here")
    issue41.add_argument(
        "--paths", nargs="+", choices=PATHS, default=["eager"], help="training paths (TrainConfig.step, or packed)"
    )
    issue41.add_argument("--pack", nargs="+", type=int, default=[1, 4, 16], help="runs per pack of --paths packed")
    issue41.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    issue41.add_argument("--k-frames", type=int, default=8, help="K drawn frames of the image cases")
    issue41.add_argument("--workers", type=int, default=None, help="parallel runs of a grid (default: CPUs / threads)")
    issue41.add_argument("--profile", action="store_true", help="also profile one fit epoch (CPU, torch.profiler)")
    issue41.add_argument("--top", type=int, default=12, help="operators listed by the profile")
    args = parser.parse_args()
    if args.device is not None:
        if args.epochs < 1:
            parser.error("--epochs must be at least 1")
        print(f"torch {torch.__version__}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
        figures = bench_issue41(args)
        print(f"\nload average at the end: {os.getloadavg()[0]:.2f}")
        if args.json and figures:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_json(args.json, figures)
        return
    if args.threads:
        torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    figures = {}
    with tempfile.TemporaryDirectory(prefix="bench_train_") as tmp:
        work = Path(tmp)
        epochs = not (args.demo_only or args.no_epochs)
        if epochs and not args.no_cpu:
            figures["cpu"] = bench_device(torch.device("cpu"), args, work)
        if torch.cuda.is_available() and epochs:
            figures["cuda"] = bench_device(torch.device("cuda"), args, work)
        elif epochs:
            print("\nno GPU: CUDA is not available on this machine, GPU figures not measured")
        if args.schedule:
            if args.schedule_device == "cuda" and not torch.cuda.is_available():
                print("\nno GPU: the schedule is not run (use --schedule-device cpu)")
            else:
                figures["schedule"] = run_schedule(
                    args.schedule_device,
                    args.vision_frames,
                    work / "schedule",
                    args.schedule_fit_epochs,
                    args.schedule_step,
                )
                if args.json:  # written at once: a later, time-boxed step may not finish
                    atomic_write_json(args.json, figures)
        if args.demo or args.demo_only:
            bench_demo(work)
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f}")
    if args.json:
        atomic_write_json(args.json, figures)


if __name__ == "__main__":
    main()
