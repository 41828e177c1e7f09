"""Issue 24 (items 8, 9, 11, 12): corrupted data files are refused, commands that would do
nothing useful are refused, and every error is one line.

- schema 2: ``motor``, ``labels``, ``params`` and the step fields carry HDF5's Fletcher-32
  checksum, so two flipped bytes are one line naming the file and the field (schema-1
  files still read); the writer mark ``primspace_writer`` (:func:`file_writer`);
- every error of the option parser is ``primspace: error: ...`` on one line, exit 2;
- ``experiment --epochs 1,2,3``, ``train --motor-weight 0 --no-images`` and clustering
  identical points are refused; points too large or too small for float64 are refused
  with that reason (no warnings);
- ``AutoDecoder.inverse_transform`` checks its codes.
"""

from __future__ import annotations

import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import DatasetWriter, MotionDataset
from primspace.utils.errors import DataError, UserError

SAMPLE = dict(labels=[0, 1, 2, 0, 1, -1], params=np.arange(12.0).reshape(6, 2))


def _dataset(n: int = 6, images: bool = False) -> MotionDataset:
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, (n, 5, 8, 8, 3), dtype=np.uint8) if images else None
    return MotionDataset(rng.normal(size=(n, 5, 3)), images=frames, **SAMPLE)


def _flip_two_bytes(path, name: str) -> None:
    """Flip two bytes inside the stored data of the array ``name`` (not its metadata)."""
    with h5py.File(path, "r") as f:
        node = f[name]
        offset = node.id.get_chunk_info(0).byte_offset if node.chunks else node.id.get_offset()
    with open(path, "r+b") as fh:
        for at in (offset + 1, offset + 2):
            fh.seek(at)
            byte = fh.read(1)[0]
            fh.seek(at)
            fh.write(bytes([byte ^ 0xA5]))


# ------------------------------------------------------------------ integrity (item 8)


@pytest.mark.parametrize("name", ["motor", "labels", "params"])
def test_flipped_bytes_are_refused_naming_file_and_field(tmp_path, name, run_cli):
    path = _dataset().save(tmp_path / "d.h5")
    _flip_two_bytes(path, name)
    with pytest.raises(DataError) as caught:
        MotionDataset.load(path)
    message = str(caught.value)
    assert len(message.splitlines()) == 1
    assert str(path) in message and f"field '{name}'" in message and "checksum" in message
    assert_user_error(run_cli("info", path), str(path), f"field '{name}'", "corrupted")


def test_step_fields_carry_the_checksum_too(tmp_path):
    ds = MotionDataset(
        np.zeros((2, 4, 1)),
        labels=[0, 1],
        lengths=[4, 3],
        step_labels=[[0, 0, 1, 1], [1, 1, 1, -1]],
        step_segments=[[0, 0, 1, 1], [0, 0, 0, -1]],
    )
    with h5py.File(ds.save(tmp_path / "s.h5")) as f:
        assert f.attrs["schema_version"] == 2
        assert all(f[name].fletcher32 for name in ("motor", "labels", "lengths", "step_labels", "step_segments"))


def test_schema_1_files_still_read(tmp_path):
    """A file as version 1 wrote it (contiguous, no checksum) loads as before."""
    ds = _dataset()
    path = tmp_path / "v1.h5"
    with h5py.File(path, "w") as f:
        f.attrs["schema_version"] = 1
        f.attrs["joint_names"] = np.array(ds.joint_names, dtype=h5py.string_dtype())
        f.attrs["dt"] = 1.0
        f.attrs["source"] = "version 1"
        f.create_dataset("motor", data=ds.motor)
        f.create_dataset("labels", data=ds.labels, fillvalue=-1)
        f.create_dataset("params", data=ds.params)
    back = MotionDataset.load(path)
    np.testing.assert_array_equal(back.motor, ds.motor)
    np.testing.assert_array_equal(back.labels, ds.labels)
    assert back.source == "version 1"
    with h5py.File(path, "r+") as f:
        f.attrs["schema_version"] = 3
    with pytest.raises(DataError, match="schema version 3 is newer than this primspace reads"):
        MotionDataset.load(path)


def test_a_saved_file_with_images_still_round_trips(tmp_path):
    ds = _dataset(images=True)
    back = MotionDataset.load(ds.save(tmp_path / "i.h5"))
    np.testing.assert_array_equal(np.asarray(back.images), ds.images)
    np.testing.assert_array_equal(back.params, ds.params)


def test_the_writer_mark(tmp_path):
    from primspace.utils.outputs import file_writer

    marked = _dataset().save(tmp_path / "m.h5", writer="primspace simulate")
    assert file_writer(marked) == "primspace simulate"
    assert file_writer(_dataset().save(tmp_path / "plain.h5")) is None
    with DatasetWriter(tmp_path / "w.h5", n_samples=2, length=5, joint_names=["a"], writer="primspace merge") as w:
        w.write(0, motor=np.zeros((2, 5, 1)))
    assert file_writer(tmp_path / "w.h5") == "primspace merge"
    (tmp_path / "text.h5").write_text("not HDF5")
    assert file_writer(tmp_path / "text.h5") is None
    assert file_writer(tmp_path / "missing.h5") is None
    assert file_writer(tmp_path) is None
    assert MotionDataset.load(marked).source == ""  # loading ignores the mark


# -------------------------------------------------------- one line everywhere (item 11)


@pytest.fixture(scope="module")
def data_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "d.h5"
    _dataset().save(path)
    return path


def _one_usage_line(res, *fragments):
    assert_user_error(res, *fragments)
    assert res.err.startswith("primspace: error: "), res.err
    assert "─" not in res.err and "Usage:" not in res.err  # no box, no usage block


@pytest.mark.parametrize(
    "args,fragments",
    [
        (("train", "{data}", "--out", "{tmp}/run", "--epochs", "abc"), ("'--epochs'", "abc")),
        (("train", "{data}", "--out", "{tmp}/run", "--bogus"), ("No such option: --bogus",)),
        (("train", "{data}"), ("Missing option", "'--out'")),
        (("train", "{data}", "--out", "{tmp}/run", "--init", "bogus"), ("'--init'", "bogus")),
        (("bogus-command",), ("No such command", "bogus-command")),
        (("cluster", "{data}", "--k", "1.5", "--out", "{tmp}/c"), ("'--k'", "1.5")),
    ],
)
def test_option_parser_errors_are_one_line(run_cli, data_file, tmp_path, args, fragments):
    args = [a.format(data=data_file, tmp=tmp_path) for a in args]
    _one_usage_line(run_cli(*args), *fragments)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("args", [["train", "x.h5", "--epochs", "abc", "--out", "run"], ["no-such-command"]])
def test_the_real_entry_point_prints_one_line(tmp_path, args):
    env = dict(os.environ, COLUMNS="80")
    proc = subprocess.run(
        [sys.executable, "-m", "primspace", *args], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300
    )
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("primspace: error: ")


def test_help_version_and_no_arguments(run_cli):
    res = run_cli("--help")
    assert res.code == 0 and "cluster" in res.out and res.err == ""
    res = run_cli("train", "--help")
    assert res.code == 0 and "--motor-weight" in res.out
    assert run_cli("--version").code == 0
    res = run_cli()
    assert res.code == 2 and "Usage" in res.out + res.err and "error" not in res.err


def _replace_command(monkeypatch, name: str, callback) -> None:
    from primspace.cli.app import app

    info = next(c for c in app.registered_commands if c.name == name)
    monkeypatch.setattr(info, "callback", callback)


def test_a_commands_own_exit_status_is_kept(run_cli, monkeypatch):
    import typer

    def exits():
        raise typer.Exit(3)

    _replace_command(monkeypatch, "info", exits)
    assert run_cli("info").code == 3


def test_ctrl_c_is_one_line_and_non_zero(run_cli, monkeypatch):
    def interrupted():
        raise KeyboardInterrupt

    _replace_command(monkeypatch, "info", interrupted)
    res = run_cli("info")
    lines = [line for line in res.err.splitlines() if line.strip()]
    assert res.code == 130 and lines == ["primspace: error: interrupted"], res.err


# ------------------------------------------------------------------- clustering (9, 11)


def _points(tmp_path, name: str, X) -> str:
    path = tmp_path / f"{name}.npy"
    np.save(path, X)
    return str(path)


@pytest.fixture()
def spread_points():
    rng = np.random.default_rng(0)
    return rng.normal(size=(20, 3))


def test_cluster_values_near_1e300_are_too_large(run_cli, tmp_path, spread_points):
    res = run_cli("cluster", _points(tmp_path, "big", spread_points * 1e300), "--k", "2", "--out", tmp_path / "c")
    assert_user_error(res, "too large", "scale the points down")
    assert "Warning" not in res.err and not (tmp_path / "c").exists()


def test_cluster_values_near_1e_300_are_too_small_not_identical(run_cli, tmp_path, spread_points):
    res = run_cli("cluster", _points(tmp_path, "tiny", spread_points * 1e-300), "--k", "2", "--out", tmp_path / "c")
    assert_user_error(res, "too small", "scale the points up")
    assert "identical" not in res.err and "Warning" not in res.err


@pytest.mark.parametrize("row", [[1.0, 1.0, 1.0], [0.3, -2.0, 5.0]])
def test_cluster_identical_points_are_refused(run_cli, tmp_path, row):
    res = run_cli("cluster", _points(tmp_path, "same", np.tile(row, (20, 1))), "--k", "2", "--out", tmp_path / "c")
    assert_user_error(res, "all 20 points are identical")
    assert not (tmp_path / "c").exists()


def test_the_estimator_gives_the_same_reasons(spread_points):
    from primspace.cluster import LowRankSubspaceClustering

    model = LowRankSubspaceClustering(2, random_state=0)
    with pytest.raises(UserError, match="too large"):
        model.fit(spread_points * 1e300)
    with pytest.raises(UserError, match="too small"):
        model.fit(spread_points * 1e-300)
    with pytest.raises(UserError, match="identical"):
        model.fit(np.tile([0.3, -2.0, 5.0], (20, 1)))
    assert model.fit(spread_points).labels_.shape == (20,)


# ---------------------------------------------------- commands that would do nothing (9)


def test_experiment_epochs_takes_at_most_two_values(run_cli, tmp_path, monkeypatch):
    import primspace.cli.experiments as cli_experiments

    def started(*args, **kwargs):
        raise AssertionError("the experiment started")

    monkeypatch.setattr(cli_experiments, "_experiment", started)
    res = run_cli("experiment", "intra", "--out", tmp_path / "exp", "--epochs", "1,2,3")
    assert_user_error(res, "--epochs", "at most two values", "1,2,3")


@pytest.mark.parametrize("extra", [("--no-images",), ()])
def test_train_with_nothing_to_learn_is_refused(run_cli, tmp_path, data_file, extra):
    """``--motor-weight 0`` with no vision loss (``--no-images``, or data without images)."""
    res = run_cli("train", data_file, "--out", tmp_path / "run", "--epochs", "1", "--motor-weight", "0", *extra)
    assert_user_error(res, "--motor-weight 0", "no loss")
    assert not (tmp_path / "run").exists()


# --------------------------------------------------------- inverse_transform (item 12)


@pytest.fixture(scope="module")
def decoder():
    from primspace import AutoDecoder
    from primspace.train import TrainConfig
    from test_train import SMALL, primitives

    model = AutoDecoder(SMALL, TrainConfig(epochs=0, threads=1, seed=0), progress=False)
    model.fit(primitives(2, seed=0))
    return model


@pytest.mark.parametrize(
    "Z,fragment",
    [
        (np.zeros((0, 6)), "no rows"),
        (np.zeros((0, 3)), "must have shape (n, 6)"),
        (np.array([["a", "b", "c", "d", "e", "f"]]), "must hold numbers"),
        (np.zeros((2, 3)), "must have shape (n, 6)"),
        (np.zeros(6), "must have shape (n, 6)"),
        (np.full((1, 6), np.nan), "finite"),
        (np.full((1, 6), 1e39), "float32 range"),
        ([[0.0] * 6, [0.0] * 5], "array of numbers"),
    ],
)
@pytest.mark.slow
def test_inverse_transform_checks_its_codes(decoder, Z, fragment):
    with pytest.raises(UserError) as caught:
        decoder.inverse_transform(Z)
    assert fragment in str(caught.value) and len(str(caught.value).splitlines()) == 1


@pytest.mark.slow
def test_inverse_transform_still_decodes(decoder):
    motor, frames = decoder.inverse_transform(decoder.codes_.astype(np.float64))
    assert motor.shape[0] == len(decoder.codes_) and frames is None


def test_fit_with_nothing_to_learn_is_refused_from_python_too(tmp_path):
    """The library refuses what the command line refuses: motor_weight 0 and no vision loss."""
    from primspace.train import TrainConfig, fit
    from test_train import SMALL, primitives

    with pytest.raises(UserError, match="motor_weight is 0 and no vision loss"):
        fit(
            primitives(2, seed=0),
            tmp_path / "run",
            model_config=SMALL,
            train_config=TrainConfig(epochs=1, motor_weight=0),
            progress=False,
        )
    assert not (tmp_path / "run").exists()
