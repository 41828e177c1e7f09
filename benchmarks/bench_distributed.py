"""One model beyond one machine: the frame loader's throughput, and training with frames
in memory or streamed, in one process or two (gloo), with the time split between waiting
for data, computing and communicating (issue 28, item 4).

Data: the demo preset's simulated motions (126 of T = 61 steps with 48x64 frames,
generated here unless a file is given). Every configuration runs in fresh processes (so
each one's peak memory is its own), ``--threads`` math threads per training process.

1. Loader: a pass over the data in batches of ``--batch`` samples through
   :class:`primspace.train.streaming.FrameStream` with 0, 1, 2 workers (after a warm-up
   pass that starts them): samples/s, MB/s of decoded frames, decode ms per sample.
2. Training: epoch seconds (median of the epochs after the first), samples/s; seconds per
   epoch waiting for frames (``FrameStream.waited``), in gradient all-reduce (DDP comm
   hook: start to finish, overlapping the backward pass) and in the code gathers and loss
   sums (blocking); peak resident memory per process and of its largest loader worker.
3. The epoch time at 100,000 demonstrations projected from the measured samples/s, and
   the memory the frames would take loaded (56 GB at T = 61, 48x64).

Usage::

    python benchmarks/bench_distributed.py [DATA.h5] [--epochs 3] [--batch 16] [--threads 1] [--device cpu]
        [--processes 1,2] [--loader-workers 0,1,2] [--train-workers N]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import socket
import statistics
import tempfile
import time
from pathlib import Path

import torch
import torch.multiprocessing as mp

PROJECT_N = 100_000


def _loader_rates(path: Path, batch: int, workers_list) -> list[dict]:
    """Samples/s, MB/s and decode time per sample of a pass over the file's frames."""
    from primspace.data import MotionDataset
    from primspace.train.streaming import FrameStream

    data = MotionDataset.load(path)
    order = torch.randperm(len(data), generator=torch.Generator().manual_seed(0))
    keys = [(order[s : s + batch], None) for s in range(0, len(data), batch)]
    rows = []
    for workers in workers_list:
        stream = FrameStream(data.images, workers, torch.device("cpu"))
        try:
            for _ in stream.batches(keys):  # warm-up: starts the workers
                pass
            stream.waited = stream.decoded = 0.0
            stream.samples = stream.nbytes = 0
            start = time.perf_counter()
            for _ in stream.batches(keys):
                pass
            seconds = time.perf_counter() - start
        finally:
            stream.close()
        rows.append(
            {
                "workers": workers,
                "samples_s": stream.samples / seconds,
                "mb_s": stream.nbytes / seconds / 1e6,
                "decode_ms": 1e3 * stream.decoded / stream.samples,
            }
        )
    return rows


def _timed(counters: dict) -> None:
    """Count the seconds of the collective operations and of each epoch's frame waits (this process)."""
    from torch.distributed.algorithms.ddp_comm_hooks import default_hooks

    from primspace.train import distributed, loop

    for name in ("gather_rows", "sum"):
        original = getattr(distributed.World, name)

        def wrapped(self, *a, _original=original, **kw):
            start = time.perf_counter()
            try:
                return _original(self, *a, **kw)
            finally:
                counters["blocking_comm"] += time.perf_counter() - start

        setattr(distributed.World, name, wrapped)

    def allreduce(state, bucket):
        start = time.perf_counter()

        def done(fut):
            counters["allreduce"] += time.perf_counter() - start
            return fut.value()[0]

        return default_hooks.allreduce_hook(None, bucket).then(done)

    make_ddp = loop.data_parallel

    def data_parallel(*a, **kw):
        model = make_ddp(*a, **kw)
        if hasattr(model, "register_comm_hook"):
            model.register_comm_hook(None, allreduce)
        return model

    loop.data_parallel = data_parallel

    train_epoch = loop.Session._train_epoch

    def epoch(session):
        before = {**counters, "waited": session.stream.waited if session.stream else 0.0}
        out = train_epoch(session)
        after = {**counters, "waited": session.stream.waited if session.stream else 0.0}
        counters["epochs"].append({k: after[k] - before[k] for k in ("waited", "allreduce", "blocking_comm")})
        counters["workers_mb"] = max(counters["workers_mb"], _workers_peak_mb(session.stream))
        return out

    loop.Session._train_epoch = epoch


def _workers_peak_mb(stream) -> float:
    """The largest peak resident memory of the stream's loader workers (forked from the
    forkserver, so not this process's children)."""
    it = None if stream is None else getattr(stream.loader, "_iterator", None)
    peaks = [0.0]
    for worker in getattr(it, "_workers", []):
        try:
            status = Path(f"/proc/{worker.pid}/status").read_text()
        except OSError:
            continue
        peaks += [int(line.split()[1]) / 1024 for line in status.splitlines() if line.startswith("VmHWM:")]
    return max(peaks)


def _train_process(rank: int, size: int, port: int, spec: dict, out: str) -> None:
    """One training process of a configuration; writes its measurements to ``out``-RANK.json."""
    os.environ.update(
        MASTER_ADDR="127.0.0.1",
        MASTER_PORT=str(port),
        RANK=str(rank),
        LOCAL_RANK=str(rank),
        WORLD_SIZE=str(size),
        LOCAL_WORLD_SIZE=str(size),
    )
    torch.set_num_threads(spec["threads"])
    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, configure_process, fit
    from primspace.train.distributed import launched

    counters = {"allreduce": 0.0, "blocking_comm": 0.0, "epochs": [], "workers_mb": 0.0}
    _timed(counters)
    tc = TrainConfig(
        epochs=spec["epochs"],
        batch_size=spec["batch"],
        threads=spec["threads"],
        log_initial=False,
        device=spec["device"],
        stream_frames=spec["stream"],
        loader_workers=spec["workers"],
    )
    configure_process(tc)
    with launched(spec["device"]):
        data = MotionDataset.load(spec["path"])
        run = fit(data, model_config=ModelConfig(latent_dim=40), train_config=tc, progress=False)
    later = [h["seconds"] for h in run.history if h["epoch"] > 1] or [run.history[-1]["seconds"]]
    parts = counters["epochs"][1:] or counters["epochs"]
    result = {
        "epoch_s": statistics.median(later),
        "n": len(data),
        **{k: statistics.median(p[k] for p in parts) for k in ("waited", "allreduce", "blocking_comm")},
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "workers_rss_mb": counters["workers_mb"],
    }
    Path(f"{out}-{rank}.json").write_text(json.dumps(result))


def _train(spec: dict, processes: int, folder: Path) -> list[dict]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = folder / f"train-{len(list(folder.glob('train-*')))}"
    mp.start_processes(_train_process, args=(processes, port, spec, str(out)), nprocs=processes, start_method="spawn")
    return [json.loads(Path(f"{out}-{r}.json").read_text()) for r in range(processes)]


def _data(path: str | None, folder: Path) -> Path:
    if path is not None:
        return Path(path)
    from primspace.sim.generate import generate_dataset

    out = folder / "demo.h5"
    generate_dataset("demo", seed=0, out=out, progress=False, workers=1)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", nargs="?")
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--loader-workers", default="0,1,2")
    parser.add_argument("--processes", default="1,2", help="process counts to train with (gloo on the CPU)")
    parser.add_argument(
        "--train-workers",
        type=int,
        default=None,
        help="loader workers of a streamed training process (default: 1 alone, 0 with several)",
    )
    args = parser.parse_args()
    from primspace.data import MotionDataset

    with tempfile.TemporaryDirectory() as tmp:
        path = _data(args.data, Path(tmp))
        data = MotionDataset.load(path)
        per_sample = data.images.nbytes / len(data)
        print(
            f"{path}: {len(data)} motions, T = {data.length}, frames {data.image_size}, {per_sample / 1e6:.3f} MB "
            f"per motion decoded, {os.path.getsize(path) / len(data) / 1e3:.1f} kB stored; {os.cpu_count()} cores"
        )
        print(f"\nloader (batches of {args.batch}, a pass after a warm-up pass)")
        print(f"{'workers':>8} {'samples/s':>10} {'MB/s':>8} {'decode ms/sample':>17}")
        rates = _loader_rates(path, args.batch, [int(w) for w in args.loader_workers.split(",")])
        for r in rates:
            print(f"{r['workers']:>8} {r['samples_s']:>10.1f} {r['mb_s']:>8.1f} {r['decode_ms']:>17.2f}")
        print(
            f"\ntraining (batch {args.batch}, {args.threads} thread(s) per process, device {args.device}, q = 40, "
            f"median of epochs 2..{args.epochs})"
        )
        print(
            f"{'processes':>9} {'frames':>14} {'epoch s':>8} {'samples/s':>10} {'wait data s':>12} "
            f"{'allreduce s':>12} {'gather+sum s':>13} {'peak MB/proc':>13} {'workers MB':>11} {'100k epoch h':>13}"
        )
        for processes in [int(p) for p in args.processes.split(",")]:
            streamed = args.train_workers if args.train_workers is not None else (0 if processes > 1 else 1)
            for stream, workers in ((False, 0), (True, streamed)):
                spec = dict(
                    path=str(path),
                    epochs=args.epochs,
                    batch=args.batch,
                    threads=args.threads,
                    device=args.device,
                    stream=stream,
                    workers=workers,
                )
                res = _train(spec, processes, Path(tmp))
                epoch = max(r["epoch_s"] for r in res)
                sps = res[0]["n"] / epoch
                mode = f"streamed, {workers} w" if stream else "in memory"
                print(
                    f"{processes:>9} {mode:>14} {epoch:>8.2f} {sps:>10.1f} {max(r['waited'] for r in res):>12.3f} "
                    f"{max(r['allreduce'] for r in res):>12.3f} {max(r['blocking_comm'] for r in res):>13.3f} "
                    f"{max(r['rss_mb'] for r in res):>13.0f} {max(r['workers_rss_mb'] for r in res):>11.0f} "
                    f"{PROJECT_N / sps / 3600:>13.2f}"
                )
        print(
            f"\nat {PROJECT_N} motions the frames take {PROJECT_N * per_sample / 1e9:.1f} GB loaded; the loader "
            f"reads {PROJECT_N / max(r['samples_s'] for r in rates) / 60:.1f} min per pass at its best rate here"
        )


if __name__ == "__main__":
    start = time.perf_counter()
    main()
    print(f"({time.perf_counter() - start:.0f} s)")
