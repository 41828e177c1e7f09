"""One rule for sample numbers, the data file's index (issue 37, section 3): after a split
with --indices, `cluster RUN` numbers and scores a run's codes by its samples in the data
file, and `reconstruct --sample` speaks of the data file's numbers."""

import csv
import json

import numpy as np
import pytest

from conftest import assert_user_error
from test_train import primitives

FIT, TEST = list(range(0, 18)), list(range(18, 30))


def _split(where):
    """demos.h5 (30 labelled samples) split by --indices: fit on 0..17, new on 18..29."""
    from primspace.cli import main

    data = primitives(10, seed=0)
    data.save(where / "demos.h5")
    (where / "fit.txt").write_text("\n".join(map(str, FIT)))
    (where / "test.txt").write_text("\n".join(map(str, TEST)))
    common = ["--epochs", "2", "--threads", "1"]
    for args in (
        [
            "train",
            where / "demos.h5",
            "--indices",
            where / "fit.txt",
            "--latent-dim",
            "4",
            "--out",
            where / "fit",
            *common,
        ],
        ["infer", where / "fit", where / "demos.h5", "--indices", where / "test.txt", "--out", where / "new", *common],
    ):
        try:
            main([str(a) for a in args])
        except SystemExit as exc:
            assert not exc.code, exc.code
    return where, data


@pytest.fixture(scope="module")
def split(tmp_path_factory):
    return _split(tmp_path_factory.mktemp("split"))


@pytest.fixture(scope="module")
def moved(tmp_path_factory):
    """The same, then demos.h5 moved to moved.h5."""
    where, data = _split(tmp_path_factory.mktemp("moved"))
    (where / "demos.h5").rename(where / "moved.h5")
    return where, data


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("given", ["new", "new/latents.npy"])
def test_cluster_of_a_run_numbers_its_codes_by_the_data_file_and_scores_them(split, run_cli, tmp_path, given):
    where, data = split
    result = run_cli("cluster", where / given, "--k", "3", "--out", tmp_path / "out")
    assert result.code == 0, result.err
    rows = _rows(tmp_path / "out" / "labels.csv")
    assert [int(r["sample"]) for r in rows] == TEST  # before: 0..11, the run's rows (or refused: not a file)
    assert [int(r["true"]) for r in rows] == data.labels[TEST].tolist()  # the run's labels, from its data file
    record = json.loads((tmp_path / "out" / "result.json").read_text())
    assert record["scores"]["n_scored"] == len(TEST) and "numbered by the data file's index" in record["points"]
    assert "accuracy" in result.out


def test_cluster_of_a_plain_npy_keeps_rows_and_a_run_without_its_file_clusters_unscored(moved, run_cli, tmp_path):
    where, _ = moved
    codes = np.load(where / "fit" / "latents.npy")
    np.save(tmp_path / "codes.npy", codes)
    assert run_cli("cluster", tmp_path / "codes.npy", "--k", "3", "--out", tmp_path / "a").code == 0
    assert [int(r["sample"]) for r in _rows(tmp_path / "a" / "labels.csv")] == list(range(len(codes)))
    result = run_cli("cluster", where / "fit", "--k", "3", "--out", tmp_path / "b")
    assert result.code == 0 and "demos.h5" in result.err and "--labels" in result.err
    assert [int(r["sample"]) for r in _rows(tmp_path / "b" / "labels.csv")] == FIT


def test_reconstruct_speaks_of_the_data_files_numbers(split, run_cli, tmp_path):
    where, _ = split
    assert run_cli("reconstruct", where / "new", "--sample", TEST[3], "--out", tmp_path / "s.png").code == 0
    assert_user_error(
        run_cli("reconstruct", where / "new", "--sample", 3, "--out", tmp_path / "t.png"),
        "sample 3 is not one of the run's 12 samples (18, 19, 20",
        "numbered by its index in the data file",
        "demos.h5",
    )


def test_reconstruct_names_a_moved_data_file_as_the_runs(moved, run_cli, tmp_path):
    where, _ = moved
    assert_user_error(
        run_cli("reconstruct", where / "new", "--sample", TEST[0], "--out", tmp_path / "s.png"),
        "demos.h5: no such file: it is the data file run",
        "--data NEW_PATH",
    )
    assert (
        run_cli(
            "reconstruct", where / "new", "--sample", TEST[0], "--data", where / "moved.h5", "--out", tmp_path / "s.png"
        ).code
        == 0
    )
