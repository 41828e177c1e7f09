"""Ctrl-C during training: the epoch it comes in is finished and checkpointed, the run says where it
stands; ``resume`` says where it continues from (or that it starts over); a run that did not finish
is refused by ``predict``, ``reconstruct``, ``cluster``, ``infer`` and ``act`` unless
``--allow-unfinished``."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.model.config import ModelConfig
from primspace.train import TrainConfig, fit, load_run
from primspace.train.loop import Session
from primspace.utils.interrupt import Interrupted, deferred_interrupt

TINY = ModelConfig(latent_dim=2, layer_sizes=(8, 4), taus=(2.0, 8.0), p_hidden=8, motor_hidden=8)

needs_sigint = pytest.mark.skipif(
    threading.current_thread() is not threading.main_thread()
    or signal.getsignal(signal.SIGINT) is not signal.default_int_handler,
    reason="SIGINT is handled by Python's default handler in the main thread only",
)


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """6 labelled motions of 8 steps, 2 joints, saved (the commands read a file)."""
    rng = np.random.default_rng(0)
    motor = np.cumsum(rng.normal(0, 0.1, (6, 8, 2)), axis=1).astype(np.float32)
    path = tmp_path_factory.mktemp("interrupt") / "d.h5"
    MotionDataset(motor, labels=np.arange(6) % 2, label_names=["reach", "push"], dt=0.1).save(path)
    return path


def _tc(**kw) -> TrainConfig:
    # a constant rate, checkpoints only at epoch 0 and at the end (unless Ctrl-C)
    return TrainConfig(**{"epochs": 6, "batch_size": 3, "threads": 1, "final_lr_fraction": 1.0, **kw})


def _fit(data: Path, out, **kw):
    return fit(MotionDataset.load(data), out, model_config=TINY, progress=kw.pop("progress", False), **kw)


def _sigint_after_epoch(monkeypatch, epoch: int) -> None:
    """Ctrl-C once, right after the first run to end ``epoch`` ends it (before the loop looks at the next)."""
    original = Session.end_epoch
    pressed = []

    def end_then_sigint(self, sums, seconds):
        line = original(self, sums, seconds)
        if self.epoch == epoch and not pressed:
            pressed.append(True)
            signal.raise_signal(signal.SIGINT)
        return line

    monkeypatch.setattr(Session, "end_epoch", end_then_sigint)


@needs_sigint
def test_the_first_ctrl_c_is_noted_the_second_raises(capsys):
    with deferred_interrupt("stopping after this step") as stop:
        signal.raise_signal(signal.SIGINT)
        assert stop.requested
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGINT)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert "Ctrl-C: stopping after this step (Ctrl-C again to stop at once)" in capsys.readouterr().err


def test_disabled_deferral_leaves_ctrl_c_alone():
    with deferred_interrupt("never said", enabled=False) as stop:
        assert signal.getsignal(signal.SIGINT) is not None
        assert not stop.requested


@needs_sigint
def test_ctrl_c_checkpoints_its_epoch_and_resume_continues_exactly(data, tmp_path, monkeypatch, capsys):
    straight = _fit(data, tmp_path / "straight", train_config=_tc())
    _sigint_after_epoch(monkeypatch, 3)
    with pytest.raises(Interrupted, match=r"stopped after epoch 3 of 6, checkpoint written; continue it with resume"):
        _fit(data, tmp_path / "run", train_config=_tc())
    monkeypatch.undo()
    stopped = load_run(tmp_path / "run")
    assert stopped.epoch == 3 and not stopped.finished
    logged = [json.loads(line)["epoch"] for line in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert logged == [0, 1, 2, 3]  # nothing to drop on resume
    capsys.readouterr()
    resumed = _fit(data, tmp_path / "run", train_config=_tc(), resume=True, progress=None)
    err = capsys.readouterr().err
    assert "resuming from epoch 3 of 6" in err and "dropped" not in err
    assert resumed.finished
    assert [h["loss"] for h in resumed.history] == [h["loss"] for h in straight.history]
    np.testing.assert_array_equal(resumed.latents, straight.latents)
    for name, tensor in straight.model.state_dict().items():
        assert torch.equal(tensor, resumed.model.state_dict()[name]), name


@needs_sigint
def test_ctrl_c_on_a_run_in_memory_stops_at_once(data, monkeypatch):
    """Nothing to save: no epoch is waited for."""
    _sigint_after_epoch(monkeypatch, 1)
    with pytest.raises(KeyboardInterrupt) as stopped:
        _fit(data, None, train_config=_tc())
    assert not isinstance(stopped.value, Interrupted)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_resume_says_where_it_continues_and_what_it_dropped(data, tmp_path, capsys):
    _fit(data, tmp_path / "run", train_config=_tc(epochs=2))
    with open(tmp_path / "run" / "metrics.jsonl", "a") as f:  # as if killed after logging epoch 3
        f.write(json.dumps({"epoch": 3, "loss": 9.0, "motor": 9.0, "vision": None}) + "\n")
    capsys.readouterr()
    _fit(data, tmp_path / "run", train_config=_tc(epochs=3), resume=True, progress=None)
    err = capsys.readouterr().err
    assert "resuming from epoch 2 of 3; 1 epoch(s) logged after that checkpoint dropped from metrics.jsonl" in err


def test_a_run_folder_named_after_its_kind_is_named_with_its_parent(data, tmp_path, capsys):
    _fit(data, tmp_path / "runs" / "fit", train_config=_tc(epochs=1))
    capsys.readouterr()
    _fit(data, tmp_path / "runs" / "fit", train_config=_tc(epochs=2), resume=True, progress=None)
    assert "fit runs/fit: resuming from epoch 1 of 2" in capsys.readouterr().err  # not "fit fit"


def test_resume_without_a_checkpoint_says_it_starts_over(data, tmp_path, capsys):
    capsys.readouterr()
    run = _fit(data, tmp_path / "new", train_config=_tc(epochs=1), resume=True, progress=None)
    assert "no checkpoint to resume from: starting from epoch 0" in capsys.readouterr().err
    assert run.epoch == 1


@pytest.fixture(scope="module")
def unfinished(data, tmp_path_factory) -> Path:
    """A run stopped (KeyboardInterrupt) right after its epoch-2 checkpoint, of 5 epochs."""
    out = tmp_path_factory.mktemp("unfinished") / "run"
    original = Session._checkpoint

    def checkpoint_then_die(self):
        original(self)
        if self.epoch == 2:
            raise KeyboardInterrupt

    Session._checkpoint = checkpoint_then_die
    try:
        with pytest.raises(KeyboardInterrupt):
            _fit(data, out, train_config=_tc(epochs=5, checkpoint_every=1))
    finally:
        Session._checkpoint = original
    return out


@pytest.mark.parametrize(
    "command",
    [
        ["predict", "{run}", "{data}", "--out", "{out}"],
        ["reconstruct", "{run}", "--sample", "0", "--out", "{out}.png"],
        ["cluster", "{run}", "--primitives", "2", "--out", "{out}"],
        ["infer", "{run}", "{data}", "--out", "{out}"],
        ["act", "{run}", "--primitive", "push", "--scene", "0.5,0,0.05", "--out", "{out}"],
    ],
)
def test_an_unfinished_run_is_refused_in_one_line(run_cli, unfinished, data, tmp_path, command):
    args = [a.format(run=unfinished, data=data, out=tmp_path / "o") for a in command]
    res = run_cli(*args)
    assert_user_error(res, f"{unfinished}: stopped after epoch 2 of 5", "--resume", "--allow-unfinished")
    assert not any(tmp_path.iterdir())


def test_allow_unfinished_uses_it(run_cli, unfinished, tmp_path):
    res = run_cli("cluster", unfinished, "--primitives", "2", "--out", tmp_path / "c", "--allow-unfinished")
    assert res.code == 0, res.err
    assert (tmp_path / "c" / "result.json").is_file()
    res = run_cli("reconstruct", unfinished, "--sample", "0", "--out", tmp_path / "r.png", "--allow-unfinished")
    assert res.code == 0, res.err
    assert (tmp_path / "r.png").is_file()


@pytest.mark.slow
def test_ctrl_c_on_the_command_line_checkpoints_and_resume_says_so(run_cli, data, tmp_path):
    """`primspace train` in its own process, sent SIGINT once 3 epochs are logged: exit 130, one
    line saying where it stopped; the checkpoint holds that epoch; `--resume` says it resumes there."""
    out = tmp_path / "run"
    flags = ["--layers", "8,4", "--latent-dim", "2", "--batch-size", "3", "--threads", "1"]
    args = [sys.executable, "-m", "primspace", "train", str(data), "--out", str(out), "--epochs", "100000", *flags]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    # SIGINT as a terminal delivers it: a test process that ignores SIGINT (as some test runners' workers,
    # or a library they loaded, do) would pass the ignore on to the command, which then never sees Ctrl-C
    proc = subprocess.Popen(
        args + ["--checkpoint-seconds", "100000"],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        metrics = out / "metrics.jsonl"
        for _ in range(6000):  # until 3 epochs are logged (or the process ended)
            if proc.poll() is not None or (metrics.is_file() and len(metrics.read_text().splitlines()) >= 4):
                break
            threading.Event().wait(0.05)
        assert proc.poll() is None, proc.stderr.read()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    last = err.strip().splitlines()[-1]
    done = json.loads(metrics.read_text().splitlines()[-1])["epoch"]
    assert last == (
        f"primspace: error: interrupted: fit {out.name}: stopped after epoch {done} of 100000, checkpoint written; "
        "continue it with --resume, --epochs 100000"
    )
    assert load_run(out).epoch == done >= 3
    res = run_cli("train", data, "--out", out, "--epochs", str(done + 1), "--resume", *flags)
    assert res.code == 0, res.err
    assert f"fit {out.name}: resuming from epoch {done} of {done + 1}" in res.err


@needs_sigint
def test_ctrl_c_stops_packed_runs_after_their_epoch_with_their_checkpoints(data, tmp_path, monkeypatch):
    from primspace.train.packed import fit_packed

    ds = MotionDataset.load(data)
    jobs = [
        dict(dataset=ds, out_dir=tmp_path / name, model_config=TINY, train_config=_tc(seed=seed), init=init)
        for name, seed, init in (("a", 0, "projection"), ("b", 1, "zero"))
    ]
    _sigint_after_epoch(monkeypatch, 2)  # in the first run's end of epoch 2: the second still ends it
    with pytest.raises(
        Interrupted, match=r"fit 2 runs packed: stopped after epoch 2 of 6, checkpoints written; continue"
    ):
        fit_packed(jobs, progress=False)
    monkeypatch.undo()
    assert [load_run(tmp_path / name).epoch for name in ("a", "b")] == [2, 2]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
