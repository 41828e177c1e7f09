"""An amortised encoder from the observed steps to the code, trained on decoded prior draws (issue 39)."""

import copy

import numpy as np
import pytest

from primspace.predict.encoder import EncoderPredictor
from primspace.predict.prior import PriorPredictor
from primspace.predict.prior_map import map_objective, prior_terms
from primspace.train.api import reconstruct
from primspace.train.observe import Observation
from primspace.utils.errors import UserError

# the small runs of the observation tests, shared (pytest registers the imported fixtures here)
from test_observe import eval_set, train_set, trained  # noqa: F401

NAMES = ["reach", "push", "lift"]
#: An encoder trained enough to recover codes (the test of its accuracy).
SMALL = dict(n_train=2048, steps=1000, hidden=128, batch_size=128)
#: A tiny one, for the tests of what the forecast does with the codes it finds.
TINY = dict(n_train=256, steps=50, hidden=32, batch_size=64)


@pytest.fixture(scope="module")
def prior(trained, train_set):
    """The priors, their noise, temperature and blend fixed (no K-fold choice: tested in test_prior.py)."""
    scaled = trained.scaler.transform(train_set.motor)
    fixed = dict(noise=1e-3, temperature=10.0, blend=0.5)
    return PriorPredictor(trained, n_samples=200, label_names=NAMES, **fixed).fit(scaled, train_set.labels)


def _fit(trained, train_set, prior, **kw):
    scaled = trained.scaler.transform(train_set.motor)
    return EncoderPredictor(trained, prior=prior, **{**SMALL, **kw}).fit(scaled, train_set.labels)


@pytest.fixture(scope="module")
def given(trained, train_set, prior):
    return _fit(trained, train_set, prior, given=True, **TINY)


@pytest.fixture(scope="module")
def free(trained, train_set, prior):
    return _fit(trained, train_set, prior, **TINY)


@pytest.mark.parametrize("primitive_given", [True, False])
@pytest.mark.slow
def test_the_encoder_recovers_codes_of_its_training_distribution(primitive_given, prior, trained, train_set):
    """Fresh draws from the priors, decoded and half observed: the encoder trained on the
    decoder's samples as they are finds codes nearer the drawn ones than the prior's mean of
    their primitive (given) or the codes' mean (not given)."""
    encoder = _fit(trained, train_set, prior, given=primitive_given, residuals=0.0)
    rng = np.random.default_rng(11)
    ids = np.repeat(np.arange(3), 20)
    codes = np.concatenate([prior.gaussians_[k].sample(20, rng) for k in range(3)]).astype(np.float32)
    motor = trained.scaler.transform(reconstruct(trained, codes, images=False)[0])
    labels = np.asarray(prior.primitives_.labels)[ids]
    found = encoder.encode(motor, Observation.build(0.5), labels)
    assert found.shape == codes.shape and found.dtype == np.float32
    baseline = np.stack([prior.gaussians_[k].mean for k in ids]) if primitive_given else codes.mean(axis=0)
    err, base = np.mean((found - codes) ** 2), np.mean((baseline - codes) ** 2)
    assert err < 0.5 * base, (err, base)


def test_the_forecast_predicts_the_rest_and_keeps_the_seen_steps(given, trained, eval_set):
    scaled = trained.scaler.transform(eval_set.motor)
    forecast = given.forecast(scaled, Observation.build(0.25), eval_set.labels)
    assert forecast.motor.shape == scaled.shape and np.isfinite(forecast.motor).all()
    assert forecast.codes.shape == (len(eval_set), trained.latents.shape[1])
    # the decoded codes, the jump at the last observed step decaying to zero at the end
    decoded = trained.scaler.transform(reconstruct(trained, forecast.codes, images=False)[0])
    s, end = int(np.ceil(0.25 * eval_set.length)) - 1, eval_set.length - 1
    np.testing.assert_allclose(forecast.motor[:, : s + 1], decoded[:, : s + 1], atol=1e-5)
    ramp = 1.0 - 1.0 / (end - s)
    jump = forecast.motor[:, s + 1] - decoded[:, s + 1]
    np.testing.assert_allclose(jump, ramp * (scaled[:, s] - decoded[:, s]), atol=1e-5)
    assert np.asarray(forecast.details["posterior"]).argmax(axis=1).tolist() == eval_set.labels.tolist()
    assert forecast.details["encoder"]["given"] and forecast.details["encoder"]["fit_seconds"] > 0


def test_same_seed_same_numbers(trained, train_set, prior, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    tiny = dict(n_train=256, steps=20, hidden=16)
    one, again = (_fit(trained, train_set, prior, **tiny) for _ in range(2))
    np.testing.assert_array_equal(again.losses_, one.losses_)
    np.testing.assert_array_equal(again.predict(scaled, rule), one.predict(scaled, rule))
    other = _fit(trained, train_set, prior, random_state=7, **tiny)
    assert not np.array_equal(other.losses_, one.losses_)


def test_an_unfitted_prior_is_fitted_on_a_copy(trained, train_set):
    unfitted = PriorPredictor(trained, n_samples=50, label_names=NAMES)
    encoder = _fit(trained, train_set, unfitted, n_train=64, steps=5)
    assert not hasattr(unfitted, "gaussians_") and encoder.prior_.primitives_.names == NAMES


def test_refinement_lowers_the_map_objective(given, prior, trained, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    refined = copy.copy(given).set_params(refine=10)
    start = given.forecast(scaled, rule, eval_set.labels).codes
    forecast = refined.forecast(scaled, rule, eval_set.labels)
    assert forecast.details["encoder"]["refine"] == 10 and not np.array_equal(forecast.codes, start)
    mask = rule.masks(np.full(len(eval_set), eval_set.length), eval_set.length)[0]
    means, precisions = prior_terms(prior.gaussians_, prior.primitives_.for_labels(eval_set.labels))
    terms = (np.where(mask[..., None], scaled, 0.0), mask, means, precisions, prior.choice(rule)["noise_given"])
    before, after = (map_objective(trained, c, *terms) for c in (start, forecast.codes))
    assert after.mean() < before.mean(), (after, before)


def test_online_equals_the_offline_prefix(given, trained, eval_set):
    scaled = trained.scaler.transform(eval_set.motor)
    t = eval_set.length // 3
    online = given.predict_online(scaled, labels=eval_set.labels, prediction_after=t)
    offline = given.forecast(scaled, Observation.build(int(t)), eval_set.labels)
    np.testing.assert_allclose(trained.scaler.transform(online.prediction), offline.motor, atol=1e-4)
    np.testing.assert_array_equal(online.codes[:, t - 1], offline.codes)
    assert online.errors.shape == (len(eval_set), eval_set.length) and (online.latency > 0).all()
    assert online.init == "encoder" and online.steps.tolist() == list(range(1, eval_set.length + 1))


def test_bad_inputs_are_refused(given, free, trained, train_set, prior, eval_set):
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    with pytest.raises(UserError, match="pass labels"):
        given.forecast(scaled, rule)
    with pytest.raises(UserError, match=r"label\(s\) \[9\] stand for no primitive"):
        given.forecast(scaled, rule, np.full(len(eval_set), 9))
    with pytest.raises(UserError, match=r"run's \(T, J\)"):
        free.forecast(scaled[:, :, :2], rule)
    with pytest.raises(UserError, match="prefix"):
        free.forecast(scaled, np.tile(np.arange(eval_set.length) % 2 == 1, (len(eval_set), 1)))
    with pytest.raises(UserError, match="observe='none'"):
        free.forecast(scaled, Observation.build("none", 0.5))
    with pytest.raises(UserError, match="start_step"):
        free.predict_online(scaled, start_step=0)
    for bad in (
        dict(n_train=1),
        dict(steps=0),
        dict(hidden=2.5),
        dict(lr=-1.0),
        dict(residuals=-1.0),
        dict(prior="prior"),
    ):
        with pytest.raises(UserError, match=next(iter(bad))):
            _fit(trained, train_set, bad.pop("prior", prior), **bad)
