"""Output folders are published whole and written by one process at a time.

1. A publication killed half-way never leaves a folder that mixes two outputs and looks
   complete (its ``result.json``, the completion mark, is removed before the first file
   is replaced), and a rerun, with or without ``--overwrite``, writes the output whole.
2. A writer holds the folder's lock from its check to its end: a second writer is refused
   with one line (exit 2), and a folder another writer published meanwhile is never
   written over.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.utils.errors import UserError

KILLER = r"""
import os, signal, sys
from pathlib import Path
from primspace.utils import files
from primspace.utils.folders import OutputKind, atomic_directory

out, overwrite, kill_after = Path(sys.argv[1]), sys.argv[2] == "1", int(sys.argv[3])
kind = OutputKind("primspace test", ("a.txt", "b.txt", "result.json"), frozenset({"writer"}))
moved = []

def killing(real):
    def move(src, dst, *args, **kwargs):
        real(src, dst, *args, **kwargs)
        dst = Path(dst)
        if dst.parent == out and not dst.name.startswith("."):
            moved.append(dst)
            if len(moved) == kill_after:
                os.kill(os.getpid(), signal.SIGKILL)
    return move

os.replace, os.rename = killing(os.replace), killing(os.rename)
files.rename_noreplace = killing(files.rename_noreplace)
with atomic_directory(out, overwrite, kind) as tmp:
    if kill_after == 0:  # killed while working, before publishing
        os.kill(os.getpid(), signal.SIGKILL)
    (tmp / "a.txt").write_text("new")
    (tmp / "b.txt").write_text("new")
    (tmp / "result.json").write_text('{"writer": "new"}')
"""


def _kind():
    from primspace.utils.folders import OutputKind

    return OutputKind("primspace test", ("a.txt", "b.txt", "result.json"), frozenset({"writer"}))


def _snapshot(folder):
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


def _write(out, overwrite, tag):
    from primspace.utils.folders import atomic_directory

    with atomic_directory(out, overwrite, _kind()) as tmp:
        for name in ("a.txt", "b.txt"):
            (tmp / name).write_text(tag)
        (tmp / "result.json").write_text(json.dumps({"writer": tag}))


@pytest.mark.parametrize(
    ("start", "overwrite", "kill_after"),
    [("output", True, 1), ("output", True, 2), ("empty", False, 1), ("empty", False, 0), ("new", False, 0)],
)
def test_a_killed_publication_never_looks_complete_and_a_rerun_writes_it_whole(tmp_path, start, overwrite, kill_after):
    """Killed (SIGKILL) after its first (or second) file landed, or while working: the folder
    holds no result.json beside files of two outputs; a rerun with and without --overwrite
    writes the new output whole, leaving no hidden file beside or inside it."""
    from primspace.utils.folders import is_output_of

    out = tmp_path / "o"
    if start == "output":
        _write(out, False, "old")
    elif start == "empty":
        out.mkdir()
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.run(
        [sys.executable, "-c", KILLER, str(out), "1" if overwrite else "0", str(kill_after)],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    if is_output_of(out, _kind()):  # what looks complete is one output, whole
        tag = json.loads((out / "result.json").read_text())["writer"]
        assert (out / "a.txt").read_text() == (out / "b.txt").read_text() == tag
    for again in (False, True):
        _write(out, again, f"rerun-{again}")
        assert _snapshot(out) == {
            "a.txt": f"rerun-{again}".encode(),
            "b.txt": f"rerun-{again}".encode(),
            "result.json": json.dumps({"writer": f"rerun-{again}"}).encode(),
        }
        assert [p.name for p in tmp_path.iterdir()] == ["o"]


def test_an_interrupted_publication_is_not_taken_for_another_commands(tmp_path):
    """A folder another command's killed publication left is still refused as foreign."""
    from primspace.utils.folders import OutputKind, atomic_directory

    out = tmp_path / "o"
    out.mkdir()
    subprocess.run([sys.executable, "-c", KILLER, str(out), "0", "1"], capture_output=True, timeout=120)
    other = OutputKind("primspace other", ("a.txt", "result.json"), frozenset({"writer"}))
    before = _snapshot(out)
    for overwrite in (False, True):
        with pytest.raises(UserError):
            with atomic_directory(out, overwrite, other) as tmp:
                (tmp / "result.json").write_text('{"writer": "other"}')
        assert _snapshot(out) == before


@pytest.fixture
def points(tmp_path):
    rng = np.random.default_rng(0)
    x = np.vstack([rng.normal(size=8) + rng.normal(size=(12, 2)) @ rng.normal(size=(2, 8)) for _ in range(3)])
    np.save(tmp_path / "z.npy", x)
    return tmp_path / "z.npy"


def test_a_second_writer_is_refused_while_the_first_holds_the_folder(run_cli, points, tmp_path):
    """Two `cluster --overwrite` into one folder: the one that comes second, while the first
    holds it, is refused in one line and the folder is the first's alone."""
    from primspace.cluster.outputs import CLUSTER_OUTPUT
    from primspace.utils.folders import atomic_directory

    out = tmp_path / "c"
    assert run_cli("cluster", points, "--k", 2, "--out", out).code == 0
    before = _snapshot(out)
    with pytest.raises(RuntimeError, match="the first gives up"):
        with atomic_directory(out, True, CLUSTER_OUTPUT):
            res = run_cli("cluster", points, "--k", 3, "--out", out, "--overwrite")
            assert_user_error(res, str(out), "another primspace process")
            raise RuntimeError("the first gives up")
    assert _snapshot(out) == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_folder_another_writer_published_meanwhile_is_never_written_over(run_cli, points, tmp_path):
    """A new folder that another `cluster` published while this writer worked: refused,
    even with overwrite, the other's output kept whole."""
    from primspace.cluster.outputs import CLUSTER_OUTPUT
    from primspace.utils.folders import atomic_directory

    out = tmp_path / "c"
    with pytest.raises(UserError, match="meanwhile"):
        with atomic_directory(out, True, CLUSTER_OUTPUT) as tmp:
            (tmp / "labels.csv").write_text("mine")
            (tmp / "result.json").write_text(json.dumps({"mine": True}))
            assert run_cli("cluster", points, "--k", 2, "--out", out).code == 0
            theirs = _snapshot(out)
    assert _snapshot(out) == theirs and json.loads((out / "result.json").read_text())["n_clusters"] == 2
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_every_folder_writer_is_refused_while_another_process_writes_its_folder(run_cli, tmp_path):
    """Every command that writes a folder takes its lock before any work (before reading
    its inputs): while another process holds it, each is refused at once, in one line."""
    from primspace.utils.folders import FolderLock

    out = tmp_path / "o"
    out.mkdir()
    data = tmp_path / "d.npz"
    np.savez(data, motor=np.zeros((4, 10, 2), np.float32))
    lock = FolderLock(out).acquire()
    try:
        for args in (
            ("act", tmp_path / "run", "--primitive", "push", "--scene", "0.5,0,0.05", "--out", out),
            ("predict", tmp_path / "run", data, "--out", out),
            ("segment", tmp_path / "run", data, "--out", out),
            ("cluster", tmp_path / "z.npy", "--k", 2, "--out", out),
        ):
            assert_user_error(run_cli(*args), str(out), "another primspace process")
    finally:
        lock.release()
    assert _snapshot(out) == {}


def test_a_refused_writer_leaves_another_writers_lock_file_alone(run_cli, points, tmp_path):
    """A run directory (its writer's lock file left behind by design) is refused as foreign with
    --overwrite, every file of it kept, its lock file too."""
    out = tmp_path / "run"
    out.mkdir()
    (out / ".writer.lock").write_text("12345")
    (out / "config.json").write_text("{}")
    before = _snapshot(out)
    assert_user_error(
        run_cli("cluster", points, "--k", 2, "--out", out, "--overwrite"), "not a primspace cluster output"
    )
    assert _snapshot(out) == before


def test_a_writer_killed_while_marking_the_folder_unfinished_leaves_it_writable(tmp_path):
    """The mark's own temporary, left by a killed writer (this host, a process that is gone), is
    bookkeeping: the folder is still empty to the next writer, which removes it."""
    from primspace.utils.files import temp_prefix
    from primspace.utils.folders import INCOMPLETE_NAME, LOCK_NAME

    out = tmp_path / "o"
    out.mkdir()
    (out / LOCK_NAME).write_text("999999999")
    stale = temp_prefix(INCOMPLETE_NAME).replace(f"-{os.getpid()}.", "-999999999.") + "x.tmp"
    (out / stale).write_text("primspace te")
    _write(out, False, "new")
    assert sorted(_snapshot(out)) == ["a.txt", "b.txt", "result.json"]


CLI_KILLER = r"""
import os, signal, sys
from pathlib import Path
from primspace.cli import main

out = Path(sys.argv[1])
real = os.replace

def killing(src, dst, *args, **kwargs):
    real(src, dst, *args, **kwargs)
    if Path(dst).parent == out and not Path(dst).name.startswith("."):
        os.kill(os.getpid(), signal.SIGKILL)

os.replace = killing
main(sys.argv[2:])
"""


@pytest.mark.slow
def test_a_killed_cluster_overwrite_never_looks_complete_and_is_rerun_whole(run_cli, points, tmp_path):
    """`cluster --overwrite` killed after its first file replaced the old one: no result.json
    beside files of two outputs; `cluster` again (no --overwrite) writes it whole."""
    from primspace.cluster.outputs import CLUSTER_OUTPUT
    from primspace.utils.folders import is_output_of

    out = tmp_path / "c"
    assert run_cli("cluster", points, "--k", 2, "--out", out).code == 0
    args = ["cluster", str(points), "--k", "3", "--out", str(out), "--overwrite"]
    proc = subprocess.run([sys.executable, "-c", CLI_KILLER, str(out), *args], capture_output=True, timeout=300)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert not is_output_of(out, CLUSTER_OUTPUT)
    assert run_cli("cluster", points, "--k", 3, "--out", out).code == 0
    assert json.loads((out / "result.json").read_text())["n_clusters"] == 3
    assert sorted(p.name for p in out.iterdir()) == ["clustering.png", "labels.csv", "result.json"]
