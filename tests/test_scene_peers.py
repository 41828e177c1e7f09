"""The scene-only peers (issue 40): the contextual ProMP and the nearest first frame (and the checks
every scene peer shares, the kernel ridge map's included)."""

from __future__ import annotations

import numpy as np
import pytest

from primspace.act.scene_kernel import KernelRidgePeer
from primspace.act.scene_peers import ContextualProMPPeer, NearestFramePeer
from primspace.predict.base import Predictor
from primspace.predict.metrics import observed_prefix, unobserved_mse
from primspace.predict.peers import MeanMotionPeer
from primspace.utils.errors import UserError

H, W, T, J = 48, 64, 30, 3
TABLE = (184, 153, 115)
BLOCK = (217, 13, 13)


def _frame(row: int, col: int) -> np.ndarray:
    frame = np.empty((H, W, 3), dtype=np.uint8)
    frame[:] = TABLE
    frame[2:20, 28:36] = 235  # the arm
    frame[row : row + 3, col : col + 3] = BLOCK
    return frame


def _motion(label: int, row: int, col: int) -> np.ndarray:
    """A label's base motion plus offsets linear in the block's column and row, smooth in time."""
    t = np.linspace(0, 1, T)[:, None]
    a, b = (col - 30) / 28.0, (row - 35) / 9.0
    base = 0.3 * np.sin(np.pi * (label + 1) * t + np.arange(J)) * (1 + label)
    return base + a * np.sin(np.pi * t) * [0.5, -0.3, 0.2] + b * t * [0.2, 0.4, -0.3]


def _scenes(n_per_label: int, seed: int, n_labels: int = 2):
    """Motor (n, T, J), labels, frames (n, T, H, W, 3) (the first frame the scene) and positions."""
    rng = np.random.default_rng(seed)
    motor, labels, frames, positions = [], [], [], []
    for label in range(n_labels):
        for _ in range(n_per_label):
            row, col = int(rng.integers(26, 44)), int(rng.integers(2, 59))
            motor.append(_motion(label, row, col))
            labels.append(label)
            first = _frame(row, col)
            frames.append(np.stack([first, np.zeros_like(first)]))  # later frames: never read
            positions.append((row, col))
    return np.array(motor), np.array(labels), np.array(frames), np.array(positions, dtype=np.float64)


@pytest.fixture(scope="module")
def data():
    return _scenes(20, seed=0), _scenes(6, seed=1)


def _scored(peer, fit, test):
    motor, labels, frames, _ = fit
    peer.fit(motor, labels, frames=frames)
    motor_t, labels_t, frames_t, _ = test
    observed = observed_prefix(len(motor_t), T, 1.0 / T)
    hidden = np.where(observed[..., None], motor_t, np.nan)  # the unobserved steps are never read
    predicted = peer.predict(hidden, observed, labels_t, frames=frames_t)
    assert predicted.shape == motor_t.shape and np.all(np.isfinite(predicted))
    return float(np.mean(unobserved_mse(predicted, motor_t, observed)))


def test_contextual_promp_from_the_block_beats_the_mean_motion_and_pixel_pca(data):
    fit, test = data
    mean = _scored(MeanMotionPeer(), fit, test)
    peer = ContextualProMPPeer(features="blob", n_iter=50)
    blob = _scored(peer, fit, test)
    assert peer.needs_labels and isinstance(peer, Predictor)
    assert set(peer.promps_) == {0, 1} and all(a > 0 for a in peer.alphas_.values())
    assert blob < 0.01 * mean, (blob, mean)
    # the pixels' principal components hardly see a 3x3 block: about the mean motion
    pca = _scored(ContextualProMPPeer(features="pca", n_iter=50), fit, test)
    assert blob < 0.01 * pca and pca < 1.05 * mean, (pca, mean)
    # the weights at nearly no penalty reproduce the fitted motions
    motor, labels, frames, _ = fit
    exact = ContextualProMPPeer(features="blob", alpha=1e-6, n_iter=50).fit(motor, labels, frames=frames)
    weights = exact.weights(frames, labels)
    assert weights.shape == (len(motor), J * exact.n_basis)
    first = exact.promps_[0].trajectory_from_weights(np.linspace(0, 1, T), weights[0])
    assert np.max(np.abs(first - motor[0])) < 0.05


def test_contextual_promp_lengths_and_one_for_all(data):
    (motor, labels, frames, _), _ = data
    lengths = np.full(len(motor), T)
    lengths[::2] = T - 5
    peer = ContextualProMPPeer(features="blob", per_label=False, n_basis=8, n_iter=50).fit(motor, None, lengths, frames)
    assert not peer.needs_labels and list(peer.promps_) == [None]
    observed = observed_prefix(len(motor), T, 0.1, lengths)
    out = peer.predict(motor, observed, lengths=lengths, frames=frames)
    np.testing.assert_array_equal(out[0, T - 5 :], np.broadcast_to(out[0, T - 6], (5, J)))


def test_nearest_frame_returns_the_demonstration_of_the_closest_block(data):
    (motor, labels, frames, positions), (motor_t, labels_t, frames_t, positions_t) = data
    peer = NearestFramePeer(features="blob").fit(motor, labels, frames=frames)
    observed = observed_prefix(len(motor_t), T, 0.2)
    predicted = peer.predict(motor_t, observed, labels_t, frames=frames_t)
    centres = positions + 1.0
    mean, scale = centres.mean(axis=0), centres.std(axis=0)
    for i in range(len(motor_t)):
        dist = np.linalg.norm((centres - mean) / scale - (positions_t[i] + 1.0 - mean) / scale, axis=1)
        dist[labels != labels_t[i]] = np.inf
        np.testing.assert_array_equal(predicted[i], motor[int(np.argmin(dist))])


def test_nearest_frame_on_pixels_finds_the_same_scene(data):
    (motor, labels, frames, _), _ = data
    peer = NearestFramePeer().fit(motor, labels, frames=frames)
    assert peer.needs_labels
    pick = [3, 25, 7]
    chosen = peer.neighbours(frames[pick, 0], labels[pick])
    np.testing.assert_array_equal(chosen, pick)
    observed = observed_prefix(3, T, 0.5)
    np.testing.assert_array_equal(peer.predict(motor[pick], observed, labels[pick], frames=frames[pick]), motor[pick])


@pytest.mark.parametrize(
    "peer", [ContextualProMPPeer(features="blob", n_iter=20), NearestFramePeer(), KernelRidgePeer()]
)
def test_bad_inputs_raise_user_error(data, peer):
    (motor, labels, frames, _), _ = data
    observed = observed_prefix(len(motor), T, 0.2)
    with pytest.raises(UserError, match="call fit"):
        peer.predict(motor, observed, labels, frames=frames)
    with pytest.raises(UserError, match="frames"):
        peer.fit(motor, labels)
    with pytest.raises(UserError, match="labels"):
        peer.fit(motor, None, frames=frames)
    peer.fit(motor[labels == 0], labels[labels == 0], frames=frames[labels == 0])
    with pytest.raises(UserError, match="frames"):
        peer.predict(motor, observed, labels * 0)
    with pytest.raises(UserError, match=r"label\(s\) \[1\]"):
        peer.predict(motor, observed, labels, frames=frames)
    with pytest.raises(UserError, match="n = "):
        peer.predict(motor, observed, labels * 0, frames=frames[:3])
    with pytest.raises(UserError, match="uint8"):
        peer.predict(motor[:2], observed[:2], labels[:2] * 0, frames=frames[:2].astype(np.float32))


def test_bad_arguments_raise_user_error():
    with pytest.raises(UserError, match="pca, blob, pixels"):
        ContextualProMPPeer(features="colour")
    with pytest.raises(UserError, match="pca, blob, pixels"):
        NearestFramePeer(features="colour")
    with pytest.raises(UserError, match="alpha"):
        ContextualProMPPeer(alpha=0.0)
    with pytest.raises(UserError, match="alpha"):
        ContextualProMPPeer(alpha="best")
    with pytest.raises(UserError, match="n_basis"):
        ContextualProMPPeer(n_basis=1)
