"""MAP through the decoder under a code prior per primitive (issue 39, deliverable 2b): the
objective falls from the prior's conditioned code, a stiff prior holds the code at its mean,
no iterations decode the start, the primitive given matters, and the numbers repeat."""

import copy

import numpy as np
import pytest

from primspace.predict import unobserved_mse
from primspace.predict.candidates import continuity_correction
from primspace.predict.code_prior import GaussianCode
from primspace.predict.prior import PriorPredictor
from primspace.predict.prior_map import PriorMapPredictor, map_objective, map_refine, prior_terms
from primspace.train import reconstruct
from primspace.train.observe import Observation
from primspace.utils.errors import UserError

# the small runs of the observation tests, shared (pytest registers the imported fixtures here)
from test_observe import eval_set, train_set, trained  # noqa: F401

NAMES = ["reach", "push", "lift"]
#: The prior's draws, and its noise, temperature and blend fixed (no K-fold choice: tested in test_prior.py).
PRIOR = dict(n_samples=200, label_names=NAMES, noise=1e-3, temperature=10.0, blend=0.5)


def _prior(trained, train_set, **kw):
    scaled = trained.scaler.transform(train_set.motor)
    return PriorPredictor(trained, **PRIOR, **kw).fit(scaled, train_set.labels)


@pytest.fixture(scope="module")
def given_prior(trained, train_set):
    return _prior(trained, train_set, given=True)


def _map(trained, train_set, prior, **kw):
    scaled = trained.scaler.transform(train_set.motor)
    return PriorMapPredictor(trained, prior=prior, **kw).fit(scaled, train_set.labels)


def _error(forecast, scaled, rule):
    n, steps = scaled.shape[:2]
    return unobserved_mse(forecast.motor, scaled, rule.masks(np.full(n, steps), steps)[0]).mean()


def _terms(predictor, scaled, rule, labels):
    """The MAP's observed steps and prior terms for ``labels`` (as the predictor builds them)."""
    mask = rule.masks(np.full(len(scaled), scaled.shape[1]), scaled.shape[1])[0]
    means, precisions = prior_terms(predictor.prior_.gaussians_, labels)
    r = predictor.prior_.choice(rule)["noise_given"]
    return np.where(mask[..., None], scaled, 0.0), mask, means, precisions, r


def test_the_objective_falls_from_the_conditioned_code(given_prior, trained, train_set, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    predictor = _map(trained, train_set, given_prior, iterations=100)
    forecast = predictor.forecast(scaled, rule, eval_set.labels)
    inner = given_prior.forecast(scaled, rule, eval_set.labels)
    terms = _terms(predictor, scaled, rule, eval_set.labels)
    before = map_objective(trained, inner.codes, *terms)
    after = map_objective(trained, forecast.codes, *terms)
    assert (after < before).all(), (before, after)
    record = forecast.details["map"]
    assert record["iterations"] == 100 and record["objective_end"] < record["objective_start"]
    assert np.isclose(record["objective_start"], before.mean()) and np.isclose(record["objective_end"], after.mean())
    assert forecast.codes.shape == inner.codes.shape and np.isfinite(forecast.motor).all()
    np.testing.assert_array_equal(forecast.details["posterior"], inner.details["posterior"])
    assert forecast.details["prior"] == inner.details["prior"]


@pytest.mark.slow
def test_a_stiff_prior_holds_the_code_at_its_mean(given_prior, trained, train_set, eval_set):
    """A tiny covariance (a huge prior weight): from the mean the code stays there; from the
    conditioned code it goes there."""
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.5)
    stiff = copy.copy(given_prior)
    q = trained.latents.shape[1]
    stiff.gaussians_ = [GaussianCode(g.mean, 1e-8 * np.eye(q), g.family) for g in given_prior.gaussians_]
    predictor = _map(trained, train_set, stiff, iterations=300, lr=0.05)
    seen, mask, means, precisions, r = _terms(predictor, scaled, rule, eval_set.labels)
    held = map_refine(trained, means, seen, mask, means, precisions, r, 100, 0.01)
    np.testing.assert_allclose(held, means, atol=1e-4)
    forecast = predictor.forecast(scaled, rule, eval_set.labels)
    start = given_prior.forecast(scaled, rule, eval_set.labels).codes
    gap = np.abs(forecast.codes - means).max()
    assert gap < 1e-2 < np.abs(start - means).max(), gap


def test_no_iterations_decode_the_start(given_prior, trained, train_set, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    forecast = _map(trained, train_set, given_prior, iterations=0).forecast(scaled, rule, eval_set.labels)
    start = given_prior.forecast(scaled, rule, eval_set.labels).codes
    np.testing.assert_array_equal(forecast.codes, start)
    decoded = trained.scaler.transform(reconstruct(trained, start, images=False)[0])
    mask = rule.masks(np.full(len(scaled), scaled.shape[1]), scaled.shape[1])[0]
    expected = continuity_correction(decoded, np.where(mask[..., None], scaled, 0.0), mask, np.ones_like(mask))
    np.testing.assert_allclose(forecast.motor, expected, rtol=1e-6, atol=1e-6)
    assert forecast.details["map"]["objective_end"] == forecast.details["map"]["objective_start"]


def test_the_primitive_given_beats_another(given_prior, trained, train_set, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    predictor = _map(trained, train_set, given_prior)
    own = _error(predictor.forecast(scaled, rule, eval_set.labels), scaled, rule)
    other = _error(predictor.forecast(scaled, rule, (eval_set.labels + 1) % 3), scaled, rule)
    assert own < other, (own, other)


def test_the_same_seed_gives_the_same_numbers(trained, train_set, eval_set):
    """Two predictors fitted afresh (the prior cloned and fitted inside) agree to the bit."""
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.5)
    prior = PriorPredictor(trained, **PRIOR, random_state=5)
    runs = [
        _map(trained, train_set, prior, given=True, iterations=50, start="best_member").forecast(
            scaled, rule, eval_set.labels
        )
        for _ in range(2)
    ]
    assert not hasattr(prior, "gaussians_")  # the given unfitted prior is left as it was
    np.testing.assert_array_equal(runs[0].motor, runs[1].motor)
    np.testing.assert_array_equal(runs[0].codes, runs[1].codes)
    assert runs[0].details["map"]["start"] == "best_member"


def test_without_the_primitive_the_top_one_is_refined(given_prior, trained, train_set, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.5)
    posterior = given_prior.asked()  # the same fitted priors, asked without the primitive
    predictor = _map(trained, train_set, posterior, iterations=20)
    assert not predictor.needs_labels
    forecast = predictor.forecast(scaled, rule)
    weights = np.asarray(forecast.details["posterior"])
    assert weights.shape == (len(eval_set), 3) and np.allclose(weights.sum(axis=1), 1.0)
    assert forecast.details["map"]["objective_end"] <= forecast.details["map"]["objective_start"]
    assert PriorMapPredictor(trained, prior=posterior, given=True).needs_labels


def test_bad_settings_are_named(given_prior, trained, train_set, eval_set):
    with pytest.raises(UserError, match="start must be one of conditioned, best_member"):
        _map(trained, train_set, given_prior, start="mean")
    scaled = trained.scaler.transform(eval_set.motor)
    terms = _terms(_map(trained, train_set, given_prior), scaled, Observation.build(0.5), eval_set.labels)
    with pytest.raises(UserError, match="iterations must be a whole number"):
        map_refine(trained, terms[2], *terms, -1, 0.01)
    with pytest.raises(UserError, match="lr must be a finite number > 0"):
        map_refine(trained, terms[2], *terms, 5, 0.0)
    with pytest.raises(UserError, match="r must be finite and > 0"):
        map_refine(trained, terms[2], *terms[:4], 0.0, 5, 0.01)
