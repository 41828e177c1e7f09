"""Scene features learned from the frames alone (``features="learned"``): a keypoint follows a
moving bright square, the same seed gives the same features, the scene policy and the contextual
ProMP peer fit and predict with them, bad input is one UserError.

Tiny synthetic frames (24 x 32, a 4 x 4 square on a grey table); fits of 20-40 Adam steps."""

from __future__ import annotations

import numpy as np
import pytest

from primspace.act.frame_features import FEATURE_NAMES, LearnedKeypoints, frame_features
from primspace.act.scene_peers import ContextualProMPPeer
from primspace.act.scene_policy import ScenePolicy
from primspace.utils.errors import UserError

pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)

H, W, SIZE = 24, 32, 4


def squares(n: int, seed: int = 0):
    """``n`` frames with a bright square at a random place, and its centre's column and row."""
    rng = np.random.default_rng(seed)
    rows, cols = rng.integers(0, H - SIZE, n), rng.integers(0, W - SIZE, n)
    frames = np.full((n, H, W, 3), 60, dtype=np.uint8)
    for i in range(n):
        frames[i, rows[i] : rows[i] + SIZE, cols[i] : cols[i] + SIZE] = 240
    return frames, cols + (SIZE - 1) / 2, rows + (SIZE - 1) / 2


def best_correlation(values: np.ndarray, truth: np.ndarray) -> float:
    return max(abs(np.corrcoef(values[:, j], truth)[0, 1]) for j in range(values.shape[1]))


def test_a_keypoint_tracks_the_square_on_new_frames():
    frames, _, _ = squares(48)
    model = LearnedKeypoints(keypoints=2, steps=20).fit(frames)
    new, u, v = squares(32, seed=1)
    points = model.transform(new)
    assert points.shape == (32, 6) and points.dtype == np.float64  # two x, two y, two presences
    assert np.all(np.abs(points[:, :4]) <= 1) and np.all(points[:, 4:] >= 0)
    assert best_correlation(points[:, 0:2], u) > 0.9  # x follows the column
    assert best_correlation(points[:, 2:4], v) > 0.9  # y follows the row


def test_same_seed_same_features_another_seed_other_features():
    frames, _, _ = squares(16)
    a = LearnedKeypoints(keypoints=2, steps=10, random_state=3).fit_transform(frames)
    b = LearnedKeypoints(keypoints=2, steps=10, random_state=3).fit_transform(frames)
    c = LearnedKeypoints(keypoints=2, steps=10, random_state=4).fit_transform(frames)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_the_name_resolves_with_its_seed_and_any_frame_size_works():
    assert "learned" in FEATURE_NAMES
    assert isinstance(frame_features("learned"), LearnedKeypoints)
    assert frame_features("learned", random_state=7).random_state == 7
    odd = np.random.default_rng(0).integers(0, 256, (3, 7, 9, 3), dtype=np.uint8)
    assert LearnedKeypoints(keypoints=3, steps=2).fit_transform(odd).shape == (3, 9)


def motions(cols: np.ndarray, rows: np.ndarray, length: int = 8) -> np.ndarray:
    """A motion (n, length, 2) per square: joints moving from 0 towards the square's place."""
    ramp = np.linspace(0, 1, length)[None, :, None]
    return ramp * np.stack([cols / W, rows / H], axis=1)[:, None, :]


def test_the_scene_policy_and_the_contextual_promp_read_learned_features():
    frames, u, v = squares(24)
    motor, labels, length = motions(u, v), np.zeros(24, dtype=np.int64), 8
    video = np.repeat(frames[:, None], length, axis=1)
    fitted, held = np.arange(20), np.arange(20, 24)
    learned = LearnedKeypoints(keypoints=4, steps=30)  # "learned" with fewer steps
    policy = ScenePolicy(features=learned, label_names=["reach"]).fit(
        motor[fitted], labels[fitted], None, video[fitted]
    )
    assert isinstance(policy.extractor_, LearnedKeypoints) and policy.extractor_.encoder_ is not None
    assert policy.see(frames[:2]).shape == (2, 12)
    assert not policy.hidden(policy.see(frames[:1])[0], policy.see(frames[1:2])[0])  # no colour rule
    forecast = policy.forecast(motor[held], None, labels[held], None, video[held]).motor
    assert forecast.shape == motor[held].shape and np.isfinite(forecast).all()
    mean_error = np.mean((motor[fitted].mean(axis=0) - motor[held]) ** 2)
    assert np.mean((forecast - motor[held]) ** 2) < mean_error
    again = ScenePolicy(features=learned, label_names=["reach"]).fit(motor[fitted], labels[fitted], None, video[fitted])
    np.testing.assert_array_equal(again.forecast(motor[held], None, labels[held], None, video[held]).motor, forecast)
    peer = ContextualProMPPeer(n_basis=4, features=learned, n_iter=20).fit(
        motor[fitted], labels[fitted], None, video[fitted]
    )
    first_step = np.repeat((np.arange(length) < 1)[None], len(held), axis=0)
    assert peer.forecast(motor[held], first_step, labels[held], None, video[held]).motor.shape == motor[held].shape


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"keypoints": 0}, "keypoints"),
        ({"steps": 1.5}, "steps"),
        ({"random_state": -1}, "random_state"),
        ({"threshold": -1.0}, "threshold"),
    ],
)
def test_bad_settings_are_one_user_error(kwargs, fragment):
    with pytest.raises(UserError, match=fragment):
        LearnedKeypoints(**kwargs)


def test_bad_frames_are_one_user_error():
    frames, _, _ = squares(4)
    with pytest.raises(UserError, match="uint8"):
        LearnedKeypoints(steps=1).fit(frames.astype(np.float32))
    with pytest.raises(UserError, match="at least 2"):
        LearnedKeypoints(steps=1).fit(frames[:1])
    with pytest.raises(UserError, match="call fit"):
        LearnedKeypoints().transform(frames)
    with pytest.raises(UserError, match="fitted on"):
        LearnedKeypoints(steps=1).fit(frames).transform(np.zeros((1, 12, 16, 3), dtype=np.uint8))
