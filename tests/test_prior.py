"""The prior in code space per primitive (issue 39's first piece): a Gaussian over each
primitive's fitted codes, its draws decoded once and conditioned on the observed steps."""

import numpy as np
import pytest

from primspace.errors import UserError
from primspace.predict import unobserved_mse
from primspace.predict.prior import GaussianCodePrior
from primspace.train.observe import Observation

# the small runs of the observation tests, shared (pytest registers the imported fixtures here)
from test_observe import eval_set, train_set, trained  # noqa: F401


@pytest.fixture(scope="module")
def prior(trained, train_set):
    return GaussianCodePrior(trained, n_samples=300).fit(None, train_set.labels)


def test_the_primitive_asked_for_is_the_one_predicted(prior, trained, eval_set):
    """Given each motion's own primitive the prediction of the rest is better than given another."""
    scaled, rule = trained.scaler.transform(eval_set.motor), Observation.build(0.25)
    observed = rule.masks(np.full(len(eval_set), eval_set.length), eval_set.length)[0]
    own = prior.forecast(scaled, rule, eval_set.labels)
    other = prior.forecast(scaled, rule, (eval_set.labels + 1) % 3)
    err_own = unobserved_mse(own.motor, scaled, observed).mean()
    err_other = unobserved_mse(other.motor, scaled, observed).mean()
    assert np.isfinite(own.motor).all() and err_own < err_other, (err_own, err_other)
    assert own.codes.shape == (len(eval_set), trained.latents.shape[1])
    assert set(own.details["prior"]) == {"n_samples", "noise"}


def test_the_draws_follow_the_seed_and_the_codes_of_each_primitive(prior, trained, train_set):
    again = GaussianCodePrior(trained, n_samples=300).fit(None, train_set.labels)
    for label in prior.codes_:
        np.testing.assert_array_equal(again.codes_[label], prior.codes_[label])
        own = trained.latents[train_set.labels == label]
        assert np.allclose(prior.codes_[label].mean(axis=0), own.mean(axis=0), atol=0.35 * own.std() + 1e-6)
    other = GaussianCodePrior(trained, n_samples=300, random_state=7).fit(None, train_set.labels)
    assert not np.array_equal(other.codes_[0], prior.codes_[0])


def test_the_prior_needs_the_primitive(prior, trained, train_set, eval_set):
    scaled = trained.scaler.transform(eval_set.motor)
    with pytest.raises(UserError, match="pass labels"):
        prior.forecast(scaled, Observation.build(0.25))
    with pytest.raises(UserError, match=r"label\(s\) \[9\] have no fitted demonstration"):
        prior.forecast(scaled, Observation.build(0.25), np.full(len(eval_set), 9))
    with pytest.raises(UserError, match="needs the labels"):
        GaussianCodePrior(trained).fit(None, None)
