"""Frames of another aspect ratio (issue 26, item 5): centre crop by default, pad or stretch on request."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.data.importers.frames import AlignedFrames, fit_box, resize_frames
from primspace.utils.errors import UserError


def _square(n=1, size=84):
    """84x84 frames: white, a red band in the top and bottom 10 rows, a blue one in the left and right 14 columns."""
    frames = np.full((n, size, size, 3), 255, dtype=np.uint8)
    frames[:, :10] = frames[:, -10:] = (255, 0, 0)
    frames[:, 10:-10, :14] = frames[:, 10:-10, -14:] = (0, 0, 255)
    return frames


def test_the_boxes_keep_the_aspect_ratio_or_not():
    assert fit_box((84, 84), (48, 64), "crop") == (10, 0, 63, 84)  # 63 x 84 is 3:4
    assert fit_box((84, 84), (48, 64), "pad") == (0, -14, 84, 112)
    assert fit_box((84, 84), (48, 64), "stretch") == (0, 0, 84, 84)
    assert fit_box((480, 640), (48, 64), "crop") == (0, 0, 480, 640)  # same aspect ratio: the whole frame
    assert fit_box((40, 200), (48, 64), "crop") == (0, 73, 40, 53)  # a wide frame loses its sides
    assert fit_box((40, 200), (48, 64), "pad") == (-55, 0, 150, 200)


def test_crop_drops_the_edges_pad_adds_black_bars_stretch_keeps_everything():
    crop, pad, stretch = (resize_frames(_square(), (48, 64), fit)[0].astype(int) for fit in ("crop", "pad", "stretch"))
    red, blue, black = np.array([255, 0, 0]), np.array([0, 0, 255]), np.zeros(3)
    # crop: rows 10..72 of the square, so no red band survives; the blue side bands do
    assert np.abs(crop[0, 32] - (255, 255, 255)).max() < 40 and np.abs(crop[24, 2] - blue).max() < 40
    # pad: black bars left and right (14 of 112 columns: 8 of 64), the red bands kept at the top
    assert np.abs(pad[24, 3] - black).max() < 10 and np.abs(pad[2, 32] - red).max() < 40
    # stretch: both bands, the frame squeezed
    assert np.abs(stretch[2, 32] - red).max() < 40 and np.abs(stretch[24, 2] - blue).max() < 40


def test_the_source_text_names_the_fit_only_when_it_was_needed():
    frames = AlignedFrames(5, (48, 64), fit="pad")
    frames.add(3, lambda idx: _square(len(idx)))
    frames.add(3, lambda idx: np.zeros((len(idx), 96, 128, 3), np.uint8))
    assert frames.stack().shape == (2, 5, 48, 64, 3)
    assert frames.describe() == "frames 84x84, 96x128 -> 48x64 (padded)"
    same = AlignedFrames(5, (48, 64))
    same.add(3, lambda idx: np.zeros((len(idx), 96, 128, 3), np.uint8))
    assert same.collect().describe() == "frames 96x128 -> 48x64"
    with pytest.raises(UserError, match="image fit 'zoom' is not one of crop, pad, stretch"):
        AlignedFrames(5, (48, 64), fit="zoom")


@pytest.mark.parametrize("fit, edge", [("crop", "white"), ("pad", "black"), ("stretch", "red")])
def test_import_image_fit_on_the_command_line(run_cli, tmp_path, fit, edge):
    frames = np.stack([_square(4), _square(4)])
    np.savez(tmp_path / "d.npz", motor=np.random.default_rng(0).normal(size=(2, 4, 2)), images=frames)
    res = run_cli("import", tmp_path / "d.npz", "-T", "4", "--image-fit", fit, "--out", tmp_path / "d.h5")
    assert res.code == 0, res.err
    ds = MotionDataset.load(tmp_path / "d.h5")
    top_centre = np.asarray(ds.images[0, 0, 1, 32], dtype=int)
    want = {"white": (255, 255, 255), "black": (0, 0, 0), "red": (255, 0, 0)}[edge]
    if fit == "pad":
        top_centre = np.asarray(ds.images[0, 0, 24, 1], dtype=int)  # the bar at the side
    assert np.abs(top_centre - want).max() < 40
    assert ds.source.endswith({"crop": "(centre crop)", "pad": "(padded)", "stretch": "(stretched)"}[fit])


def test_image_fit_without_frames_is_refused(run_cli, tmp_path):
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "a.csv").write_text("x\n0\n1\n")
    assert_user_error(
        run_cli("import", tmp_path / "c", "-T", "4", "--image-fit", "pad", "--out", tmp_path / "o.h5"),
        "--image-fit pad: there are no frames",
    )
