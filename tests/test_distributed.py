"""One model trained by two processes (issue 28, items 2-3): gloo on the CPU, launched by
``torch.multiprocessing`` (the library's path, once for every check) and by ``torchrun``
(the command line).

Two processes give the numbers of one process that computes each batch in the same two
parts (``micro_batches=2``), bit for bit: each part's backward pass is the single
process's times a power of two, and the reduction adds two addends (docs/scale.md). A
single process that computes each batch at once sums the samples' gradients in another
order, so it agrees to rounding only (checked within a tolerance).
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.multiprocessing as mp

from primspace.data import MotionDataset
from primspace.train import TrainConfig, TrainingDivergedError, fit, infer, load_run
from primspace.train.distributed import World, part_bounds
from test_streaming import numbers, same_state
from test_train import primitives
from test_vision_frames import SMALL

pytestmark = pytest.mark.usefixtures("one_thread_each")  # one thread per test, as the processes (tests/conftest.py)

# 13 samples in batches of 4: the last batch has one sample, so one process has none
BASE = dict(epochs=2, batch_size=4, threads=1, seed=0, checkpoint_every=1, final_lr_fraction=1.0)  # resumed to 3 below
IMAGES = dict(BASE, vision_frames=3, loss_reduction="sum")
MOTOR_ONLY = dict(BASE, vision_weight=0.0)  # the model has an image head, its loss is not trained
PRECISION = dict(BASE, vision_frames=3, loss_reduction="precision")  # learned log-variances in the decoder
INFER_ROWS = [0, 4, 5, 9, 12]
DEADLINE = 300  # seconds for both processes, start to end


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _process(rank: int, port: int, folder: str) -> None:
    """What each of the two processes runs (a launcher's environment, then every check)."""
    os.environ.update(
        MASTER_ADDR="127.0.0.1",
        MASTER_PORT=str(port),
        RANK=str(rank),
        LOCAL_RANK=str(rank),
        WORLD_SIZE="2",
        LOCAL_WORLD_SIZE="2",
    )
    torch.set_num_threads(1)
    from primspace.train.distributed import launched

    folder = Path(folder)
    ds = MotionDataset.load(folder / "data.h5")
    out = {}
    with launched("cpu", timeout_minutes=2):
        run = fit(
            ds,
            folder / "run",
            model_config=SMALL,
            train_config=TrainConfig(**IMAGES, stream_frames=True, loader_workers=0),
            progress=False,
        )
        out["fit"], out["fit_history"] = run.state, numbers(run.history)
        motor = fit(ds, model_config=SMALL, train_config=TrainConfig(**MOTOR_ONLY), progress=False)
        out["motor"], out["motor_history"] = motor.state, numbers(motor.history)
        inferred = infer(run, ds, epochs=2, indices=INFER_ROWS, progress=False)
        out["infer"] = inferred.state
        out["precision"] = fit(ds, model_config=SMALL, train_config=TrainConfig(**PRECISION), progress=False).state
        try:
            fit(ds, model_config=SMALL, train_config=TrainConfig(**{**BASE, "lr": 1e30}), progress=False)
        except TrainingDivergedError as exc:
            out["diverged"] = str(exc)
    torch.save(out, folder / f"rank{rank}.pt")


@pytest.fixture(scope="module")
def two_processes(tmp_path_factory):
    """Both processes' results (each a dict of checkpoint states), and their folder."""
    folder = tmp_path_factory.mktemp("ddp")
    primitives(5, seed=0, T=12, images=True).subset(np.arange(13)).save(folder / "data.h5")
    context = mp.start_processes(_process, args=(_free_port(), str(folder)), nprocs=2, join=False, start_method="spawn")
    start = time.monotonic()
    try:
        while not context.join(timeout=5):  # a failing process ends the other (ProcessRaisedException)
            if time.monotonic() - start > DEADLINE:
                pytest.fail(f"the two processes did not finish in {DEADLINE} s")
    finally:
        for p in context.processes:
            if p.is_alive():
                p.kill()
    ranks = [torch.load(folder / f"rank{r}.pt", weights_only=False) for r in range(2)]
    return ranks, folder


@pytest.mark.slow
def test_the_processes_hold_the_same_model_and_codes(two_processes):
    (a, b), _ = two_processes
    for key in ("fit", "motor", "infer"):
        assert same_state(a[key], b[key]), key
    assert a["fit_history"] == b["fit_history"]


@pytest.mark.slow
def test_two_processes_give_the_numbers_of_two_parts_in_one_bit_for_bit(two_processes):
    """Uneven batches (13 samples, batches of 4: the last one leaves a process empty),
    streamed frames with K drawn per sequence, the paper's summed loss."""
    (ddp, _), folder = two_processes
    ds = MotionDataset.load(folder / "data.h5")
    one = fit(ds, model_config=SMALL, train_config=TrainConfig(**IMAGES, micro_batches=2), progress=False)
    assert same_state(one.state, ddp["fit"])
    assert numbers(one.history) == ddp["fit_history"]
    inferred = infer(one, ds, epochs=2, indices=INFER_ROWS, micro_batches=2, progress=False)
    assert same_state(inferred.state, ddp["infer"])


@pytest.mark.slow
def test_motor_only_training_with_an_unused_image_head(two_processes):
    (ddp, _), folder = two_processes
    ds = MotionDataset.load(folder / "data.h5")
    one = fit(ds, model_config=SMALL, train_config=TrainConfig(**MOTOR_ONLY, micro_batches=2), progress=False)
    assert same_state(one.state, ddp["motor"])
    assert (
        ddp["motor_history"][-1]["vision"] is None
        and ddp["motor_history"][-1]["loss"] < ddp["motor_history"][0]["loss"]
    )


@pytest.mark.slow
def test_learned_precisions_train_in_two_processes_as_in_two_parts(two_processes):
    (ddp, other), folder = two_processes
    ds = MotionDataset.load(folder / "data.h5")
    one = fit(ds, model_config=SMALL, train_config=TrainConfig(**PRECISION, micro_batches=2), progress=False)
    assert same_state(one.state, ddp["precision"]) and same_state(other["precision"], ddp["precision"])
    assert float(one.model.precision.raw.detach().abs().min()) > 0  # they trained


@pytest.mark.slow
def test_one_process_at_once_agrees_within_rounding(two_processes):
    """Summing the samples' gradients in one pass changes only the rounding: after two
    epochs the codes and weights agree to 1e-4 relative (float32 sums of a few dozen
    terms in another order, carried through Adam's division by sqrt(v))."""
    (ddp, _), folder = two_processes
    ds = MotionDataset.load(folder / "data.h5")
    one = fit(ds, model_config=SMALL, train_config=TrainConfig(**IMAGES), progress=False)
    torch.testing.assert_close(one.state["latents"]["codes"], ddp["fit"]["latents"]["codes"], rtol=1e-4, atol=1e-5)
    for name, value in one.state["model"].items():
        torch.testing.assert_close(value, ddp["fit"]["model"][name], rtol=1e-4, atol=1e-5)
    for mine, theirs in zip(numbers(one.history), ddp["fit_history"], strict=True):
        assert mine == pytest.approx(theirs, rel=1e-4)


@pytest.mark.slow
def test_a_checkpoint_of_two_processes_resumes_in_one(two_processes, tmp_path):
    """The run directory written by process 0 is today's format; one process continues it
    exactly as two would (the same batch order, the same frame draws)."""
    (ddp, _), folder = two_processes
    ds = MotionDataset.load(folder / "data.h5")
    run = shutil.copytree(folder / "run", tmp_path / "run")
    assert load_run(run).epoch == 2
    more = TrainConfig(**{**IMAGES, "epochs": 3, "micro_batches": 2})
    resumed = fit(ds, run, model_config=SMALL, train_config=more, resume=True, progress=False)
    straight = fit(ds, model_config=SMALL, train_config=more, progress=False)
    assert same_state(resumed.state, straight.state)
    assert [h["epoch"] for h in resumed.history] == [0, 1, 2, 3]


@pytest.mark.slow
def test_a_divergence_stops_every_process(two_processes):
    (a, b), _ = two_processes
    assert "became" in a["diverged"] and a["diverged"] == b["diverged"]


def test_parts_split_a_batch_without_padding():
    assert part_bounds(5, 2) == [(0, 3), (3, 5)] and part_bounds(1, 2) == [(0, 1), (1, 1)]
    first, second = World(0, 2).parts(1, join=True), World(1, 2).parts(1, join=True)
    assert first[0].rows == slice(0, 1) and first[0].weight == 2.0 and not first[0].dummy
    assert second[0].dummy and second[0].weight == 0.0 and World(1, 2).parts(1) == []
    one = World(micro_batches=2).parts(5)
    assert [p.rows for p in one] == [slice(0, 3), slice(3, 5)] and [p.weight for p in one] == [0.6, 0.4]


@pytest.mark.skipif(shutil.which("torchrun", path=os.path.dirname(sys.executable)) is None, reason="no torchrun")
@pytest.mark.slow
def test_torchrun_launches_the_command(two_processes, tmp_path):
    _, folder = two_processes
    torchrun = os.path.join(os.path.dirname(sys.executable), "torchrun")
    args = [
        torchrun,
        "--nproc-per-node",
        "2",
        "--master-port",
        str(_free_port()),
        "-m",
        "primspace",
        "train",
        str(folder / "data.h5"),
        "--out",
        str(tmp_path / "run"),
        "--device",
        "cpu",
        "--no-images",
        "--layers",
        "12,6",
        "--latent-dim",
        "3",
        "--batch-size",
        "4",
        "--epochs",
        "2",
        "--threads",
        "1",
    ]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    done = subprocess.run(args, capture_output=True, text=True, timeout=DEADLINE, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.count("wrote ") == 1  # one summary, from process 0
    assert load_run(tmp_path / "run").epoch == 2
    again = subprocess.run(args, capture_output=True, text=True, timeout=DEADLINE, env=env)
    assert again.returncode != 0 and "--resume" in again.stderr  # a user error stops both processes
