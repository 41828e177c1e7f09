"""The Gaussian peers: the raw trajectories' Gaussian and the tuned ProMP, their settings chosen by K-fold
prediction of the fitted demonstrations (never the answer), and the share of a prediction through the decoder."""

import inspect

import numpy as np
import pytest

from primspace.predict.code_prior import fold_split
from primspace.predict.gaussian_peers import RawGaussianPeer, TunedProMPPeer
from primspace.predict.metrics import unobserved_mse
from primspace.predict.peers import ProMPPeer
from primspace.predict.registry import built_on_run, model_share
from primspace.train.observe import Observation
from primspace.utils.errors import UserError
from test_train import primitives


@pytest.fixture(scope="module")
def data():
    train, test = primitives(6, seed=0, T=20), primitives(3, seed=100, T=20)
    scale = np.abs(train.motor).max()
    return train.motor / scale, train.labels, test.motor / scale, test.labels


def test_the_raw_gaussian_is_the_conditioned_gaussian_of_the_demonstrations(data):
    x, labels, y, test_labels = data
    peer = RawGaussianPeer(per_label=True, noise=1e-4).fit(x, labels)
    observed = Observation.build(0.25).masks(np.full(len(y), 20), 20)[0]
    got = peer.predict(y, observed, test_labels)
    # written out: mean and covariance of the label's flattened demonstrations, Gaussian conditioning
    i, own = 0, x[labels == test_labels[0]].reshape(-1, 80)
    mean, cov = own.mean(axis=0), np.cov(own, rowvar=False)
    o = np.flatnonzero(np.repeat(observed[0], 4))
    gain = cov[:, o] @ np.linalg.inv(cov[np.ix_(o, o)] + 1e-4 * np.eye(len(o)))
    expected = mean + gain @ (y[i].reshape(-1)[o] - mean[o])
    np.testing.assert_allclose(got[i].reshape(-1), expected, atol=1e-8)


@pytest.mark.slow
def test_the_tuned_promp_with_fixed_settings_is_the_packages_conditioning(data):
    x, labels, y, test_labels = data
    observed = Observation.build(0.25).masks(np.full(len(y), 20), 20)[0]
    sequential = ProMPPeer(n_basis=6, noise=1e-3, n_iter=30).fit(x, labels).predict(y, observed, test_labels)
    batch = TunedProMPPeer(n_basis=6, ridge=0.0, noise=1e-3, n_iter=30).fit(x, labels).predict(y, observed, test_labels)
    np.testing.assert_allclose(batch, sequential, atol=1e-8)


def test_the_settings_are_chosen_on_the_fitted_data_only(data, monkeypatch):
    from primspace.predict import gaussian_peers

    assert min(gaussian_peers.BASIS_GRID) == 10 and max(gaussian_peers.BASIS_GRID) == 40  # the range
    # a smaller grid of basis counts and ridges (the choice's rule is the same for any grid)
    monkeypatch.setattr(gaussian_peers, "BASIS_GRID", (4, 8))
    monkeypatch.setattr(gaussian_peers, "RIDGE_GRID", (0.0, 1e-4))
    x, labels, y, test_labels = data
    rule = Observation.build(0.25)
    peer = TunedProMPPeer(n_basis="auto", n_iter=30).fit(x, labels)
    first = peer.forecast(y, rule, test_labels)
    # the test motions' unobserved steps replaced by anything: the same choice, the same prediction
    observed = rule.masks(np.full(len(y), 20), 20)[0]
    other = np.where(observed[..., None], y, 5.0)
    again = TunedProMPPeer(n_basis="auto", n_iter=30).fit(x, labels).forecast(other, rule, test_labels)
    assert again.details["setting"] == first.details["setting"]
    np.testing.assert_array_equal(again.motor, first.motor)
    assert first.details["model_share"] == 0.0
    scores = peer.choices_[rule.key]["scores"]
    assert (
        len(scores) == 2 * 2 * len(gaussian_peers.NOISE_GRID)
        and min(scores.values()) == scores[repr(first.details["setting"])]
    )


def test_the_tuned_raw_gaussian_beats_its_worst_setting_on_the_test_motions(data):
    x, labels, y, test_labels = data
    rule = Observation.build(0.25)
    observed = rule.masks(np.full(len(y), 20), 20)[0]
    tuned = RawGaussianPeer().fit(x, labels).predict(y, rule, test_labels)
    errors = [
        np.nanmean(unobserved_mse(RawGaussianPeer(noise=r).fit(x, labels).predict(y, rule, test_labels), y, observed))
        for r in (1e-5, 1e-2)
    ]
    assert np.nanmean(unobserved_mse(tuned, y, observed)) <= max(errors)


def test_the_folds_are_the_priors_split():
    groups = [np.arange(0, 7), np.arange(7, 12)]
    folds = fold_split(groups, 13, [0, 39, 2])
    assert folds[12] == -1 and set(folds[:12]) == set(range(5))
    rng = np.random.default_rng([0, 39, 2])
    own = rng.permutation(groups[0])
    assert folds[own[0]] == 0 and folds[own[1]] == 1


def test_bad_settings_are_one_user_error():
    with pytest.raises(UserError, match="n_basis"):
        TunedProMPPeer(n_basis=1).fit(np.zeros((4, 5, 2)), np.array([0, 0, 1, 1]))
    with pytest.raises(UserError, match="noise"):
        RawGaussianPeer(noise="big").fit(np.zeros((4, 5, 2)), np.array([0, 0, 1, 1]))


def test_the_model_share_of_each_kind_of_predictor():
    from primspace.predict import REGISTRY
    from primspace.predict.peers import NearestPeer

    assert model_share({}, built_on_run(NearestPeer())) == 0.0  # "nearest" is a gradient start's name too
    assert model_share({"model_share": 0.0}, False) == 0.0
    assert model_share({}, True) == 1.0  # the mixture, a gradient start: they decode codes
    assert model_share({"model_share": 0.5}, True) == 0.5  # the prior's share of decoded draws
    assert {name for name, spec in REGISTRY.items() if spec.needs_run} == {
        name for name, spec in REGISTRY.items() if "run" in inspect.signature(spec.cls).parameters
    }


class _Fragile(TunedProMPPeer):
    """A tuned ProMP over basis counts 5 and 6 whose fit with 6 fails (as the package's EM may)."""

    def settings(self):
        return [{"n_basis": b, "ridge": 0.0, "noise": 1e-3} for b in self.bases]

    def fit_group(self, motor, lengths, key):
        if key == 6:
            raise np.linalg.LinAlgError("SVD did not converge")
        return super().fit_group(motor, lengths, key)


@pytest.mark.slow
def test_a_setting_that_cannot_be_fitted_is_not_chosen(data):
    x, labels, y, test_labels = data
    rule = Observation.build(0.25)
    peer = _Fragile(n_iter=20)
    peer.bases = (6, 5)
    forecast = peer.fit(x, labels).forecast(y, rule, test_labels)
    assert forecast.details["setting"]["n_basis"] == 5
    assert np.isnan(peer.choices_[rule.key]["scores"][repr({"n_basis": 6, "ridge": 0.0, "noise": 1e-3})])
    peer = _Fragile(n_iter=20)
    peer.bases = (6, 6)
    with pytest.raises(UserError, match="no setting can be fitted"):
        peer.fit(x, labels).forecast(y, rule, test_labels)
