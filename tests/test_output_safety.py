"""No command destroys its input or files it did not write; file-system failures, empty
lists, contradictory flags and damaged results get one line and exit 2.

The cases the review found (issue "Nothing lost, nothing misreported") each have a test
here: `cluster d/lat.npy --out d --overwrite`, `import a.npz --out a.npz --overwrite`,
`infer RUN data.h5 --out RUN --overwrite`, a symlinked --out pointing at an input.
"""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.utils.errors import UserError
from primspace.utils.files import atomic_write_text, check_outside_inputs, remove_stale_temporaries, temp_prefix

TRAIN = ("--layers", "8,4", "--threads", "1", "--batch-size", "4", "--latent-dim", "3", "--no-images")


def _snapshot(folder):
    """Every file under ``folder`` with its bytes: what must survive a refused command."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def npz_file(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "a.npz"
    np.savez(path, motor=rng.normal(size=(6, 12, 3)).astype(np.float32), labels=np.arange(6) % 2)
    return path


@pytest.fixture
def data_file(tmp_path):
    rng = np.random.default_rng(1)
    t = np.linspace(0, 1, 10)
    a = rng.uniform(0.5, 1.5, (8, 1, 1))
    motor = np.concatenate([a * np.sin(4 * t)[None, :, None], a**2 * t[None, :, None]], 2)
    path = tmp_path / "d.h5"
    MotionDataset(motor, labels=np.arange(8) % 2, dt=0.1).save(path)
    return path


@pytest.fixture
def fit_run(run_cli, data_file, tmp_path):
    run = tmp_path / "run"
    res = run_cli("train", data_file, "--epochs", "2", "--out", run, *TRAIN)
    assert res.code == 0, res.err
    return run


# ------------------------------------------------------------------ the three found cases


def test_import_refuses_to_replace_its_source(run_cli, npz_file, tmp_path):
    before = npz_file.read_bytes()
    assert_user_error(run_cli("import", npz_file, "--length", 10, "--out", npz_file, "--overwrite"), "is the input")
    assert npz_file.read_bytes() == before
    link = tmp_path / "link.h5"
    link.symlink_to(npz_file)
    assert_user_error(run_cli("import", npz_file, "--length", 10, "--out", link, "--overwrite"), "is the input")
    assert npz_file.read_bytes() == before and link.is_symlink()


def test_import_into_a_csv_folder_or_onto_a_directory_is_refused(run_cli, tmp_path):
    folder = tmp_path / "csv"
    folder.mkdir()
    (folder / "a.csv").write_text("j0,j1\n0,1\n1,2\n2,3\n")
    assert_user_error(run_cli("import", folder, "--length", 5, "--out", folder / "out.h5"), "lies inside the input")
    target = tmp_path / "target"
    target.mkdir()
    (target / "x").write_text("keep")
    res = run_cli("import", folder, "--format", "csv", "--length", 5, "--out", target, "--overwrite")
    assert_user_error(res, "is a directory")
    assert (target / "x").read_text() == "keep"


def test_infer_refuses_to_write_into_the_trained_run(run_cli, fit_run, data_file, tmp_path):
    before = _snapshot(fit_run)
    for out in (fit_run, fit_run / "new"):
        res = run_cli("infer", fit_run, data_file, "--epochs", "1", "--out", out, "--overwrite", "--threads", "1")
        assert_user_error(res, "input")
    link = tmp_path / "alias"
    link.symlink_to(fit_run, target_is_directory=True)
    assert_user_error(
        run_cli("infer", fit_run, data_file, "--epochs", "1", "--out", link, "--overwrite"), "is the input"
    )
    assert _snapshot(fit_run) == before
    assert json.loads((fit_run / "config.json").read_text())["parent"] is None


def test_train_refuses_its_data_file_or_weights_as_output(run_cli, fit_run, data_file, tmp_path):
    before = data_file.read_bytes()
    assert_user_error(run_cli("train", data_file, "--epochs", "1", "--out", data_file, "--overwrite", *TRAIN), "input")
    assert_user_error(
        run_cli(
            "train", data_file, "--epochs", "1", "--weights-from", fit_run, "--out", fit_run, "--overwrite", *TRAIN
        ),
        "is the input",
    )
    assert data_file.read_bytes() == before


# ------------------------------------------------------------- overwrite replaces only ours


def test_overwrite_of_a_run_keeps_files_it_did_not_write(run_cli, fit_run, data_file):
    (fit_run / "notes.txt").write_text("my notes")
    nested = fit_run / "eval"
    assert (
        run_cli("infer", fit_run, data_file, "--epochs", "1", "--out", nested, "--threads", "1").code == 2
    )  # inside input
    res = run_cli("train", data_file, "--epochs", "1", "--seed", "3", "--out", fit_run, "--overwrite", *TRAIN)
    assert res.code == 0, res.err
    assert (fit_run / "notes.txt").read_text() == "my notes"
    assert json.loads((fit_run / "config.json").read_text())["train"]["seed"] == 3


def test_train_does_not_replace_an_infer_run(run_cli, fit_run, data_file, tmp_path):
    ev = tmp_path / "ev"
    assert run_cli("infer", fit_run, data_file, "--epochs", "1", "--out", ev, "--threads", "1").code == 0
    before = _snapshot(ev)
    assert_user_error(
        run_cli("train", data_file, "--epochs", "1", "--out", ev, "--overwrite", *TRAIN), "is an infer run"
    )
    assert _snapshot(ev) == before


def test_a_run_that_fails_on_its_data_leaves_the_old_run_and_no_new_directory(run_cli, data_file, tmp_path):
    """Found: a corrupted image chunk made `train` leave an empty run directory."""
    import h5py

    bad = tmp_path / "bad.h5"
    rng = np.random.default_rng(0)
    MotionDataset(rng.normal(size=(4, 6, 2)), images=rng.integers(0, 255, (4, 6, 8, 8, 3), dtype=np.uint8)).save(bad)
    with h5py.File(bad, "r") as f:
        info = f["images"].id.get_chunk_info(2)
    with open(bad, "r+b") as fh:
        fh.seek(info.byte_offset)
        fh.write(b"\x00garbage" * max(1, info.size // 8))
    out = tmp_path / "new-run"
    res = run_cli(
        "train", bad, "--epochs", "1", "--out", out, "--layers", "8,4", "--image-channels", "4,4,4", "--threads", "1"
    )
    assert_user_error(res, str(bad), "images", "sample")
    assert not out.exists()


# ------------------------------------------------------------------ contradictions


def test_resume_with_overwrite_or_fewer_epochs_is_refused_more_extends(run_cli, fit_run, data_file):
    before = _snapshot(fit_run)
    assert_user_error(
        run_cli("train", data_file, "--epochs", "3", "--out", fit_run, "--resume", "--overwrite", *TRAIN),
        "give one of them",
    )
    assert_user_error(
        run_cli("train", data_file, "--epochs", "1", "--out", fit_run, "--resume", *TRAIN), "--epochs 2 or more"
    )
    assert _snapshot(fit_run) == before
    res = run_cli("train", data_file, "--epochs", "4", "--out", fit_run, "--resume", *TRAIN)
    assert res.code == 0 and "epoch 4" in res.out, res.err


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--seeds", ""], "--seeds is empty"),
        (["--inits", ""], "--inits is empty"),
        (["--inits", " , "], "--inits is empty"),
        (["--latent-dims", ""], "--latent-dims is empty"),
        (["--workers", "0"], "--workers 0"),
    ],
)
def test_experiment_lists_and_workers_are_refused_alike(run_cli, tmp_path, args, fragment):
    assert_user_error(run_cli("experiment", "intra", "--out", tmp_path / "e", *args), fragment)
    assert not (tmp_path / "e").exists()


@pytest.mark.parametrize("command", [["demo"], ["generate", "--no-images"]])
def test_workers_zero_is_refused_by_every_command(run_cli, tmp_path, command):
    out = tmp_path / ("o.h5" if command[0] == "generate" else "o")
    assert_user_error(run_cli(*command, "--out", out, "--workers", "0"), "--workers 0")
    assert not out.exists()


def test_a_trailing_slash_never_writes_a_file_named_like_the_folder(run_cli, npz_file, data_file, tmp_path):
    for args in (
        ("import", npz_file, "--length", 10, "--out", f"{tmp_path}/newdir/"),
        ("show", data_file, "--out", f"{tmp_path}/newdir/"),
        ("generate", "--no-images", "--out", f"{tmp_path}/newdir/"),
    ):
        assert_user_error(run_cli(*args), "must name a file")
        assert not (tmp_path / "newdir").exists()


def test_reconstruct_checks_the_data_is_the_runs_and_frames(run_cli, fit_run, data_file, tmp_path):
    other = tmp_path / "other.h5"
    ds = MotionDataset.load(data_file)
    MotionDataset(ds.motor * 1.01, labels=ds.labels, dt=ds.dt).save(other)
    assert_user_error(
        run_cli("reconstruct", fit_run, "--sample", 0, "--data", other, "--out", tmp_path / "r.png"), "not its data"
    )
    short = tmp_path / "short.h5"
    MotionDataset(ds.motor[:, :6], dt=ds.dt).save(short)
    assert_user_error(
        run_cli("reconstruct", fit_run, "--sample", 0, "--data", short, "--out", tmp_path / "r.png"), "T=6"
    )
    assert_user_error(
        run_cli("reconstruct", fit_run, "--sample", 0, "--frames", 0, "--out", tmp_path / "r.png"), "--frames 0"
    )
    assert not (tmp_path / "r.png").exists()
    assert run_cli("reconstruct", fit_run, "--sample", 0, "--data", data_file, "--out", tmp_path / "r.png").code == 0


# -------------------------------------------------------------- the file system says no


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_an_unwritable_output_directory_is_one_line(run_cli, npz_file, data_file, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        assert_user_error(run_cli("import", npz_file, "--length", 10, "--out", locked / "o.h5"), "locked")
        assert_user_error(run_cli("cluster", data_file, "--k", 2, "--out", locked / "c"), "locked")
        assert_user_error(run_cli("train", data_file, "--epochs", "1", "--out", locked / "r", *TRAIN), "locked")
    finally:
        locked.chmod(0o700)
    assert list(locked.iterdir()) == []


def test_file_system_errors_are_user_errors_in_the_library(tmp_path):
    """As root the permission test above cannot run; a path through a regular file fails
    for everyone, and must be one UserError naming the path, not an OSError."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(UserError, match="cannot write"):
        atomic_write_text(blocker / "sub" / "o.txt", "y")


def test_outputs_get_the_users_umask(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "a.txt", "x")
        assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o644
        os.umask(0o077)
        atomic_write_text(tmp_path / "b.txt", "x")
        assert stat.S_IMODE((tmp_path / "b.txt").stat().st_mode) == 0o600
    finally:
        os.umask(old)


def test_temporaries_of_a_killed_writer_are_removed_by_the_next_write(tmp_path):
    import subprocess
    import sys

    target = tmp_path / "d.h5"
    # a process that dies while holding a temporary (SIGKILL: no clean-up)
    code = (
        "import os, signal, sys; sys.path[:0] = sys.argv[1:2]\n"
        "from primspace.utils.files import atomic_path\n"
        f"with atomic_path({str(target)!r}) as tmp:\n"
        "    tmp.write_bytes(b'half')\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code, ""], capture_output=True)
    assert proc.returncode == -9
    left = [p.name for p in tmp_path.iterdir()]
    assert len(left) == 1 and left[0].startswith(".d.h5.") and left[0].endswith(".tmp"), left
    # a live writer's temporary is kept
    live = tmp_path / f"{temp_prefix('d.h5')}abc.tmp"
    live.write_text("in use")
    atomic_write_text(target, "done")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["d.h5", live.name])
    assert remove_stale_temporaries(target) == []


def test_check_outside_inputs_compares_resolved_paths(tmp_path):
    (tmp_path / "in").mkdir()
    f = tmp_path / "in" / "x.npy"
    f.write_text("x")
    with pytest.raises(UserError, match="is the input"):
        check_outside_inputs(tmp_path / "in" / ".." / "in" / "x.npy", [f])
    with pytest.raises(UserError, match="contains the input"):
        check_outside_inputs(tmp_path, [f])
    with pytest.raises(UserError, match="lies inside the input"):
        check_outside_inputs(tmp_path / "in" / "out", [tmp_path / "in"])
    check_outside_inputs(tmp_path / "in" / "y.npy", [f, None])  # a sibling is fine


# ----------------------------------------------------------------------- experiments


@pytest.mark.slow
def test_success_on_data_not_from_the_simulator_fails_before_training(run_cli, data_file, tmp_path, grid_only):
    out = tmp_path / "exp"
    res = run_cli("experiment", "success", "--data", data_file, "--out", out)
    assert_user_error(res, str(data_file), "label")
    assert not (out / "runs").exists()
    # `all` runs what these data allow: the success step is left out, with a note
    res = run_cli(
        "experiment",
        "all",
        "--data",
        data_file,
        "--out",
        tmp_path / "exp2",
        "--epochs",
        "2,1",
        "--latent-dims",
        "2",
        "--inits",
        "zero",
        "--workers",
        "1",
    )
    assert res.code == 0, res.err
    assert f"success: skipped, the simulator cannot judge these data ({data_file}" in res.out
    assert (tmp_path / "exp2" / "results" / "intra.json").exists()
    assert not (tmp_path / "exp2" / "results" / "success.json").exists()
    assert not list((tmp_path / "exp2" / "runs").glob("success*"))


def test_experiment_refuses_data_inside_its_output(run_cli, data_file, tmp_path):
    out = tmp_path  # contains d.h5
    assert_user_error(run_cli("experiment", "intra", "--data", data_file, "--out", out), "contains the input")


@pytest.mark.parametrize(
    "content",
    ["{not json", "[1, 2]", json.dumps({"runs": "nope"}), json.dumps({"runs": [{"init": "zero"}]})],
)
def test_report_on_damaged_results_is_one_line(run_cli, tmp_path, content):
    out = tmp_path / "exp"
    (out / "results").mkdir(parents=True)
    (out / "experiment.json").write_text(json.dumps({"preset": "demo", "data": str(tmp_path / "d.h5"), "timings": {}}))
    (out / "results" / "intra.json").write_text(content)
    assert_user_error(run_cli("report", out), "intra.json")
    assert not (out / "report.html").exists()


def test_report_on_a_damaged_experiment_json_is_one_line(run_cli, tmp_path):
    out = tmp_path / "exp"
    out.mkdir()
    (out / "experiment.json").write_text("[]")
    assert_user_error(run_cli("report", out), "experiment.json")
    (out / "experiment.json").write_text("{")
    assert_user_error(run_cli("report", out), "experiment.json")


def test_an_output_path_through_a_file_is_one_line_for_every_writer(run_cli, npz_file, data_file, tmp_path):
    """The file system refusing a write (here: a parent that is a regular file, which fails
    for root too) is one line naming the path, and nothing is left behind."""
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    assert_user_error(run_cli("import", npz_file, "--length", 10, "--out", blocker / "o.h5"), "blocker")
    assert_user_error(run_cli("cluster", data_file, "--k", 2, "--out", blocker / "c"), "blocker")
    assert_user_error(run_cli("train", data_file, "--epochs", "1", "--out", blocker / "r", *TRAIN), "blocker")
    assert_user_error(run_cli("show", data_file, "--out", blocker / "s.png"), "blocker")
    assert blocker.read_text() == "x"


def test_cluster_labels_from_an_npz_archive_is_one_line(run_cli, tmp_path, npz_file):
    np.save(tmp_path / "z.npy", np.random.default_rng(0).normal(size=(6, 3)))
    assert_user_error(
        run_cli("cluster", tmp_path / "z.npy", "--k", 2, "--labels", npz_file, "--out", tmp_path / "c"),
        "a.npz",
        ".npz archive",
    )


def test_experiment_with_zero_epochs_is_refused(run_cli, tmp_path):
    assert_user_error(run_cli("experiment", "intra", "--epochs", "0,0", "--out", tmp_path / "e"), "at least 1")
    assert not (tmp_path / "e").exists()


def test_indices_out_of_range_name_the_index_file_and_the_data(run_cli, data_file, tmp_path):
    (tmp_path / "idx.txt").write_text("0 99\n")
    res = run_cli(
        "train", data_file, "--epochs", "1", "--indices", tmp_path / "idx.txt", "--out", tmp_path / "r", *TRAIN
    )
    assert_user_error(res, "idx.txt", "sample 99", "d.h5")
    assert not (tmp_path / "r").exists()


def test_generate_refuses_a_zero_frame_size_even_without_images(run_cli, tmp_path):
    assert_user_error(run_cli("generate", "--no-images", "--height", 0, "--out", tmp_path / "g.h5"), "height")
    assert not (tmp_path / "g.h5").exists()


@pytest.mark.parametrize("command", ["reconstruct", "animate"])
def test_drawing_a_run_never_writes_over_its_data_file(run_cli, fit_run, data_file, command):
    """The run's data file is an input even when --data is not given (it comes from the run)."""
    before = data_file.read_bytes()
    result = run_cli(command, fit_run, "--sample", 0, "--out", data_file, "--overwrite")
    assert_user_error(result, str(data_file), "is the input")
    assert data_file.read_bytes() == before
