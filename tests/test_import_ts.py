"""The UEA/UCR ``.ts`` importer: files, several files, a folder; labels and channels; errors located."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

BENCHMARK = Path(__file__).resolve().parents[1] / "benchmarks" / "eval_auto_tau.py"

MULTI = """# two channels, two classes
@problemName Tiny
@timeStamps false
@missing false
@univariate false
@dimensions 2
@equalLength true
@seriesLength 3
@classLabel true walk run
@data
1.0,2.0,3.0:-1.5,0.25,4e-1:walk
0.5,0.5,0.5:7,8,9:run
"""


def _benchmark():
    spec = importlib.util.spec_from_file_location("eval_auto_tau", BENCHMARK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_benchmark_reads_ts_values_and_labels(tmp_path):
    """The benchmark's reading of a .ts file (n, T, channels), pinned before the reader moved."""
    path = tmp_path / "Tiny_TRAIN.ts"
    path.write_text(MULTI, encoding="utf-8")
    series, labels = _benchmark().read_ts(path)[:2]
    np.testing.assert_array_equal(
        np.stack(series), [[[1.0, -1.5], [2.0, 0.25], [3.0, 0.4]], [[0.5, 7.0], [0.5, 8.0], [0.5, 9.0]]]
    )
    assert list(labels) == ["walk", "run"]


UNIVARIATE_TRAIN = """#GunPoint-like: one channel, classes 1 and 2
@problemName Gesture
@timeStamps false
@univariate true
@equalLength false
@classLabel true 1 2
@data
0,1,2,3:1
3,2,1:2
"""

UNIVARIATE_TEST = """@problemName Gesture
@univariate true
@classLabel true 1 2
@data
5,5,5,5,5:2
"""


def _write(folder, name, text):
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def test_import_multivariate_file_channels_become_joints_classes_labels(tmp_path):
    from primspace.data.importers import import_ts

    ds = import_ts(_write(tmp_path, "Tiny_TRAIN.ts", MULTI), 3)
    assert ds.motor.shape == (2, 3, 2)
    np.testing.assert_allclose(ds.motor[0], [[1.0, -1.5], [2.0, 0.25], [3.0, 0.4]], rtol=1e-6)
    assert ds.label_names == ["walk", "run"]  # @classLabel's order
    np.testing.assert_array_equal(ds.labels, [0, 1])
    assert ds.joint_names == ["channel_0", "channel_1"]
    assert list(ds.source_ids) == ["ts:Tiny_TRAIN.ts:0", "ts:Tiny_TRAIN.ts:1"]


def test_import_train_and_test_files_in_order_and_a_folder_alike(tmp_path):
    from primspace.data import resample
    from primspace.data.importers import import_ts

    train = _write(tmp_path, "Gesture_TRAIN.ts", UNIVARIATE_TRAIN)
    test = _write(tmp_path, "Gesture_TEST.ts", UNIVARIATE_TEST)
    ds = import_ts([train, test], 4)
    assert ds.motor.shape == (3, 4, 1)
    np.testing.assert_array_equal(ds.labels, [0, 1, 1])
    assert ds.label_names == ["1", "2"]
    np.testing.assert_allclose(ds.motor[1, :, 0], resample([np.array([[3.0], [2.0], [1.0]])], 4)[0, :, 0], rtol=1e-6)
    assert [s.split(":")[1] for s in ds.source_ids] == ["Gesture_TRAIN.ts", "Gesture_TRAIN.ts", "Gesture_TEST.ts"]
    folder = import_ts(tmp_path, 4)  # a folder: its .ts files by name (TEST before TRAIN)
    np.testing.assert_array_equal(folder.labels, [1, 0, 1])
    np.testing.assert_allclose(folder.motor[0], ds.motor[2])


def test_import_ts_command_writes_the_data_set(run_cli, tmp_path):
    from primspace.data import MotionDataset

    train = _write(tmp_path, "Gesture_TRAIN.ts", UNIVARIATE_TRAIN)
    test = _write(tmp_path, "Gesture_TEST.ts", UNIVARIATE_TEST)
    out = tmp_path / "g.h5"
    res = run_cli("import", train, test, "--format", "ts", "--length", "5", "--out", out)
    assert res.code == 0, res.err
    ds = MotionDataset.load(out)
    assert (len(ds), ds.length, ds.n_joints) == (3, 5, 1)
    guessed = run_cli("import", train, "--length", "5", "--out", tmp_path / "guessed.h5")  # .ts: the format guessed
    assert guessed.code == 0, guessed.err
    assert len(MotionDataset.load(tmp_path / "guessed.h5")) == 2
    folder = run_cli("import", tmp_path, "--length", "5", "--out", tmp_path.parent / f"{tmp_path.name}-folder.h5")
    assert folder.code == 0, folder.err  # a folder of .ts files (and no .csv): the format guessed
    assert len(MotionDataset.load(tmp_path.parent / f"{tmp_path.name}-folder.h5")) == 3


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        (MULTI.replace("0.5,0.5,0.5:7,8,9:run", "0.5,?,0.5:7,8,9:run"), ("line 12", "missing")),
        (MULTI.replace("7,8,9", "7,eight,9"), ("line 12", "channel 1 value 1", "'eight' is not a number")),
        (MULTI.replace("7,8,9", "7,8"), ("line 12", "channel 1 has 2 values")),
        (MULTI.replace(":run", ":jump"), ("line 12", "'jump'", "walk, run")),
        (MULTI.replace("0.5,0.5,0.5:7,8,9:run", "0.5,0.5,0.5:run"), ("line 12", "1 channel(s), the file has 2")),
        (MULTI.replace("1.0,2.0", "1.0,nan"), ("line 11", "not a finite number")),
        (MULTI.replace("@timeStamps false", "@timeStamps true"), ("line 3", "time-stamped")),
        (MULTI.replace("@data\n", ""), ("line 10", "expected an @tag")),
        (MULTI.split("@data")[0], ("no @data line",)),
        (MULTI.split("@data")[0] + "@data\n", ("no series after @data",)),
    ],
)
def test_malformed_ts_refused_in_one_line_naming_file_and_line(run_cli, tmp_path, text, fragments):
    from conftest import assert_user_error

    bad = _write(tmp_path, "Bad_TRAIN.ts", text)
    out = tmp_path / "bad.h5"
    assert_user_error(
        run_cli("import", bad, "--format", "ts", "--length", "4", "--out", out), "Bad_TRAIN.ts", *fragments
    )
    assert not out.exists()


def test_files_that_disagree_refused_naming_the_file(run_cli, tmp_path):
    from conftest import assert_user_error

    train = _write(tmp_path, "Gesture_TRAIN.ts", UNIVARIATE_TRAIN)
    other = _write(tmp_path, "Tiny_TEST.ts", MULTI)
    res = run_cli("import", train, other, "--format", "ts", "--length", "4", "--out", tmp_path / "x.h5")
    assert_user_error(res, "Tiny_TEST.ts", "2 channel(s), Gesture_TRAIN.ts 1")
    empty = tmp_path / "empty"
    empty.mkdir()
    assert_user_error(run_cli("import", empty, "--format", "ts", "-T", "4", "--out", tmp_path / "y.h5"), "no .ts files")
    several = run_cli("import", train, other, "--format", "npz", "-T", "4", "--out", tmp_path / "z.h5")
    assert_user_error(several, "--format npz reads one source, got 2")
