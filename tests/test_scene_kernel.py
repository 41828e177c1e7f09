"""The scene policy's kind of map as its peer (:class:`~primspace.act.scene_kernel.KernelRidgePeer`):
a Gaussian process's mean from the first frame's features to the whole motion, its lengths and
penalty chosen by K-fold on the fitted demonstrations only.

On the synthetic scenes of test_scene_peers.py (a 3 x 3 red block on a table, motions smooth in its
place)."""

from __future__ import annotations

import numpy as np
import pytest

from primspace.act.scene_kernel import LENGTH_GRID, PENALTY_GRID, KernelRidgePeer
from primspace.act.scene_peers import ContextualProMPPeer
from primspace.predict.base import Predictor
from primspace.predict.metrics import observed_prefix
from primspace.predict.peers import MeanMotionPeer
from primspace.utils.errors import UserError
from test_scene_peers import J, T, _scenes, _scored


@pytest.fixture(scope="module")
def data():
    return _scenes(20, seed=0), _scenes(6, seed=1)


def test_bad_arguments_raise_user_error():
    with pytest.raises(UserError, match="pca, blob, pixels"):
        KernelRidgePeer(features="colour")
    for bad in (0.0, -1.0, "best", True):
        with pytest.raises(UserError, match="length_scale"):
            KernelRidgePeer(length_scale=bad)
        with pytest.raises(UserError, match="penalty"):
            KernelRidgePeer(penalty=bad)
    with pytest.raises(UserError, match="folds"):
        KernelRidgePeer(folds=1)
    with pytest.raises(UserError, match="random_state"):
        KernelRidgePeer(random_state=-1)


def test_kernel_ridge_predicts_the_motion_from_the_block_with_settings_from_its_grid(data):
    fit, test = data
    peer = KernelRidgePeer()
    error = _scored(peer, fit, test)
    assert peer.needs_labels and isinstance(peer, Predictor) and set(peer.choices_) == {0, 1}
    for choice in peer.choices_.values():
        assert len(choice["length_scale"]) == 3 and set(choice["length_scale"]) <= set(LENGTH_GRID)  # one per feature
        assert choice["penalty"] in PENALTY_GRID and choice["score"] > 0
    # the motions are smooth in the block's place: far below the mean motion and the blob ProMP regression
    assert error < 0.01 * _scored(MeanMotionPeer(), fit, test)
    assert error < _scored(ContextualProMPPeer(features="blob", n_iter=50), fit, test)
    # a forecast says that the run takes no part
    motor_t, labels_t, frames_t, _ = test
    forecast = peer.forecast(motor_t, observed_prefix(len(motor_t), T, 0.1), labels_t, frames=frames_t)
    assert forecast.details == {} and forecast.codes is None  # registry.model_share: a peer's share is 0


def test_kernel_ridge_at_a_tiny_penalty_passes_through_the_fitted_motions(data):
    (motor, labels, frames, _), _ = data
    peer = KernelRidgePeer(length_scale=1.0, penalty=1e-9).fit(motor, labels, frames=frames)
    assert peer.choices_[0] == {"length_scale": [1.0] * 3, "penalty": 1e-9, "score": None}  # given: nothing chosen
    observed = observed_prefix(len(motor), T, 0.1)
    np.testing.assert_allclose(peer.predict(motor, observed, labels, frames=frames), motor, atol=1e-4)


def test_kernel_ridge_lengths_and_one_for_all(data):
    (motor, labels, frames, _), _ = data
    lengths = np.full(len(motor), T)
    lengths[::2] = T - 5
    peer = KernelRidgePeer(per_label=False).fit(motor, None, lengths, frames)
    assert not peer.needs_labels and list(peer.choices_) == [None]
    out = peer.predict(motor, observed_prefix(len(motor), T, 0.1, lengths), lengths=lengths, frames=frames)
    assert out.shape == motor.shape and np.all(np.isfinite(out))
    np.testing.assert_array_equal(out[0, T - 5 :], np.broadcast_to(out[0, T - 6], (5, J)))


def test_kernel_ridge_same_seed_same_numbers_and_the_folds_follow_the_seed(data):
    (motor, labels, frames, _), (motor_t, labels_t, frames_t, _) = data
    noisy = motor + np.random.default_rng(5).normal(scale=0.05, size=motor.shape)  # a choice with something to weigh
    observed = observed_prefix(len(motor_t), T, 0.1)

    def run(seed):
        peer = KernelRidgePeer(random_state=seed).fit(noisy, labels, frames=frames)
        return peer.choices_, peer.predict(motor_t, observed, labels_t, frames=frames_t)

    (a, pa), (b, pb), (c, _) = run(0), run(0), run(1)
    assert a == b
    np.testing.assert_array_equal(pa, pb)
    assert [v["score"] for v in a.values()] != [v["score"] for v in c.values()]  # other folds, other scores


def test_kernel_ridge_chooses_on_the_fitted_demonstrations_only(data):
    """Its settings are a function of the fitted demonstrations: evaluation data changed any way
    leaves them (and the fitted map) as they were, while noise on the fitted motions moves them."""
    (motor, labels, frames, _), (motor_t, labels_t, frames_t, _) = data
    observed = observed_prefix(len(motor_t), T, 0.1)
    peer = KernelRidgePeer().fit(motor, labels, frames=frames)
    chosen = {k: dict(v) for k, v in peer.choices_.items()}
    first = peer.predict(motor_t, observed, labels_t, frames=frames_t)
    perturbed = motor_t * -3.0 + 1.0  # the evaluation motions, nothing like the fitted ones
    again = peer.predict(perturbed, observed, labels_t, frames=frames_t)
    assert peer.choices_ == chosen
    np.testing.assert_array_equal(again, first)  # no evaluation step is read
    refit = KernelRidgePeer().fit(motor, labels, frames=frames)
    refit.predict(perturbed, observed, labels_t, frames=frames_t)
    assert refit.choices_ == chosen
    noisy = motor + np.random.default_rng(1).normal(scale=0.2, size=motor.shape)
    moved = KernelRidgePeer().fit(noisy, labels, frames=frames).choices_
    assert any(moved[k]["penalty"] > chosen[k]["penalty"] for k in chosen), (moved, chosen)


def test_kernel_ridge_needs_two_demonstrations_per_primitive(data):
    (motor, labels, frames, _), _ = data
    keep = np.r_[np.flatnonzero(labels == 0), np.flatnonzero(labels == 1)[:1]]
    with pytest.raises(UserError, match="at least 2"):
        KernelRidgePeer().fit(motor[keep], labels[keep], frames=frames[keep])
