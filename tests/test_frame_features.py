"""Features of camera frames (issue 40): pixel PCA, the colour blob, the names."""

from __future__ import annotations

import numpy as np
import pytest

from primspace.act.frame_features import (
    BLOCK_COLOUR,
    ColourBlob,
    PixelPCA,
    PixelVector,
    frame_features,
)
from primspace.utils.errors import UserError

H, W = 48, 64
TABLE = (184, 153, 115)  # rgba 0.72 0.60 0.45
ARM = (235, 235, 235)  # white 0.92
HAND = (64, 64, 64)  # dark grey 0.25


def scene(row: int, col: int, size: int = 3, colour=BLOCK_COLOUR) -> np.ndarray:
    """A table with a white arm, a grey hand and a ``size`` square of ``colour`` at ``[row, col]``."""
    frame = np.empty((H, W, 3), dtype=np.uint8)
    frame[:] = TABLE
    frame[2:20, 28:36] = ARM
    frame[20:24, 29:35] = HAND
    frame[row : row + size, col : col + size] = colour
    return frame


def scenes(positions, size: int = 3) -> np.ndarray:
    return np.stack([scene(r, c, size) for r, c in positions])


def test_block_colour_is_the_red_in_0_255():
    assert BLOCK_COLOUR == (217, 13, 13)


def test_colour_blob_recovers_centroid_and_mass():
    positions = [(30, 10), (35, 50), (40, 20), (26, 44)]
    blob = ColourBlob().fit(scenes(positions))
    rows = blob.transform(scenes(positions))
    assert rows.shape == (4, 3) and rows.dtype == np.float64
    # the block weighs 1 per pixel; the table, arm and hand nothing
    np.testing.assert_allclose(rows[:, 0], 9.0)
    for (r, c), (_, u, v) in zip(positions, rows):
        assert abs(u - (c + 1)) < 0.1 and abs(v - (r + 1)) < 0.1
    # a 2x2 and a 4x4 block: the mass is the area
    small = ColourBlob().fit_transform(np.stack([scene(30, 10, 2), scene(30, 10, 4)]))
    np.testing.assert_allclose(small[:, 0], [4.0, 16.0])
    np.testing.assert_allclose(small[:, 1:], [[10.5, 30.5], [11.5, 31.5]])


def test_colour_blob_soft_weight_and_missing_block():
    blob = ColourBlob().fit(scenes([(30, 10), (40, 30)]))
    np.testing.assert_allclose(blob.centroid_, [(11 + 31) / 2, (31 + 41) / 2])
    # a dull red (excess 100) weighs (100 - 50) / 100 = 0.5 per pixel
    dull = scene(30, 10, colour=(120, 20, 10))[None]
    np.testing.assert_allclose(blob.transform(dull)[0], [4.5, 11.0, 31.0])
    # no block: mass 0 and the fit-time mean centroid
    empty = np.full((1, H, W, 3), TABLE, dtype=np.uint8)
    np.testing.assert_allclose(blob.transform(empty)[0], [0.0, *blob.centroid_])


def test_colour_blob_other_dominant_channel():
    green = (20, 200, 30)
    frames = np.stack([scene(30, 10), scene(10, 50, colour=green)])
    rows = ColourBlob(colour=green).fit_transform(frames)
    np.testing.assert_allclose(rows[1], [9.0, 51.0, 11.0])
    assert rows[0, 0] == 0.0  # the red block is not green


def test_pixel_pca_shape_and_determinism():
    rng = np.random.default_rng(0)
    positions = [(int(r), int(c)) for r, c in zip(rng.integers(25, 44, 12), rng.integers(2, 60, 12))]
    frames = scenes(positions)
    a = PixelPCA().fit(frames)
    assert a.n_components_ == 11  # capped at n - 1
    out = a.transform(frames)
    assert out.shape == (12, 11) and out.dtype == np.float64
    np.testing.assert_array_equal(PixelPCA().fit_transform(frames), out)
    assert PixelPCA(n_components=3).fit_transform(frames).shape == (12, 3)


def test_pixel_vector_is_the_scaled_pixels():
    frames = scenes([(30, 10), (40, 30)])
    rows = PixelVector().fit_transform(frames)
    assert rows.shape == (2, H * W * 3)
    np.testing.assert_allclose(rows, frames.reshape(2, -1) / 255.0)


def test_frame_features_names_and_objects():
    assert isinstance(frame_features("pca"), PixelPCA)
    assert isinstance(frame_features("blob"), ColourBlob)
    assert isinstance(frame_features("pixels"), PixelVector)
    mine = PixelPCA(n_components=2)
    copy = frame_features(mine)
    assert isinstance(copy, PixelPCA) and copy is not mine and copy.n_components == 2
    with pytest.raises(UserError, match="pca, blob, pixels"):
        frame_features("hog")
    with pytest.raises(UserError, match="fit and transform"):
        frame_features(42)


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((2, H, W), dtype=np.uint8),  # no colour axis
        np.zeros((2, H, W, 3), dtype=np.float32),  # not uint8
        np.zeros((0, H, W, 3), dtype=np.uint8),  # empty
    ],
)
def test_bad_frames_raise_user_error(bad):
    with pytest.raises(UserError):
        ColourBlob().fit(bad)
    with pytest.raises(UserError):
        PixelPCA().fit(bad)


def test_bad_arguments_and_unfitted_raise_user_error():
    with pytest.raises(UserError, match="dominant"):
        ColourBlob(colour=(200, 200, 10))
    with pytest.raises(UserError, match="colour"):
        ColourBlob(colour=(300, 0, 0))
    with pytest.raises(UserError, match="soft"):
        ColourBlob(soft=0.0)
    with pytest.raises(UserError, match="n_components"):
        PixelPCA(n_components=0)
    frames = scenes([(30, 10), (40, 30)])
    with pytest.raises(UserError, match="call fit"):
        ColourBlob().transform(frames)
    with pytest.raises(UserError, match="at least 2"):
        PixelPCA().fit(frames[:1])
    fitted = PixelPCA().fit(frames)
    with pytest.raises(UserError, match="fitted on"):
        fitted.transform(np.zeros((1, 24, 32, 3), dtype=np.uint8))
