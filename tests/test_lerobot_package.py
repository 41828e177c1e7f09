"""The LeRobot importer against the ``lerobot`` package itself (issue 26), when it is installed.

primspace never needs ``lerobot``; CI does not install it, so these tests skip there. With
it (LeRobot >= 0.4, which reads v3.0 only):

    python -m venv /tmp/lrvenv && /tmp/lrvenv/bin/pip install lerobot pytest hypothesis
    /tmp/lrvenv/bin/pip install -e '.[video]'
    /tmp/lrvenv/bin/python -m pytest tests/test_lerobot_package.py

They check that a data set that ``test_import_lerobot.write_v3`` writes is one LeRobot's
``LeRobotDataset`` reads, that a data set LeRobot records itself and one its converter makes
from a ``write_v2`` set import, and that for every row primspace takes the state and the frame
that LeRobot's reader returns. Imported one episode at a time with ``length`` = its rows and
the frames' own size, primspace keeps rows and frames as they are (resampling to the same
length, frame_steps(n, n) = 0..n-1, no resizing).
"""

from __future__ import annotations

import importlib.util
import json
import os

import numpy as np
import pytest

if importlib.util.find_spec("lerobot") is not None:  # before huggingface_hub reads them: a local folder only
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("HF_DATASETS_OFFLINE", "1")
pytest.importorskip("lerobot")
LeRobotDataset = pytest.importorskip(
    "lerobot.datasets.lerobot_dataset", reason="LeRobot >= 0.4 (v3.0 data sets)"
).LeRobotDataset

from primspace.data import import_lerobot  # noqa: E402
from test_import_lerobot import (
    CAMERA,
    FPS,
    H,
    W,
    can_encode,
    check_import,
    coded_frames,
    identify,
    state_of,
    write_v2,
    write_v3,
)  # noqa: E402


def backends():
    """LeRobot's video decoders here: ``pyav``, and ``torchcodec`` when it loads (it needs FFmpeg's libraries)."""
    found = ["pyav"]
    try:
        importlib.import_module("torchcodec.decoders")
        found.append("torchcodec")
    except Exception:
        pass
    return found


def assert_same_as_lerobot(root, lengths, backend="pyav"):
    """Every row: the state and the frame LeRobot's reader returns are those primspace imports."""
    ds = LeRobotDataset("local/primspace-test", root=root, video_backend=backend)
    assert len(ds) == sum(lengths)
    g = 0
    for e, n in enumerate(lengths):
        ours = import_lerobot(root, n, images=CAMERA, image_size=(H, W), episodes=[e])
        for r in range(n):
            item = ds[g]
            g += 1
            assert (item["episode_index"].item(), item["frame_index"].item()) == (e, r)
            state = item["observation.state"].numpy()
            np.testing.assert_array_equal(state, state_of(e, n)[r])
            np.testing.assert_allclose(ours.motor[0, r], state, rtol=0, atol=1e-6)
            theirs = np.round(item[CAMERA].permute(1, 2, 0).numpy() * 255).astype(np.uint8)  # float CHW in [0, 1]
            assert identify(theirs) == identify(ours.images[0, r]) == (e, r)
            assert np.abs(theirs.astype(int) - ours.images[0, r]).max() <= 2  # 0 with lerobot 0.4.4
            assert item["task"] == ours.label_names[ours.labels[0]]  # tasks.parquet as LeRobot writes it
    return ds


@pytest.mark.parametrize("backend", backends())
@pytest.mark.parametrize("codec", ["mpeg4", "libsvtav1"])
def test_v3_written_here_is_read_alike_by_lerobot(tmp_path, codec, backend):
    """write_v3's layout (two data files, a video of three episodes, meta/episodes in two files)."""
    can_encode(codec)
    lengths = (6, 9, 5, 7)
    write_v3(tmp_path / "ds", lengths=lengths, codec=codec, gop=3)
    assert_same_as_lerobot(tmp_path / "ds", lengths, backend)


def test_data_set_recorded_by_lerobot_imports(tmp_path):
    """LeRobot's own writer (create, add_frame, save_episode: AV1 video), read by both."""
    lengths, tasks = (6, 9, 5), ("push", "lift", "push")
    features = {
        "observation.state": {"dtype": "float32", "shape": (3,), "names": ["shoulder", "elbow", "wrist"]},
        CAMERA: {"dtype": "video", "shape": (H, W, 3), "names": ["height", "width", "channels"]},
    }
    recorder = LeRobotDataset.create("local/primspace-test", fps=FPS, root=tmp_path / "rec", features=features)
    for e, n in enumerate(lengths):
        for state, frame in zip(state_of(e, n), coded_frames(e, n)):
            recorder.add_frame({"observation.state": state, CAMERA: frame, "task": tasks[e]})
        recorder.save_episode()
    recorder.finalize()
    ds = assert_same_as_lerobot(tmp_path / "rec", lengths)
    ours = import_lerobot(tmp_path / "rec", 7, images=CAMERA, image_size=(24, 32))
    check_import(ours, [state_of(e, n) for e, n in enumerate(lengths)], 7)
    assert ours.joint_names == ["shoulder", "elbow", "wrist"]
    first_rows = np.cumsum((0,) + lengths[:-1])
    assert [ours.label_names[k] for k in ours.labels] == [ds[int(g)]["task"] for g in first_rows] == list(tasks)


def test_v21_converted_by_lerobot_imports_the_same(tmp_path):
    """A write_v2 set (v2.1, which LeRobot >= 0.4 no longer reads) through LeRobot's converter to v3.0."""
    convert = pytest.importorskip("lerobot.datasets.v30.convert_dataset_v21_to_v30").convert_dataset
    root, lengths = tmp_path / "local" / "v21", (12, 20, 9)
    write_v2(root, lengths=lengths)
    before = import_lerobot(root, 11, images=CAMERA, image_size=(24, 32))

    convert("local/v21", root=tmp_path, push_to_hub=False)  # root becomes v3.0; the original moves to v21_old
    assert json.loads((root / "meta" / "info.json").read_text())["codebase_version"] == "v3.0"
    after = import_lerobot(root, 11, images=CAMERA, image_size=(24, 32))
    np.testing.assert_array_equal(after.motor, before.motor)
    np.testing.assert_array_equal(after.images, before.images)
    assert after.label_names == before.label_names and after.labels.tolist() == before.labels.tolist()
    assert_same_as_lerobot(root, lengths)
