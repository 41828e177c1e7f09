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
