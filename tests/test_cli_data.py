"""End to end: `primspace import` + `primspace info`, and bad input on the command line."""

import json
import os
import subprocess
import sys

import numpy as np

from conftest import assert_user_error
from primspace.data import MotionDataset


def test_import_lasa_then_info(run_cli, tmp_path):
    out = tmp_path / "lasa.h5"
    res = run_cli("import", "--format", "lasa", "--length", "64", "--shapes", "Sine,Angle,CShape", "--out", out)
    assert res.code == 0, res.err
    assert "21 samples x 64 steps x 2 joints" in res.out
    ds = MotionDataset.load(out)
    assert ds.label_names == ["Sine", "Angle", "CShape"] and ds.motor.shape == (21, 64, 2)

    res = run_cli("info", out)
    assert res.code == 0
    assert "samples  21" in res.out and "Sine 7" in res.out and "joint ranges" in res.out

    res = run_cli("info", out, "--json")
    info = json.loads(res.out)
    assert info["n_samples"] == 21 and info["length"] == 64 and info["joint_names"] == ["x", "y"]
    assert info["label_counts"] == {"Sine": 7, "Angle": 7, "CShape": 7}
    lo, hi = info["joint_ranges"]["x"]
    assert lo == float(ds.motor[..., 0].min()) and hi == float(ds.motor[..., 0].max())


def test_import_refuses_existing_output_and_keeps_it(run_cli, tmp_path):
    out = tmp_path / "d.h5"
    out.write_bytes(b"precious")
    res = run_cli("import", "--format", "lasa", "-T", "10", "--out", out)
    assert_user_error(res, str(out), "--overwrite")
    assert out.read_bytes() == b"precious"
    # --overwrite replaces only an earlier output of the same command (issue 24): not a user's file
    assert_user_error(run_cli("import", "--format", "lasa", "-T", "10", "--out", out, "--overwrite"), str(out))
    assert out.read_bytes() == b"precious"
    out.unlink()
    assert run_cli("import", "--format", "lasa", "-T", "10", "--out", out).code == 0
    res = run_cli("import", "--format", "lasa", "-T", "10", "--shapes", "Sine", "--out", out, "--overwrite")
    assert res.code == 0 and len(MotionDataset.load(out)) == 7


def test_bad_npz_is_one_line_and_leaves_no_output(run_cli, tmp_path):
    src = tmp_path / "bad.npz"
    np.savez(src, np.zeros((5, 2)), np.full((4, 2), np.inf))
    out = tmp_path / "out.h5"
    res = run_cli("import", src, "--length", "10", "--out", out)
    assert_user_error(res, "bad.npz", "field 'motor'", "sample 1", "NaN or inf")
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["bad.npz"]


def test_cli_argument_errors(run_cli, tmp_path):
    assert_user_error(
        run_cli("import", "--format", "npz", "-T", "10", "--out", tmp_path / "o.h5"), "needs a source path"
    )
    assert_user_error(
        run_cli("import", tmp_path / "x.txt", "-T", "10", "--out", tmp_path / "o.h5"), "cannot tell the format"
    )
    assert_user_error(
        run_cli("import", "--format", "lasa", "-T", "10", "--shapes", "Nope", "--out", tmp_path / "o.h5"),
        "unknown LASA shape",
    )
    assert run_cli("import", "--format", "tar", "-T", "10", "--out", tmp_path / "o.h5").code == 2  # click's usage error
    assert not (tmp_path / "o.h5").exists()


def test_installed_entry_point_runs_as_a_process(tmp_path):
    """`python -m primspace` in a real process: exit codes and stderr as a user sees them."""
    env = dict(os.environ)
    bad = tmp_path / "notes.h5"
    bad.write_text("not hdf5")
    proc = subprocess.run(
        [sys.executable, "-m", "primspace", "info", str(bad)], capture_output=True, text=True, env=env
    )
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert proc.stderr.startswith(f"primspace: error: {bad}: not a readable HDF5 file")
    assert proc.stdout == ""
