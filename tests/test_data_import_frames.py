"""Importing demonstrations with camera frames: robomimic HDF5, npz with images (LeRobot:
tests/test_import_lerobot.py).

Every source file is written here, in its format's layout. Frames are filled with one
colour per recorded frame (frame ``i`` has the value ``_level(i)``), so a stored frame
tells which recorded frame it came from, after resizing (a constant image stays
constant under Lanczos).
"""

from __future__ import annotations

import json
import re

import h5py
import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset, import_npz, import_robomimic, resample
from primspace.data.importers import frame_steps
from primspace.data.importers.frames import resize_frames
from primspace.utils.errors import DataError

SRC_H, SRC_W = 32, 40  # source frames (even sides: yuv420p video)


def _level(i: int) -> int:
    """The grey level of recorded frame ``i`` (distinct, 23 apart: survives video coding)."""
    return (23 * i + 10) % 250


def frames_of(n: int, h: int = SRC_H, w: int = SRC_W) -> np.ndarray:
    """``n`` frames, frame ``i`` a constant image of grey level ``_level(i)``."""
    levels = np.array([_level(i) for i in range(n)], dtype=np.uint8)
    return np.broadcast_to(levels[:, None, None, None], (n, h, w, 3)).copy()


def source_index(frame: np.ndarray, n: int, tol: float = 0.0) -> int:
    """Which of ``n`` recorded frames a stored frame shows (its mean grey level)."""
    mean = float(frame.mean())
    best = min(range(n), key=lambda i: abs(_level(i) - mean))
    assert abs(_level(best) - mean) <= tol, (mean, _level(best))
    return best


def joints_of(t: int, width: int, offset: float) -> np.ndarray:
    """A smooth (t, width) joint sequence, different for each ``offset``."""
    s = np.linspace(0.0, 1.0, t)[:, None]
    return offset + np.sin(2.0 * s + np.arange(width)[None, :]) + s


# ------------------------------------------------------------------ the alignment rule


def test_frame_steps_is_the_nearest_frame_in_normalised_time():
    for n, length in [(5, 3), (3, 5), (30, 61), (61, 61), (100, 7), (2, 9)]:
        got = frame_steps(n, length)
        t = np.arange(length) / (length - 1)  # output step k's normalised time
        source_t = np.arange(n) / (n - 1)  # recorded frame i's normalised time
        distance = np.abs(source_t[got] - t)
        nearest = np.abs(source_t[None, :] - t[:, None]).min(axis=1)
        np.testing.assert_allclose(distance, nearest, atol=1e-12)
        assert got[0] == 0 and got[-1] == n - 1
    assert frame_steps(5, 3).tolist() == [0, 2, 4]
    assert frame_steps(3, 5).tolist() == [0, 1, 1, 2, 2]  # a tie (k=1: 0.5) goes to the later frame
    assert frame_steps(61, 61).tolist() == list(range(61))


def test_resize_is_anti_aliased_and_keeps_a_frame_of_the_target_size():
    checker = (np.indices((48, 64)).sum(axis=0) % 2 * 255).astype(np.uint8)
    checker = np.repeat(checker[None, ..., None], 3, axis=-1)
    small = resize_frames(checker, (24, 32))
    assert small.shape == (1, 24, 32, 3) and small.dtype == np.uint8
    assert 110 <= small.min() and small.max() <= 145  # averaged to grey; nearest-neighbour gives 0 or 255
    rng = np.random.default_rng(0)
    same = rng.integers(0, 256, size=(2, 24, 32, 3), dtype=np.uint8)
    np.testing.assert_array_equal(resize_frames(same, (24, 32)), same)
    ramp = np.broadcast_to(np.linspace(0, 255, 80).astype(np.uint8)[None, None, :, None], (1, 60, 80, 3))
    half = resize_frames(ramp, (30, 40))[0, 15, :, 0].astype(float)
    assert np.all(np.diff(half[2:-2]) >= 0) and abs(half[20] - 127) < 8  # a ramp stays a ramp


# ------------------------------------------------------------------------- robomimic


def write_robomimic(path, demos: dict, control_freq: float | None = 20.0) -> None:
    """``demos``: ``{"demo_3": {"robot0_joint_pos": array, ...}}``, written under data/<demo>/obs."""
    with h5py.File(path, "w") as f:
        data = f.create_group("data")
        if control_freq is not None:
            data.attrs["env_args"] = json.dumps({"env_name": "Lift", "env_kwargs": {"control_freq": control_freq}})
        for name, obs in demos.items():
            group = data.create_group(f"{name}/obs")
            for key, value in obs.items():
                group.create_dataset(key, data=value)
            data[name].create_dataset("actions", data=np.zeros((len(next(iter(obs.values()))), 7)))


def robomimic_demos(lengths=(30, 45, 20, 25), names=None) -> dict:
    names = names or [f"demo_{i}" for i in range(len(lengths))]
    return {
        name: {
            "robot0_joint_pos": joints_of(t, 7, offset=10.0 * int(name[5:])),
            "robot0_gripper_qpos": joints_of(t, 2, offset=-5.0 - int(name[5:])),
            "agentview_image": frames_of(t),
        }
        for name, t in zip(names, lengths)
    }


def test_robomimic_joints_in_the_order_given_frames_aligned_and_resized(tmp_path):
    demos = robomimic_demos()
    write_robomimic(tmp_path / "lift.hdf5", demos)
    ds = import_robomimic(
        tmp_path / "lift.hdf5",
        61,
        joints=["robot0_gripper_qpos", "robot0_joint_pos"],
        images="agentview_image",
        image_size=(48, 64),
    )
    assert ds.motor.shape == (4, 61, 9) and ds.images.shape == (4, 61, 48, 64, 3) and ds.images.dtype == np.uint8
    assert ds.joint_names == ["robot0_gripper_qpos_0", "robot0_gripper_qpos_1"] + [
        f"robot0_joint_pos_{j}" for j in range(7)
    ]
    for i, obs in enumerate(demos.values()):
        want = np.concatenate([obs["robot0_gripper_qpos"], obs["robot0_joint_pos"]], axis=1)
        np.testing.assert_allclose(ds.motor[i], resample(want, 61), rtol=1e-5, atol=1e-5)
        n = len(want)
        got = [source_index(ds.images[i, k], n) for k in range(61)]
        assert got == frame_steps(n, 61).tolist()
    np.testing.assert_allclose(ds.dt, (1 / 20) * np.mean([29, 44, 19, 24]) / 60)
    assert "32x40 -> 48x64" in ds.source and "agentview_image" in ds.source


def test_robomimic_demos_in_natural_numeric_order_and_joints_only(tmp_path):
    names = ["demo_10", "demo_2", "demo_0", "demo_1"]  # HDF5 lists them demo_0, demo_1, demo_10, demo_2
    write_robomimic(tmp_path / "d.hdf5", robomimic_demos((20, 21, 22, 23), names), control_freq=None)
    ds = import_robomimic(tmp_path / "d.hdf5", 10, joints=["robot0_joint_pos"])
    # joint 0 starts at offset + sin(0) = 10 * demo number
    np.testing.assert_allclose(ds.motor[:, 0, 0], [0.0, 10.0, 20.0, 100.0], atol=1e-5)
    assert ds.images is None and ds.dt == pytest.approx(1.0 * np.mean([21, 20, 19, 22]) / 9)


def test_robomimic_missing_keys_name_the_file_the_demo_and_the_keys_there(tmp_path):
    demos = robomimic_demos()
    del demos["demo_2"]["agentview_image"]
    path = tmp_path / "lift.hdf5"
    write_robomimic(path, demos)
    with pytest.raises(DataError) as err:
        import_robomimic(path, 20, joints=["robot0_joint_pos", "robot0_eef_pos"])
    msg = str(err.value)
    assert (
        msg.startswith(f"{path}, field 'robot0_eef_pos', sample 0:")
        and "data/demo_0/obs/robot0_eef_pos is missing" in msg
    )
    assert "keys there: agentview_image, robot0_gripper_qpos, robot0_joint_pos" in msg
    with pytest.raises(
        DataError,
        match=r"sample 2: data/demo_2/obs/agentview_image is missing; keys there: "
        r"robot0_gripper_qpos, robot0_joint_pos; at demo level \(data/demo_2\): actions$",
    ):
        import_robomimic(path, 20, joints=["robot0_joint_pos"], images="agentview_image")
    with pytest.raises(DataError, match=r"no joint keys given .*data/demo_0/obs has: agentview_image, "):
        import_robomimic(path, 20, joints=[])
    with h5py.File(tmp_path / "plain.hdf5", "w") as f:
        f.create_dataset("motor", data=np.zeros((2, 5, 1)))
    with pytest.raises(DataError, match=r"plain\.hdf5: no 'data' group .*it has: motor"):
        import_robomimic(tmp_path / "plain.hdf5", 20, joints=["q"])


@pytest.mark.parametrize(
    "frames, match",
    [
        (frames_of(25).astype(np.float32), r"frames must be uint8, got float32"),
        (frames_of(25)[..., 0], r"frames must be \(T_i, H, W, 3\), got rank 3"),
        (frames_of(24), r"24 frames for 25 joint steps"),
        (
            np.concatenate([frames_of(25), frames_of(25)[..., :1]], axis=-1),
            r"frames must have 3 colour channels \(RGB\), got 4",
        ),
    ],
    ids=["dtype", "rank", "count", "channels"],
)
def test_robomimic_bad_frames_name_the_file_the_key_and_the_demo(tmp_path, frames, match):
    demos = robomimic_demos()
    demos["demo_3"]["agentview_image"] = frames
    path = tmp_path / "bad.hdf5"
    write_robomimic(path, demos)
    with pytest.raises(DataError, match=rf"^{re.escape(str(path))}, field 'agentview_image', sample 3: {match}"):
        import_robomimic(path, 20, joints=["robot0_joint_pos"], images="agentview_image")


def test_robomimic_joint_keys_of_different_lengths_are_refused(tmp_path):
    demos = robomimic_demos()
    demos["demo_1"]["robot0_gripper_qpos"] = demos["demo_1"]["robot0_gripper_qpos"][:-1]
    write_robomimic(tmp_path / "d.hdf5", demos)
    with pytest.raises(
        DataError,
        match=r"sample 1: data/demo_1/obs/robot0_gripper_qpos has 44 steps, "
        r"robot0_joint_pos has 45",
    ):
        import_robomimic(tmp_path / "d.hdf5", 20, joints=["robot0_joint_pos", "robot0_gripper_qpos"])


# ------------------------------------------------------------------------------- npz


def test_npz_stacked_frames_and_joints_key(tmp_path):
    joints = np.stack([joints_of(15, 3, offset=i) for i in range(2)])
    np.savez(tmp_path / "s.npz", joints=joints, images=np.stack([frames_of(15), frames_of(15)]), dt=0.1)
    ds = import_npz(tmp_path / "s.npz", 8, image_size=(16, 24))
    assert ds.images.shape == (2, 8, 16, 24, 3)
    np.testing.assert_allclose(ds.motor, resample(joints, 8), rtol=1e-5, atol=1e-5)
    assert [source_index(f, 15) for f in ds.images[1]] == frame_steps(15, 8).tolist() == [0, 2, 4, 6, 8, 10, 12, 14]
    assert ds.source == "npz:s.npz; frames 32x40 -> 16x24 (centre crop)"


def test_npz_per_demo_frames_of_different_sizes_and_lengths(tmp_path):
    arrays = {
        "joints_0": joints_of(12, 2, 0),
        "joints_1": joints_of(30, 2, 1),
        "joints_2": joints_of(7, 2, 2),
        "images_0": frames_of(12, 24, 32),
        "images_1": frames_of(30, 60, 80),
        "images_2": frames_of(7),
    }
    np.savez(tmp_path / "p.npz", **arrays)
    ds = import_npz(tmp_path / "p.npz", 11)
    assert ds.images.shape == (3, 11, 48, 64, 3)
    for i, n in enumerate((12, 30, 7)):
        assert [source_index(f, n) for f in ds.images[i]] == frame_steps(n, 11).tolist()
        np.testing.assert_allclose(ds.motor[i], resample(arrays[f"joints_{i}"], 11), rtol=1e-5, atol=1e-5)
    assert ds.source.endswith("frames 24x32, 60x80, 32x40 -> 48x64 (centre crop)")


def test_npz_frames_with_lengths_and_without_frames_unchanged(tmp_path):
    seqs = [joints_of(t, 2, i) for i, t in enumerate((9, 14))]
    np.savez(
        tmp_path / "l.npz",
        motor=np.concatenate(seqs),
        lengths=[9, 14],
        images=np.concatenate([frames_of(9), frames_of(14)]),
    )
    ds = import_npz(tmp_path / "l.npz", 5)
    assert [source_index(f, 14) for f in ds.images[1]] == frame_steps(14, 5).tolist()
    np.savez(tmp_path / "j.npz", motor=np.stack(seqs[:1] * 2))
    plain = import_npz(tmp_path / "j.npz", 5)
    assert plain.images is None and plain.source == "npz:j.npz"


@pytest.mark.parametrize(
    "arrays, match",
    [
        (
            dict(
                joints_0=np.zeros((5, 2)),
                joints_1=np.zeros((6, 2)),
                images_0=frames_of(5),
                images_1=frames_of(6).astype(np.int16),
            ),
            r"field 'images_1', sample 1: frames must be uint8, got int16",
        ),
        (
            dict(joints_0=np.zeros((5, 2)), joints_1=np.zeros((6, 2)), images_0=frames_of(5), images_1=frames_of(5)),
            r"field 'images_1', sample 1: 5 frames for 6 joint steps",
        ),
        (
            dict(motor=np.zeros((2, 5, 2)), images=frames_of(5)[None]),
            r"field 'images': holds 1 demonstrations, the joints 2",
        ),
        (dict(motor=np.zeros((2, 5, 2)), images=frames_of(10)), r"field 'images': must be \(N, T, H, W, 3\)"),
        (
            dict(motor=np.zeros((2, 5, 2)), images=np.zeros((2, 5, 4, 4, 1), np.uint8)),
            r"field 'images', sample 0: frames must have 3 colour channels",
        ),
        (
            dict(joints_0=np.zeros((5, 2)), joints_1=np.zeros((5, 2)), images_0=frames_of(5)),
            r"field 'images_1', sample 1: missing: per-demonstration arrays must be numbered images_0 \.\. images_1",
        ),
        (dict(joints_0=np.zeros((5, 2)), joints_2=np.zeros((5, 2))), r"field 'joints_1', sample 1: missing"),
        (
            dict(motor=np.zeros((2, 5, 2)), joints=np.zeros((2, 5, 2))),
            r"field 'joints': holds both 'motor' and 'joints'",
        ),
        (
            dict(arr_0=np.zeros((5, 2)), motor_0=np.zeros((5, 2))),
            r"holds per-demonstration arrays named arr_0 and motor_0",
        ),
        (  # issue 38: arr_2's joints were paired with images_1's frames
            dict(arr_0=np.zeros((5, 2)), arr_2=np.zeros((5, 2)), images_0=frames_of(5), images_1=frames_of(5)),
            r"field 'arr_1', sample 1: missing: per-demonstration arrays must be numbered arr_0 \.\. arr_1",
        ),
    ],
    ids=["dtype", "count", "n", "rank", "channels", "missing-images", "missing-joints", "both", "mixed", "arr-gap"],
)
def test_npz_bad_frames_name_file_field_and_sample(tmp_path, arrays, match):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(DataError, match=rf"^{re.escape(str(path))}(, |: ){match}"):
        import_npz(path, 10)


# -------------------------------------------------------------------- command line


def test_cli_robomimic_import_then_info_reports_frames(run_cli, tmp_path):
    write_robomimic(tmp_path / "lift.hdf5", robomimic_demos())
    out = tmp_path / "data.h5"
    res = run_cli(
        "import",
        tmp_path / "lift.hdf5",
        "--joints",
        "robot0_joint_pos,robot0_gripper_qpos",
        "--images",
        "agentview_image",
        "--length",
        "61",
        "--out",
        out,
    )  # robomimic guessed from .hdf5
    assert res.code == 0, res.err
    assert "4 samples x 61 steps x 9 joints, frames 48x64" in res.out
    ds = MotionDataset.load(out)
    assert ds.joint_names[0] == "robot0_joint_pos_0" and ds.joint_names[-1] == "robot0_gripper_qpos_1"
    res = run_cli("info", out)
    assert res.code == 0 and "images   61x48x64x3 uint8 per sample" in res.out and "frames 32x40 -> 48x64" in res.out
    info = json.loads(run_cli("info", out, "--json").out)
    assert info["image_shape"] == [61, 48, 64, 3] and "32x40" in info["source"]


def test_cli_npz_import_with_frames(run_cli, tmp_path):  # LeRobot's: tests/test_import_lerobot.py
    np.savez(tmp_path / "f.npz", motor=np.zeros((2, 5, 1)), images=np.stack([frames_of(5)] * 2))
    res = run_cli("import", tmp_path / "f.npz", "-T", "9", "--image-size", "8x8", "--out", tmp_path / "n.h5")
    assert res.code == 0, res.err
    assert MotionDataset.load(tmp_path / "n.h5").images.shape == (2, 9, 8, 8, 3)


def test_cli_import_option_errors_are_one_line(run_cli, tmp_path):
    write_robomimic(tmp_path / "lift.hdf5", robomimic_demos((6, 7)))
    o = tmp_path / "o.h5"
    res = run_cli("import", tmp_path / "lift.hdf5", "--joints", "robot0_joint_pos,nope", "-T", "9", "--out", o)
    assert_user_error(
        res,
        "lift.hdf5",
        "field 'nope'",
        "sample 0",
        "data/demo_0/obs/nope is missing",
        "keys there: agentview_image, robot0_gripper_qpos, robot0_joint_pos",
    )
    res = run_cli("import", tmp_path / "lift.hdf5", "-T", "9", "--out", o)
    assert_user_error(res, "no joint keys given (--joints", "agentview_image, robot0_gripper_qpos")
    res = run_cli(
        "import",
        tmp_path / "lift.hdf5",
        "--joints",
        "robot0_joint_pos",
        "--images",
        "agentview_image",
        "--image-size",
        "50x64",
        "-T",
        "9",
        "--out",
        o,
    )
    assert_user_error(res, "--image-size 50x64", "multiples of 8")
    assert_user_error(
        run_cli(
            "import",
            tmp_path / "lift.hdf5",
            "--joints",
            "robot0_joint_pos",
            "--image-size",
            "4:4",
            "-T",
            "9",
            "--out",
            o,
        ),
        "no frames to resize",
    )
    np.savez(tmp_path / "f.npz", motor=np.zeros((2, 5, 1)))
    assert_user_error(
        run_cli("import", tmp_path / "f.npz", "--joints", "q", "-T", "9", "--out", o),
        "--joints applies to --format robomimic or lerobot, not npz",
    )
    assert not o.exists()


def test_cli_guesses_robomimic_only_from_an_unambiguous_hdf5_file(run_cli, tmp_path):
    write_robomimic(tmp_path / "lift.h5", robomimic_demos((6, 7)))
    o = tmp_path / "o.h5"
    res = run_cli("import", tmp_path / "lift.h5", "--joints", "robot0_joint_pos", "-T", "9", "--out", o)
    assert_user_error(res, "cannot tell the format of a .h5 file", "--format robomimic")
    res = run_cli(
        "import", tmp_path / "lift.h5", "--format", "robomimic", "--joints", "robot0_joint_pos", "-T", "9", "--out", o
    )
    assert res.code == 0, res.err
    MotionDataset(np.zeros((2, 5, 1))).save(tmp_path / "made.hdf5")  # a primspace data set, named .hdf5
    res = run_cli("import", tmp_path / "made.hdf5", "-T", "9", "--out", tmp_path / "p.h5")
    assert_user_error(res, "cannot tell the format", "without data/demo_N groups", "pass --format")
