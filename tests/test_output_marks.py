"""No command replaces a file it did not write (issue 24, items 1-4).

1. Two writers, one output: the second fails with one line, the first's output intact
   (exclusive publish: a target that appears meanwhile is never replaced).
2. ``experiment`` refuses a non-empty folder that is not an experiment directory, before
   writing anything.
3. ``--overwrite`` replaces only an earlier output of the same command, recognised by the
   mark primspace writes into it (PNG text chunk, GIF comment, HDF5 attribute, a run's or
   a cluster output's own files, a summary's ``summary_version``).
4. An existing empty output folder is written into in place (never swapped for a new
   one), or refused with one line when it is not writable.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.utils.errors import OutputExistsError
from test_output_safety import data_file  # noqa: F401 (the shared fixture: a small motor-only data set)

TRAIN = ("--layers", "8,4", "--threads", "1", "--batch-size", "4", "--latent-dim", "3", "--no-images")


def _snapshot(folder):
    """Every entry under ``folder`` (files with their bytes): what a refused command must leave."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


def _npz(path, seed):
    rng = np.random.default_rng(seed)
    np.savez(path, motor=rng.normal(size=(6, 12, 3)).astype(np.float32), labels=np.arange(6) % 2)
    return path


@pytest.fixture
def npz_pair(tmp_path):
    return _npz(tmp_path / "a.npz", 0), _npz(tmp_path / "b.npz", 1)


@pytest.fixture
def points(tmp_path):
    rng = np.random.default_rng(0)
    x = np.vstack([rng.normal(size=8) + rng.normal(size=(12, 2)) @ rng.normal(size=(2, 8)) for _ in range(3)])
    np.save(tmp_path / "z.npy", x)
    return tmp_path / "z.npy"


@pytest.fixture
def fit_run(run_cli, data_file, tmp_path):
    run = tmp_path / "runs" / "other"
    res = run_cli("train", data_file, "--epochs", "2", "--out", run, *TRAIN)
    assert res.code == 0, res.err
    return run


# ------------------------------------------------------------ 1. two writers, one output


def test_an_import_whose_output_appears_meanwhile_fails_and_keeps_it(run_cli, npz_pair, tmp_path, monkeypatch):
    """`import a.npz --out o/c.h5 & import b.npz --out o/c.h5`: the one that finishes
    second must not replace the first's file (found: both printed "wrote o/c.h5")."""
    from primspace.cli import main
    from primspace.data.storage import DatasetWriter

    a, b = npz_pair
    out = tmp_path / "o" / "c.h5"
    first = {}
    original = DatasetWriter.write

    def write_while_another_publishes(self, *args, **kwargs):
        if not first:  # the other writer publishes while this one is writing its temporary file
            first["started"] = True
            with _no_exit():
                main(["import", str(b), "-T", "30", "--out", str(out)])
            first["bytes"] = out.read_bytes()
        return original(self, *args, **kwargs)

    monkeypatch.setattr(DatasetWriter, "write", write_while_another_publishes)
    res = run_cli("import", a, "-T", "30", "--out", out)
    assert_user_error(res, str(out), "--overwrite")
    assert out.read_bytes() == first["bytes"]
    assert sorted(p.name for p in out.parent.iterdir()) == ["c.h5"]  # no temporary left


class _no_exit:
    """Run a nested ``main`` that exits 0 (returns) or fails the test."""

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        if kind is SystemExit:
            raise AssertionError(f"the nested command exited {exc.code}")
        return False


@pytest.mark.slow
def test_two_import_processes_into_one_output_one_wins(npz_pair, tmp_path):
    """Two `primspace import` processes started together: whatever the interleaving, one
    exits 0, the other exits 2 with one line, and the file is the winner's."""
    a, b = npz_pair
    out = tmp_path / "o" / "c.h5"
    env = dict(os.environ, MUJOCO_GL="egl")
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "primspace", "import", str(src), "-T", "30", "--out", str(out)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for src in (a, b)
    ]
    results = [(p.wait(timeout=120), p.stdout.read(), p.stderr.read()) for p in procs]
    codes = sorted(r[0] for r in results)
    assert codes == [0, 2], results
    winner = next(i for i, r in enumerate(results) if r[0] == 0)
    loser = results[1 - winner]
    assert len(loser[2].strip().splitlines()) == 1 and str(out) in loser[2], loser
    got = MotionDataset.load(out).motor
    src = np.load((a, b)[winner])["motor"]
    assert got.shape == (6, 30, 3)
    assert np.allclose(got[:, 0], src[:, 0], atol=1e-5) and np.allclose(got[:, -1], src[:, -1], atol=1e-5)
    assert sorted(p.name for p in out.parent.iterdir()) == ["c.h5"]


def test_a_cluster_output_that_appears_meanwhile_is_not_merged_into(run_cli, points, tmp_path, monkeypatch):
    """Two `cluster` runs into one --out: found, the second merged its files over the first's."""
    from primspace.cli import main
    from primspace.cluster import outputs

    out = tmp_path / "c"
    original = outputs.write_labels_csv
    before = {}

    def write_while_another_publishes(*args, **kwargs):
        if not before:  # the other run publishes while this one writes its temporary folder
            before["started"] = True
            with _no_exit():
                main(["cluster", str(points), "--k", "2", "--out", str(out)])
            before.update(_snapshot(out))
        return original(*args, **kwargs)

    monkeypatch.setattr(outputs, "write_labels_csv", write_while_another_publishes)
    assert_user_error(run_cli("cluster", points, "--k", 3, "--out", out), str(out), "--overwrite")
    del before["started"]
    assert _snapshot(out) == before and json.loads((out / "result.json").read_text())["n_clusters"] == 2
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_atomic_path_never_replaces_a_target_that_appears_meanwhile(tmp_path, monkeypatch):
    """The library's exclusive publish, with renameat2 and with its fallbacks (hard link;
    an exclusively created placeholder)."""
    from primspace.utils import files

    fallbacks = [None, "link", "placeholder"]
    for mode in fallbacks:
        target = tmp_path / f"t-{mode}.txt"
        if mode is not None:
            monkeypatch.setattr(files, "_renameat2", lambda: None)
        if mode == "placeholder":
            monkeypatch.setattr(files.os, "link", _no_link)
        with pytest.raises(OutputExistsError, match="--overwrite"):
            with files.atomic_path(target, overwrite=False) as tmp:
                tmp.write_text("second")
                target.write_text("first")  # another writer publishes meanwhile
        assert target.read_text() == "first"
        target.unlink()
        with files.atomic_path(target, overwrite=False) as tmp:
            tmp.write_text("alone")
        assert target.read_text() == "alone"
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"t-{m}.txt" for m in fallbacks]


def test_atomic_directory_publishes_without_replacing_and_never_mixes_two_writers(tmp_path, monkeypatch):
    """A new folder is renamed into place (renameat2, or mkdir + moves without it); a
    folder that appears meanwhile is re-checked, never replaced; an empty folder is filled
    in place, and if another writer's file lands there first, ours are taken back."""
    from pathlib import Path

    from primspace.cluster.outputs import CLUSTER_OUTPUT
    from primspace.utils import files
    from primspace.utils.folders import atomic_directory

    for fallback in (False, True):
        if fallback:
            monkeypatch.setattr(files, "_renameat2", lambda: None)
        new = tmp_path / f"new-{fallback}"
        with atomic_directory(new, False, CLUSTER_OUTPUT) as tmp:
            (tmp / "result.json").write_text("{}")
        assert (new / "result.json").read_text() == "{}"
        late = tmp_path / f"late-{fallback}"
        with pytest.raises(OutputExistsError):
            with atomic_directory(late, False, CLUSTER_OUTPUT) as tmp:
                (tmp / "labels.csv").write_text("mine")
                late.mkdir()
                (late / "theirs.txt").write_text("theirs")
        assert _snapshot(late) == {"theirs.txt": b"theirs"}

    empty = tmp_path / "empty"
    empty.mkdir()
    inode = empty.stat().st_ino
    real, calls = files.rename_noreplace, []

    def another_writer_lands_second(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            Path(dst).write_text("theirs")
        return real(src, dst)

    monkeypatch.setattr(files, "rename_noreplace", another_writer_lands_second)
    with pytest.raises(OutputExistsError):
        with atomic_directory(empty, False, CLUSTER_OUTPUT) as tmp:
            for name in ("clustering.png", "labels.csv", "result.json"):
                (tmp / name).write_text("mine")
    assert _snapshot(empty) == {"labels.csv": b"theirs"} and empty.stat().st_ino == inode
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def _no_link(src, dst, **kwargs):
    raise PermissionError(1, "Operation not permitted", str(dst))


# ----------------------------------------------------- 2. experiment into a foreign folder


@pytest.mark.parametrize(
    "user_files",
    [
        {"report.html": b"<p>mine</p>", "figures/composite_loss_fit.png": b"\x89PNG mine"},
        {"results/data.json": b'{"mine": true}'},
    ],
)
def test_experiment_refuses_a_folder_that_is_not_an_experiment_before_writing(run_cli, data_file, tmp_path, user_files):
    out = tmp_path / "u"
    for name, content in user_files.items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_bytes(content)
    before = _snapshot(out)
    res = run_cli(
        "experiment",
        "intra",
        "--data",
        data_file,
        "--out",
        out,
        "--epochs",
        "1,1",
        "--latent-dims",
        "2",
        "--inits",
        "zero",
        "--seeds",
        "0",
        "--workers",
        "1",
    )
    assert_user_error(res, str(out), "not an experiment directory", "experiment.json")
    assert _snapshot(out) == before


# ------------------------------------------------------ 3. --overwrite: only our own output


def test_overwrite_refuses_a_data_set_another_runs_checkpoint_and_a_python_file(
    run_cli, fit_run, data_file, npz_pair, tmp_path
):
    a, _ = npz_pair
    victim = tmp_path / "victim.h5"
    assert run_cli("import", a, "-T", "20", "--out", victim).code == 0
    script = tmp_path / "script.py"
    script.write_text("print('mine')\n")
    checkpoint = fit_run / "checkpoint.pt"
    kept = {p: p.read_bytes() for p in (victim, script, checkpoint)}
    cases = [
        (("animate", fit_run, "--sample", 0, "--out", victim), "HDF5", "primspace import"),
        (("reconstruct", fit_run, "--sample", 0, "--out", victim), "HDF5", "primspace import"),
        (("import", a, "-T", "20", "--out", checkpoint), "primspace run", str(fit_run)),
        (("show", data_file, "--out", script), "not written by a primspace command", "script.py"),
        (("reconstruct", fit_run, "--sample", 0, "--out", script), "not written by a primspace command", "script.py"),
        (("summarize", tmp_path / "exp", "--name", "x", "--command", "c", "--out", script), "a .py file", "summarize"),
    ]
    for args, *fragments in cases:
        assert_user_error(run_cli(*args, "--overwrite"), str(args[args.index("--out") + 1]), *fragments)
    assert {p: p.read_bytes() for p in kept} == kept
    from primspace.train import load_run

    assert load_run(fit_run).epoch == 2  # the run still loads


@pytest.mark.slow
def test_overwrite_replaces_an_earlier_output_of_the_same_command_only(run_cli, fit_run, data_file, npz_pair, tmp_path):
    from primspace.utils.outputs import file_writer

    a, b = npz_pair
    data = tmp_path / "i.h5"
    assert run_cli("import", a, "-T", "20", "--out", data).code == 0
    assert file_writer(data) == "primspace import"
    res = run_cli("import", b, "-T", "20", "--out", data, "--overwrite")
    assert res.code == 0, res.err
    assert np.allclose(MotionDataset.load(data).motor[:, 0], np.load(b)["motor"][:, 0], atol=1e-5)

    shown, drawn, gif = tmp_path / "s.png", tmp_path / "r.png", tmp_path / "a.gif"
    for args, out, writer in (
        (("show", data_file, "--sample", 1), shown, "primspace show"),
        (("reconstruct", fit_run, "--sample", 1), drawn, "primspace reconstruct"),
        (("animate", fit_run, "--sample", 1, "--frames", 3, "--no-replay"), gif, "primspace animate"),
    ):
        assert run_cli(*args, "--out", out).code == 0
        assert file_writer(out) == writer
        assert run_cli(*args, "--out", out, "--overwrite").code == 0, writer
    # a PNG of another command is not replaced
    before = shown.read_bytes()
    assert_user_error(
        run_cli("reconstruct", fit_run, "--sample", 1, "--out", shown, "--overwrite"),
        str(shown),
        "PNG",
        "primspace show",
    )
    assert shown.read_bytes() == before


def test_show_refuses_an_existing_png_unless_overwrite(run_cli, data_file, tmp_path):
    out = tmp_path / "s.png"
    assert run_cli("show", data_file, "--sample", 0, "--out", out).code == 0
    before = out.read_bytes()
    assert_user_error(run_cli("show", data_file, "--sample", 1, "--out", out), str(out), "--overwrite")
    assert out.read_bytes() == before
    assert run_cli("show", data_file, "--sample", 1, "--out", out, "--overwrite").code == 0
    assert out.read_bytes() != before


def test_marks_are_read_back(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from primspace.plots import save_figure
    from primspace.plots.animation import save_gif
    from primspace.utils.outputs import describe, file_writer

    png, gif, plain = tmp_path / "f.png", tmp_path / "f.gif", tmp_path / "g.png"
    save_figure(plt.figure(), png, writer="primspace show")
    save_figure(plt.figure(), plain)
    save_gif(np.zeros((2, 4, 4, 3), dtype=np.uint8), gif, writer="primspace animate")
    assert (file_writer(png), file_writer(gif), file_writer(plain)) == ("primspace show", "primspace animate", None)
    (tmp_path / "s.json").write_text(json.dumps({"summary_version": 1}))
    assert file_writer(tmp_path / "s.json") == "primspace summarize"
    assert "PNG image written by primspace show" in describe(png)
    assert "not written by a primspace command" in describe(plain)


# ----------------------------------------------------- 4. an existing empty output folder


def _empty_read_only(path):
    path.mkdir()
    path.chmod(0o555)
    st = path.stat()
    return st.st_ino, stat.S_IMODE(st.st_mode)


def test_an_empty_output_folder_is_written_in_place(run_cli, points, data_file, tmp_path):
    """Found: `cluster --out ro_run` on an empty folder of mode 555 swapped it for a new
    0755 folder. Root writes into it (in place: same inode, same mode)."""
    if os.geteuid() != 0:
        pytest.skip("only root can write into a mode 555 folder; the refusal is tested below")
    for args in (("cluster", points, "--k", 3), ("train", data_file, "--epochs", 1, *TRAIN)):
        out = tmp_path / f"ro-{args[0]}"
        inode, mode = _empty_read_only(out)
        res = run_cli(*args, "--out", out)
        assert res.code == 0, res.err
        assert (out.stat().st_ino, stat.S_IMODE(out.stat().st_mode)) == (inode, mode) == (inode, 0o555)
        assert any(out.iterdir())
    plain = tmp_path / "plain"
    plain.mkdir()
    inode = plain.stat().st_ino
    assert run_cli("cluster", points, "--k", 3, "--out", plain).code == 0
    assert plain.stat().st_ino == inode and (plain / "result.json").is_file()


def _without_dac_override() -> list[str]:
    """A command prefix that runs a child without the power to ignore file modes."""
    if os.geteuid() != 0:
        return []
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("root ignores file modes and setpriv is not there to drop that")
    drop = "-dac_override,-dac_read_search"
    return [setpriv, f"--inh-caps={drop}", f"--bounding-set={drop}", "--"]


@pytest.mark.slow
@pytest.mark.parametrize("command", ["cluster", "train", "experiment"])
def test_a_read_only_empty_output_folder_is_refused_not_swapped(points, data_file, tmp_path, command):
    out = tmp_path / "ro_run"
    inode, mode = _empty_read_only(out)
    args = {
        "cluster": ["cluster", str(points), "--k", "3"],
        "train": ["train", str(data_file), "--epochs", "1", *TRAIN],
        "experiment": [
            "experiment",
            "intra",
            "--data",
            str(data_file),
            "--epochs",
            "1,1",
            "--latent-dims",
            "2",
            "--inits",
            "zero",
            "--seeds",
            "0",
        ],
    }[command]
    proc = subprocess.run(
        [*_without_dac_override(), sys.executable, "-m", "primspace", *args, "--out", str(out)],
        capture_output=True,
        text=True,
        env=dict(os.environ, MUJOCO_GL="egl"),
        timeout=300,
    )
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and str(out) in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert (out.stat().st_ino, stat.S_IMODE(out.stat().st_mode)) == (inode, mode)
    assert list(out.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
