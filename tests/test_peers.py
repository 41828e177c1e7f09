"""The peers of motion prediction (issue 25): ProMP, nearest neighbour, mean motion, the error."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from primspace.predict.metrics import observed_prefix, unobserved_mse
from primspace.predict.peers import (
    MeanMotionPeer,
    NearestPeer,
    ProMPPeer,
    best_noise,
    imitate_promp,
    phase,
    promp_class,
)
from primspace.utils.errors import UserError

T = 40


def _shape(label: int, t: np.ndarray) -> np.ndarray:
    """A per-label 2-joint motion: well separated frequencies and phases."""
    f = 0.5 + 0.5 * label
    return np.stack([np.sin(2 * np.pi * f * t + label), np.cos(2 * np.pi * f * t) * (1 - 0.3 * label)], axis=1)


def _demos(n_labels: int = 3, per_label: int = 4, seed: int = 0):
    """Per-label shapes, each demonstration scaled and shifted a little (a 2-d family), in [-1, 1]."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)
    motor, labels = [], []
    for label in range(n_labels):
        for _ in range(per_label):
            scale, shift = rng.uniform(0.7, 0.9), rng.uniform(-0.1, 0.1)
            motor.append(scale * _shape(label, t) + shift)
            labels.append(label)
    return np.array(motor), np.array(labels)


def _split(motor, labels):
    """Demonstrations 0..2 of each label fitted, the 4th tested."""
    test = np.arange(3, len(labels), 4)
    fit = np.setdiff1d(np.arange(len(labels)), test)
    return motor[fit], labels[fit], motor[test], labels[test]


# --- unobserved_mse ------------------------------------------------------------------------


def test_unobserved_mse_hand_computed_ignores_padding_and_observed_steps():
    truth = np.zeros((2, 4, 2))
    predicted = np.zeros((2, 4, 2))
    predicted[0, 0] = 50.0  # observed: not scored
    predicted[0, 1] = [1.0, 0.0]
    predicted[0, 2] = [2.0, 2.0]
    predicted[0, 3] = 100.0  # padding (length 3): not scored
    predicted[1, :2] = 7.0  # sample 1: all valid steps observed
    observed = np.array([[True, False, False, False], [True, True, False, False]])
    mse = unobserved_mse(predicted, truth, observed, lengths=[3, 2])
    # sample 0: (1 + 0 + 4 + 4) / (2 steps * 2 joints)
    assert mse[0] == pytest.approx(9.0 / 4.0)
    assert np.isnan(mse[1])
    # without lengths the padding step counts
    assert unobserved_mse(predicted, truth, observed)[0] == pytest.approx((9.0 + 2 * 100.0**2) / 6.0)


def test_unobserved_mse_shape_mismatch_is_a_user_error():
    with pytest.raises(UserError, match="predicted has shape"):
        unobserved_mse(np.zeros((2, 4, 2)), np.zeros((2, 4, 3)), np.zeros((2, 4), bool))
    with pytest.raises(UserError, match=r"observed must have shape \(n, T\)"):
        unobserved_mse(np.zeros((2, 4, 2)), np.zeros((2, 4, 2)), np.zeros((2, 5), bool))


def test_observed_prefix_takes_the_ceiling_of_the_fraction():
    assert observed_prefix(1, 61, 0.1).sum() == 7
    assert observed_prefix(1, 100, 0.1).sum() == 10  # 0.1 * 100 is not 10.000...02 steps
    mask = observed_prefix(2, 10, 0.25, lengths=[10, 4])
    assert mask.sum(axis=1).tolist() == [3, 1]
    assert mask[0, :3].all() and not mask[0, 3:].any()
    with pytest.raises(UserError, match="fraction"):
        observed_prefix(1, 10, 1.5)


# --- nearest neighbour and mean motion -------------------------------------------------------


def test_nearest_returns_an_exact_fitted_sequence_and_the_right_one():
    motor, labels = _demos()
    peer = NearestPeer().fit(motor, labels)
    query = motor[[5, 9]].copy()
    observed = observed_prefix(2, T, 0.3)
    query[:, 0:12:2] += 0.003  # close to, not equal to, demonstrations 5 and 9 on the observed steps
    query[:, 1:12:2] -= 0.003
    query[~observed] = np.nan  # never read
    assert peer.neighbours(query, observed).tolist() == [5, 9]
    predicted = peer.predict(query, observed)
    assert np.array_equal(predicted, motor[[5, 9]])


def test_nearest_compares_only_steps_valid_in_both_and_per_label_restricts():
    motor, labels = _demos(n_labels=2, per_label=2)
    lengths = np.array([T, T, 5, T])
    motor[2, 5:] = 99.0  # padding of demonstration 2: would be far if it counted
    query = motor[[2]].copy()
    query[0, :5] = motor[2, :5]
    observed = np.zeros((1, T), bool)
    observed[0, :10] = True
    peer = NearestPeer().fit(motor, labels, lengths=lengths)
    assert peer.neighbours(query, observed).tolist() == [2]
    # per label: demonstration 2 is label 1; asked for label 0, one of label 0's is chosen
    by_label = NearestPeer(per_label=True).fit(motor, labels, lengths=lengths)
    assert labels[by_label.neighbours(query, observed, labels=[0])[0]] == 0


def test_mean_motion_is_the_label_mean_over_valid_steps():
    motor, labels = _demos(n_labels=2, per_label=3)
    observed = observed_prefix(2, T, 0.2)
    peer = MeanMotionPeer().fit(motor, labels)
    predicted = peer.predict(motor[[0, 3]], observed, labels=[1, 0])
    assert np.allclose(predicted[0], motor[labels == 1].mean(axis=0))
    assert np.allclose(predicted[1], motor[labels == 0].mean(axis=0))
    everything = MeanMotionPeer(per_label=False).fit(motor).predict(motor[:1], observed[:1])
    assert np.allclose(everything[0], motor.mean(axis=0))
    # padding: demonstration 0 counts on its first 10 steps only; no demonstration covers the last: held
    lengths = np.array([10, T, T - 1, T, T, T])
    padded = MeanMotionPeer().fit(motor, labels, lengths=lengths).means_[0]
    assert np.allclose(padded[:10], motor[:3, :10].mean(axis=0))
    assert np.allclose(padded[20], motor[1:3, 20].mean(axis=0))
    assert np.allclose(padded[T - 1], motor[1, T - 1])


# --- errors -----------------------------------------------------------------------------------


@pytest.mark.parametrize("make", [MeanMotionPeer, lambda: NearestPeer(per_label=True)])
def test_per_label_without_labels_is_a_user_error(make):
    motor, labels = _demos(n_labels=2, per_label=2)
    with pytest.raises(UserError, match="needs the labels"):
        make().fit(motor)
    peer = make().fit(motor, labels)
    observed = observed_prefix(1, T, 0.5)
    with pytest.raises(UserError, match="needs the test samples' labels"):
        peer.predict(motor[:1], observed)
    with pytest.raises(UserError, match=r"label\(s\) \[7\] have no fitted demonstration"):
        peer.predict(motor[:1], observed, labels=[7])


def test_shape_mismatches_are_user_errors_with_clear_messages():
    motor, labels = _demos(n_labels=2, per_label=2)
    peer = NearestPeer().fit(motor, labels)
    observed = observed_prefix(1, T, 0.5)
    with pytest.raises(UserError, match="motor has 3 joints but the peer was fitted on 2"):
        peer.predict(np.zeros((1, T, 3)), observed)
    with pytest.raises(UserError, match=f"motor has T = 30 steps but the peer was fitted on T = {T}"):
        peer.predict(np.zeros((1, 30, 2)), observed[:, :30])
    with pytest.raises(UserError, match=r"observed must have shape \(n, T\) = \(1, 40\)"):
        peer.predict(motor[:1], observed[:, :20])
    with pytest.raises(UserError, match=r"motor must be a non-empty \(n, T, J\) array"):
        peer.fit(motor[0])
    with pytest.raises(UserError, match="labels must have shape"):
        NearestPeer().fit(motor, labels[:2])
    with pytest.raises(UserError, match="observed marks padding"):
        peer.predict(motor[:1], observed, lengths=[5])
    with pytest.raises(UserError, match="call fit before predict"):
        MeanMotionPeer().predict(motor[:1], observed, labels=[0])


# --- ProMP ------------------------------------------------------------------------------------


def test_promp_missing_package_is_a_user_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "movement_primitives.promp", None)  # import fails
    motor, labels = _demos(n_labels=1, per_label=2)
    with pytest.raises(UserError, match=r"pip install 'primspace\[predict\]'"):
        ProMPPeer().fit(motor, labels)


@pytest.mark.parametrize("n_basis", [4, 9])
def test_imitate_promp_is_the_packages_em_over_demonstrations_of_several_lengths(n_basis):
    pytest.importorskip("movement_primitives")
    rng = np.random.default_rng(3)
    demos = [np.cumsum(rng.normal(size=(n, 3)), axis=0) * 0.1 for n in (20, 31, 20, 25, 20, 25)]
    package = promp_class()(3, n_basis)
    package.imitate([phase(len(y)) for y in demos], demos, n_iter=40)
    ours = imitate_promp(3, n_basis, demos, 40)
    assert type(ours) is type(package)
    np.testing.assert_allclose(ours.weight_mean, package.weight_mean, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ours.weight_cov, package.weight_cov, rtol=1e-9, atol=1e-12)
    assert ours.variance == pytest.approx(package.variance, rel=1e-9)
    assert np.abs(ours.weight_mean).max() > 0.01  # it learned something, not two zero starts


def test_promp_conditioned_on_a_full_prefix_reproduces_it():
    pytest.importorskip("movement_primitives")
    motor, labels = _demos()
    fit_motor, fit_labels, test_motor, test_labels = _split(motor, labels)
    peer = ProMPPeer(n_basis=15, noise=1e-6).fit(fit_motor, fit_labels)
    observed = observed_prefix(len(test_motor), T, 0.6)
    predicted = peer.predict(test_motor, observed, labels=test_labels)
    error = np.abs(predicted - test_motor)[observed]
    prior = np.abs(peer.predict(test_motor, np.zeros_like(observed), labels=test_labels) - test_motor)[observed]
    assert error.max() < 0.03
    assert np.sqrt(np.mean(error**2)) < 0.2 * np.sqrt(np.mean(prior**2))  # the conditioning did it
    assert predicted.shape == test_motor.shape


def test_promp_per_label_beats_one_for_all_on_separated_labels():
    pytest.importorskip("movement_primitives")
    motor, labels = _demos()
    fit_motor, fit_labels, test_motor, test_labels = _split(motor, labels)
    observed = observed_prefix(len(test_motor), T, 0.05)  # 2 steps: the label is the information
    scores = {}
    for per_label in (True, False):
        peer = ProMPPeer(n_basis=10, noise=1e-3, per_label=per_label).fit(fit_motor, fit_labels)
        predicted = peer.predict(test_motor, observed, labels=test_labels)
        scores[per_label] = np.nanmean(unobserved_mse(predicted, test_motor, observed))
    assert scores[True] < 0.1 * scores[False]
    assert scores[True] < 1e-3


def test_promp_conditions_with_the_package_step_by_step():
    pytest.importorskip("movement_primitives")
    motor, labels = _demos(n_labels=2, per_label=3)
    peer = ProMPPeer(n_basis=8, noise=1e-3).fit(motor, labels)
    observed = observed_prefix(1, T, 0.3)
    by_hand = peer.promps_[1]
    phase = np.linspace(0, 1, T)
    for step in np.flatnonzero(observed[0]):
        by_hand = by_hand.condition_position(motor[4, step], 1e-3 * np.eye(2), phase[step], 1.0)
    predicted = peer.predict(motor[[4]], observed, labels=[1])
    assert np.allclose(predicted[0], by_hand.mean_trajectory(np.linspace(0, 1, T)), atol=1e-12)


def test_promp_phase_runs_over_the_valid_steps_and_holds_the_last():
    pytest.importorskip("movement_primitives")
    motor, labels = _demos(n_labels=1, per_label=3)
    peer = ProMPPeer(n_basis=8, noise=1e-3).fit(motor, labels)
    short = 25
    t = np.linspace(0, 1, short)
    sample = 0.8 * _shape(0, t)
    padded = np.full((1, T, 2), np.nan)
    padded[0, :short] = sample
    observed = observed_prefix(1, T, 0.4, lengths=[short])
    out = peer.predict(padded, observed, labels=[0], lengths=[short])
    alone = ProMPPeer(n_basis=8, noise=1e-3).fit(motor, labels)
    unpadded = alone.predict(sample[None], observed[:, :short], labels=[0])
    assert np.allclose(out[0, :short], unpadded[0])
    assert np.allclose(out[0, short:], unpadded[0, -1])


def test_peers_never_read_the_unobserved_steps():
    pytest.importorskip("movement_primitives")
    motor, labels = _demos(n_labels=2, per_label=3)
    observed = observed_prefix(2, T, 0.3)
    query = motor[[1, 4]].copy()
    hidden = query.copy()
    hidden[~observed] = np.nan
    for peer in (ProMPPeer(n_basis=8), NearestPeer(), MeanMotionPeer()):
        peer.fit(motor, labels)
        assert np.array_equal(
            peer.predict(query, observed, labels=[0, 1]), peer.predict(hidden, observed, labels=[0, 1])
        )


def test_best_noise_picks_the_lowest_score_on_the_answer():
    pytest.importorskip("movement_primitives")
    motor, labels = _demos()
    fit_motor, fit_labels, test_motor, test_labels = _split(motor, labels)
    peer = ProMPPeer(n_basis=10, noise=0.5).fit(fit_motor, fit_labels)
    observed = observed_prefix(len(test_motor), T, 0.25)
    choice = best_noise(peer, test_motor, observed, test_labels, candidates=(1e-4, 1e-2, 10.0))
    assert set(choice.scores) == {1e-4, 1e-2, 10.0}
    assert choice.scores[choice.noise] == min(choice.scores.values())
    assert choice.scores[10.0] > choice.scores[choice.noise]  # the candidates do differ
    again = peer.predict(test_motor, observed, test_labels, noise=choice.noise)
    assert np.allclose(unobserved_mse(again, test_motor, observed), choice.mse)
    assert peer.noise == 0.5
    with pytest.raises(UserError, match="noise must be a positive number"):
        best_noise(peer, test_motor, observed, test_labels, candidates=(0.0,))
