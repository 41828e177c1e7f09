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
        (["--scene", "three.h5:7"], ["three.h5", "sample 7 is outside 0..2"]),
        (["--scene", "three.h5:1"], ["three.h5", "no block params"]),
        (["--scene", "swapped.h5:1"], ["swapped.h5", "block_y, block_x, block_size", "in that order"]),
    ],
)
def test_act_refuses_its_options_before_reading_the_run(run_cli, tmp_path, monkeypatch, flags, fragments):
    import numpy as np

    from primspace.data import MotionDataset

    monkeypatch.chdir(tmp_path)
    MotionDataset(np.zeros((3, 5, 2), np.float32), dt=0.1).save(tmp_path / "three.h5")
    blocks = np.tile([0.0, 0.5, 0.05], (3, 1))
    swapped = MotionDataset(np.zeros((3, 5, 2), np.float32), params=blocks, dt=0.1)
    swapped.param_names = ["block_y", "block_x", "block_size"]
    swapped.save(tmp_path / "swapped.h5")
    res = run_cli("act", tmp_path / "run", "--primitive", "push", *flags, "--out", tmp_path / "o")
    assert_user_error(res, *fragments)
    assert not (tmp_path / "o").exists()


def test_act_without_the_predict_extra_refuses_at_once(run_cli, tmp_path, monkeypatch):
    """movement-primitives missing (the ``predict`` extra): one line naming the pip command, before
    the options, the run or the output are looked at."""
    import sys

    monkeypatch.setitem(sys.modules, "movement_primitives", None)  # what find_spec reads as not installed
    res = run_cli("act", tmp_path / "run", "--primitive", "push", "--scene", "0.5,0,0.05", "--out", tmp_path / "o")
    assert_user_error(res, "act needs the movement-primitives package", "pip install 'primspace[predict]'")
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def motor_run(tmp_path_factory):
    """A tiny run on labelled motions without frames (act refuses it for want of frames, after
    the checks of its options)."""
    import numpy as np

    from primspace.cli import main
    from primspace.data import MotionDataset

    root = tmp_path_factory.mktemp("act_options")
    motor = np.random.default_rng(0).normal(size=(4, 6, 2)).astype(np.float32)
    MotionDataset(motor, labels=np.arange(4) % 2, label_names=["reach", "push"], dt=0.1).save(root / "d.h5")
    train = ("--epochs", "1", "--layers", "4,2", "--latent-dim", "2", "--batch-size", "4", "--threads", "1")
    try:
        main(["train", str(root / "d.h5"), "--out", str(root / "run"), *train])
    except SystemExit as exc:
        assert exc.code in (0, None), exc.code
    return root


@pytest.mark.slow
@pytest.mark.parametrize(
    ("primitive", "fragments"),
    [("grasp", ["unknown primitive 'grasp'", "0 (reach), 1 (push)"]), ("2", ["out of range"])],
)
def test_act_checks_the_primitive_before_reading_frames_or_fitting(run_cli, motor_run, tmp_path, primitive, fragments):
    res = run_cli("act", motor_run / "run", "--primitive", primitive, "--scene", "0.5,0,0.05", "--out", tmp_path / "o")
    assert_user_error(res, *fragments)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_act_names_its_own_flag_for_the_fitted_data(run_cli, motor_run, tmp_path):
    """A run whose data file moved: act says to give it with --data (act has no --fitted-data)."""
    import shutil

    moved = tmp_path / "moved.h5"
    shutil.move(motor_run / "d.h5", moved)
    try:
        res = run_cli("act", motor_run / "run", "--primitive", "0", "--scene", "0.5,0,0.05", "--out", tmp_path / "o")
    finally:
        shutil.move(moved, motor_run / "d.h5")
    assert_user_error(res, "d.h5", "--data PATH")
    assert "--fitted-data" not in res.err and not (tmp_path / "o").exists()


@pytest.mark.slow
def test_act_refuses_a_scene_whose_joints_are_not_the_runs(run_cli, motor_run, tmp_path):
    """The scene file's sample names itself and says how many joints it has and the run has."""
    import numpy as np

    from primspace.data import MotionDataset

    blocks = np.tile([0.5, 0.0, 0.05], (2, 1))
    MotionDataset(np.zeros((2, 6, 3), np.float32), params=blocks, dt=0.1).save(tmp_path / "s.h5")
    res = run_cli(
        "act", motor_run / "run", "--primitive", "push", "--scene", f"{tmp_path / 's.h5'}:1", "--out", tmp_path / "o"
    )
    assert_user_error(res, "s.h5", "sample 1", "3 joints", "the run's 2")


@pytest.mark.slow
def test_act_without_frames_names_the_data_given(run_cli, motor_run, tmp_path):
    """--data without frames: named, not told to give --data; without --data, told to."""
    args = ("act", motor_run / "run", "--primitive", "push", "--scene", "0.5,0,0.05", "--out", tmp_path / "o")
    res = run_cli(*args, "--data", motor_run / "d.h5")
    assert_user_error(res, "d.h5 has none", "camera frames")
    assert "give --data" not in res.err
    assert_user_error(run_cli(*args), "the run's data has none", "give --data with frames")


def test_the_library_reads_a_scene_file_as_the_command_checks_it(tmp_path):
    """`act.command.read_scene` is the one check of a --scene (the command calls it before any work,
    the library again with the run): a file naming the block's columns in another order is refused."""
    import numpy as np

    from primspace.act.command import read_scene
    from primspace.data import MotionDataset
    from primspace.utils.errors import UserError

    params = np.array([[0.0, 0.5, 0.05], [0.02, 0.45, 0.05]])
    swapped = MotionDataset(motor=np.zeros((2, 5, 3)), params=params, param_names=["block_y", "block_x", "block_size"])
    swapped.save(tmp_path / "swapped.h5")
    with pytest.raises(UserError, match="in that order"):
        read_scene(f"{tmp_path / 'swapped.h5'}:0")
    ordered = MotionDataset(
        motor=np.zeros((2, 5, 3)), params=params[:, [1, 0, 2]], param_names=["block_x", "block_y", "block_size"]
    )
    ordered.save(tmp_path / "ordered.h5")
    (x, y, size), data, i = read_scene(f"{tmp_path / 'ordered.h5'}:1")
    assert (x, y, size) == pytest.approx((0.45, 0.02, 0.05)) and i == 1 and len(data) == 2
    assert read_scene("0.5,0.0,0.05")[1:] == (None, None)
