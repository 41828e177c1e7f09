"""`act` checks its options before any work (the run is read and the policy fitted only after):
each refusal here is one line, exit 2, while the run given does not even exist."""

from __future__ import annotations

import pytest

from conftest import assert_user_error


@pytest.mark.parametrize(
    ("flags", "fragments"),
    [
        (["--scene", "0.5,0,nope"], ["--scene", "x,y,size"]),
        (["--scene", "0.9,0,0.05"], ["block_x", "workspace"]),
        (["--scene", "scenes.h5"], ["--scene", "FILE:INDEX"]),
        (["--scene", "missing.h5:3"], ["missing.h5", "no such file"]),
        (["--scene", "0.5,0,0.05", "--every", "0"], ["re-planning interval", "0"]),
    ],
)
def test_act_refuses_its_options_before_reading_the_run(run_cli, tmp_path, monkeypatch, flags, fragments):
    monkeypatch.chdir(tmp_path)
    res = run_cli("act", tmp_path / "run", "--primitive", "push", *flags, "--out", tmp_path / "o")
    assert_user_error(res, *fragments)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_act_names_its_own_flag_for_the_fitted_data(run_cli, tmp_path):
    """A run whose data file moved: act says to give it with --data (act has no --fitted-data)."""
    import numpy as np

    from primspace.data import MotionDataset

    data = tmp_path / "d.h5"
    motor = np.random.default_rng(0).normal(size=(4, 6, 2)).astype(np.float32)
    MotionDataset(motor, labels=np.arange(4) % 2, dt=0.1).save(data)
    run = tmp_path / "run"
    train = ("--epochs", "1", "--layers", "4,2", "--latent-dim", "2", "--batch-size", "4", "--threads", "1")
    assert run_cli("train", data, "--out", run, *train).code == 0
    data.unlink()
    res = run_cli("act", run, "--primitive", "0", "--scene", "0.5,0,0.05", "--out", tmp_path / "o")
    assert_user_error(res, "d.h5", "--data PATH")
    assert "--fitted-data" not in res.err and not (tmp_path / "o").exists()
