"""One writer per run directory (issue 38, item 2): a second train or infer with --overwrite or
--resume while one writes is refused at once, the lock goes with the process however it ends,
and a checkpoint of another run beside a config is found on load."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from conftest import assert_user_error
from primspace.train import TrainConfig, fit, load_run
from primspace.train.rundir import LOCK_NAME, WriterLock
from primspace.utils.errors import UserError
from test_train import SMALL, primitives

TINY = dict(model_config=SMALL, progress=False)


def test_a_second_writer_is_refused_while_the_first_holds_the_run(tmp_path):
    data = primitives(2, seed=0, T=12, J=2)
    run = tmp_path / "run"
    fit(data, run, train_config=TrainConfig(epochs=1, batch_size=6, final_lr_fraction=1.0), **TINY)
    held = WriterLock(run).acquire()  # another process would hold it the same way
    try:
        for kw in (dict(overwrite=True), dict(resume=True)):
            with pytest.raises(UserError, match="another primspace process .* is writing this run"):
                fit(data, run, train_config=TrainConfig(epochs=2, batch_size=6, final_lr_fraction=1.0), **TINY, **kw)
    finally:
        held.release()
    again = fit(data, run, train_config=TrainConfig(epochs=2, batch_size=6, final_lr_fraction=1.0), resume=True, **TINY)
    assert again.epoch == 2  # released: the resume goes on
    assert (run / LOCK_NAME).is_file() and load_run(run).epoch == 2  # the lock file is not a run file


@pytest.mark.slow
def test_the_lock_goes_with_a_killed_process(tmp_path):
    """A writer killed while training leaves no lock behind: the next run takes the folder."""
    data = primitives(2, seed=0, T=12, J=2)
    path = tmp_path / "d.h5"
    data.save(path)
    run = tmp_path / "run"
    code = (
        "import sys; from primspace.train import TrainConfig, fit; from primspace.data import MotionDataset; "
        "from test_train import SMALL; "
        f"fit(MotionDataset.load({str(path)!r}), {str(run)!r}, model_config=SMALL, progress=False, "
        "train_config=TrainConfig(epochs=100000, batch_size=6, checkpoint_every=1))"
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.path.dirname(__file__), *sys.path]))
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not (run / "checkpoint.pt").is_file() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert (run / "checkpoint.pt").is_file()
        with pytest.raises(UserError, match=rf"pid {proc.pid}"):
            WriterLock(run).acquire()
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    WriterLock(run).acquire().release()  # taken at once: the kernel let go with the process


def test_a_checkpoint_of_another_run_is_found_on_load(run_cli, tmp_path):
    data = primitives(2, seed=0, T=12, J=2)
    a, b = tmp_path / "a", tmp_path / "b"
    fit(data, a, train_config=TrainConfig(epochs=1, batch_size=6), **TINY)
    fit(data, b, train_config=TrainConfig(epochs=1, batch_size=6, seed=5), **TINY)
    os.replace(b / "checkpoint.pt", a / "checkpoint.pt")  # what two writers left behind
    with pytest.raises(UserError, match="belongs to another run than its config.json"):
        load_run(a)
    assert_user_error(run_cli("reconstruct", a, "--sample", "0", "--out", tmp_path / "r.png"), "belongs to another run")
    assert json.loads((a / "config.json").read_text())["train"]["seed"] == 0
