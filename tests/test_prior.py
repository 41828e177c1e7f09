"""Priors in code space per primitive, and the primitive as an input (issue 39): the prior's
family chosen by held-out likelihood, its decoded draws conditioned given the primitive or
weighted by the posterior over primitives, the K-fold choices, and online filtering."""

import numpy as np
import pytest

from primspace.predict import unobserved_mse
from primspace.predict.code_prior import DecodedGaussian, SequentialGaussian, StepGains, choose_prior, fit_gaussian
from primspace.predict.primitives import primitives_from_clusters, primitives_from_labels
from primspace.predict.prior import PriorPredictor
from primspace.train.observe import Observation
from primspace.utils.errors import UserError

# the small runs of the observation tests, shared (pytest registers the imported fixtures here)
from test_observe import eval_set, train_set, trained  # noqa: F401

NAMES = ["reach", "push", "lift"]
#: Fixed noise, temperature and blend: no K-fold choice (for the tests that do not test it).
FIXED = dict(noise=1e-3, temperature=10.0, blend=0.5)


def _fit(trained, train_set, **kw):
    scaled = trained.scaler.transform(train_set.motor)
    kw.setdefault("label_names", NAMES)
    return PriorPredictor(trained, **{"n_samples": 200, **kw}).fit(scaled, train_set.labels)


@pytest.fixture(scope="module")
def posterior(trained, train_set):
    return _fit(trained, train_set)


@pytest.fixture(scope="module")
def given(posterior):
    """The same fitted priors given each motion's label, sharing the K-fold folds and choices."""
    posterior._folds()  # drawn and decoded once, before the copy, for both
    return posterior.asked(given=True)


def _errors(forecast, scaled, rule, n, steps):
    observed = rule.masks(np.full(n, steps), steps)[0]
    return unobserved_mse(forecast.motor, scaled, observed)


def test_the_primitive_asked_for_is_the_one_predicted(given, trained, eval_set):
    """Given each motion's own primitive the rest is predicted better than given another."""
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    own = given.forecast(scaled, rule, eval_set.labels)
    other = given.forecast(scaled, rule, (eval_set.labels + 1) % 3)
    err_own = _errors(own, scaled, rule, len(eval_set), eval_set.length).mean()
    err_other = _errors(other, scaled, rule, len(eval_set), eval_set.length).mean()
    assert np.isfinite(own.motor).all() and err_own < err_other, (err_own, err_other)
    assert own.codes.shape == (len(eval_set), trained.latents.shape[1])
    posterior = np.asarray(own.details["posterior"])
    np.testing.assert_array_equal(posterior.argmax(axis=1), eval_set.labels)  # given: one-hot on the label


def test_the_posterior_finds_the_primitive_and_is_calibrated(posterior, trained, eval_set):
    scaled = trained.scaler.transform(eval_set.motor)
    forecast = posterior.forecast(scaled, Observation.build(0.5))
    weights = np.asarray(forecast.details["posterior"])
    assert weights.shape == (len(eval_set), 3) and np.allclose(weights.sum(axis=1), 1.0)
    assert (weights.argmax(axis=1) == eval_set.labels).mean() >= 2 / 3
    choice = forecast.details["prior"]
    assert choice["noise"] in (1e-5, 1e-4, 1e-3, 1e-2) and choice["temperature"] >= 1.0
    assert choice["primitives"]["names"] == NAMES and choice["family"][0] in ("shrunk", "factor", "subspace")


def test_a_primitive_by_name_or_id_predicts_every_motion_as_it(trained, train_set, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    by_name = _fit(trained, train_set, primitive="push", **FIXED).forecast(scaled, rule)
    by_id = _fit(trained, train_set, primitive=1, **FIXED).forecast(scaled, rule)
    np.testing.assert_allclose(by_name.motor, by_id.motor)
    assert (np.asarray(by_name.details["posterior"]).argmax(axis=1) == 1).all()
    assert by_name.details["prior"]["primitive"] == "push"


def test_bad_primitives_name_those_available(trained, train_set):
    with pytest.raises(UserError, match=r"unknown primitive 'jump': the run's primitives are 0 \(reach\), 1 \(push\)"):
        _fit(trained, train_set, primitive="jump")
    with pytest.raises(UserError, match="primitive 7 is out of range"):
        _fit(trained, train_set, primitive=7)
    with pytest.raises(UserError, match="no labels"):
        PriorPredictor(trained).fit(trained.scaler.transform(train_set.motor), None)


def test_given_needs_the_labels(given, trained, eval_set):
    scaled = trained.scaler.transform(eval_set.motor)
    with pytest.raises(UserError, match="pass labels"):
        given.forecast(scaled, Observation.build(0.25))
    with pytest.raises(UserError, match=r"label\(s\) \[9\] stand for no primitive"):
        given.forecast(scaled, Observation.build(0.25), np.full(len(eval_set), 9))


def test_same_seed_same_numbers(posterior, trained, train_set, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    again = _fit(trained, train_set)
    np.testing.assert_array_equal(again.forecast(scaled, rule).motor, posterior.forecast(scaled, rule).motor)
    other = _fit(trained, train_set, random_state=7)
    assert not np.array_equal(other.ensembles_[0].mean, posterior.ensembles_[0].mean)


def test_clusters_found_without_labels_are_primitives(trained, train_set):
    prims = primitives_from_clusters(trained.latents, 3, train_set.labels, NAMES)
    assert prims.count == 3 and prims.source == "clusters" and (prims.assignment >= 0).all()
    unnamed = primitives_from_clusters(trained.latents, 3)
    assert unnamed.names == ["cluster 0", "cluster 1", "cluster 2"] and unnamed.resolve("2") == 2
    fitted = _fit(trained, train_set, primitives="clusters")
    assert fitted.primitives_.count == 3


def test_labels_name_the_primitives():
    prims = primitives_from_labels(np.array([2, 0, 2, -1]), ["a", "b", "c"])
    assert prims.names == ["a", "c"] and prims.assignment.tolist() == [1, 0, 1, -1]
    np.testing.assert_array_equal(prims.for_labels([2, 0]), [1, 0])
    assert prims.resolve("c") == 1 and prims.resolve(0) == 0


def test_the_held_out_likelihood_chooses_the_family_the_codes_come_from():
    """Codes on a 2-dimensional affine subspace of 12 dimensions with a tiny spread: a low-rank
    family wins; codes from an isotropic Gaussian: full shrinkage (or equivalent) wins."""
    rng = np.random.default_rng(0)
    basis = rng.standard_normal((2, 12))
    flat = [rng.standard_normal((40, 2)) @ basis + 1e-3 * rng.standard_normal((40, 12)) + 5 * k for k in range(3)]
    assert choose_prior(flat)["family"][0] in ("factor", "subspace")
    round_ = [rng.standard_normal((40, 12)) + 5 * k for k in range(3)]
    chosen = choose_prior(round_)
    assert chosen["scores"]["shrunk 1"] > chosen["scores"]["subspace 0.99"]


def test_a_gaussian_of_one_code_borrows_the_pooled_spread():
    g = fit_gaussian(np.ones((1, 4)), ("shrunk", 0.1), pooled_var=0.5)
    np.testing.assert_allclose(np.diag(g.cov), 0.5, rtol=1e-4)


@pytest.mark.parametrize("members", [50, 5])  # more members than observed entries, and fewer (Woodbury)
def test_conditioning_is_the_gaussian_formula(members):
    rng = np.random.default_rng(1)
    ens = DecodedGaussian(rng.standard_normal((members, 12)), 10)
    mask = np.zeros(12, bool)
    mask[:7] = True
    x = rng.standard_normal((3, 7))
    means, evidence = ens.conditioned(mask, 0.1).update(x)
    cov = ens.deviations.T @ ens.deviations
    s = cov[:7, :7] + 0.1 * np.eye(7)
    expect = ens.mean + (x - ens.mean[:7]) @ np.linalg.solve(s, cov[:7])
    np.testing.assert_allclose(means, expect, atol=1e-10)
    from scipy.stats import multivariate_normal

    np.testing.assert_allclose(evidence, multivariate_normal(ens.mean[:7], s).logpdf(x), rtol=1e-8)


def test_the_sequential_filter_equals_the_batch_update():
    rng = np.random.default_rng(2)
    ens = DecodedGaussian(rng.standard_normal((30, 15)), 12)
    x = rng.standard_normal((4, 9))
    seq = SequentialGaussian(StepGains(ens, 0.05, 3, 4), 4)
    for t in range(3):
        seq.observe(t, x[:, 3 * t : 3 * t + 3])
    mask = np.zeros(15, bool)
    mask[:9] = True
    means, evidence = ens.conditioned(mask, 0.05).update(x)
    np.testing.assert_allclose(seq.means, means, atol=1e-9)
    np.testing.assert_allclose(seq.evidence, evidence, rtol=1e-9)


def test_online_equals_the_offline_prefix(posterior, trained, eval_set):
    scaled = trained.scaler.transform(eval_set.motor)
    t = eval_set.length // 2
    online = posterior.predict_online(scaled, prediction_after=t)
    offline = posterior.forecast(scaled, Observation.build(int(t)))
    np.testing.assert_allclose(trained.scaler.transform(online.prediction), offline.motor, atol=1e-4)
    assert online.errors.shape == (len(eval_set), eval_set.length) and (online.latency > 0).all()


def test_a_blend_has_the_moments_of_the_mixture():
    rng = np.random.default_rng(3)
    data, model = rng.standard_normal((20, 6)) + 1.0, rng.standard_normal((40, 6))
    a, b = DecodedGaussian(data, 4), DecodedGaussian(model, 4)
    mixed = DecodedGaussian.blend(a, b, 0.3)
    cov = lambda g: g.deviations.T @ g.deviations  # noqa: E731
    np.testing.assert_allclose(mixed.mean, 0.3 * a.mean + 0.7 * b.mean)
    gap = np.outer(a.mean - b.mean, a.mean - b.mean)
    np.testing.assert_allclose(cov(mixed), 0.3 * cov(a) + 0.7 * cov(b) + 0.21 * gap, atol=1e-12)
    assert DecodedGaussian.blend(a, b, 1.0) is a and DecodedGaussian.blend(None, b, 0.7) is b


def test_the_blend_of_one_predicts_from_the_fitted_demonstrations_alone(trained, train_set, eval_set):
    """blend=1: the fitted pairs' own Gaussian; its prediction does not depend on the draws."""
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.5)
    fixed = dict(given=True, noise=1e-3, temperature=1.0, blend=1.0, n_samples=50)
    one = _fit(trained, train_set, **fixed).forecast(scaled, rule, eval_set.labels)
    other = _fit(trained, train_set, random_state=5, **fixed).forecast(scaled, rule, eval_set.labels)
    np.testing.assert_allclose(one.motor, other.motor)
    draws = _fit(trained, train_set, **{**fixed, "blend": 0.0}).forecast(scaled, rule, eval_set.labels)
    assert not np.allclose(one.motor, draws.motor)
