"""The predictor contract, checked on every registered predictor, ours and the peers alike.

As scikit-learn's ``check_estimator`` runs every estimator through the same checks, each
predictor of :data:`primspace.predict.REGISTRY` is built small on one tiny trained run and
checked: ``fit`` returns self; ``predict`` is ``(n, T, J)`` and finite; it reads only the
observed steps (what the unobserved steps hold changes nothing); ``forecast(...).motor`` is
``predict(...)``; the same seed gives the same numbers; online prediction, where offered,
keeps its documented relation to the offline one (and is refused in one line elsewhere); bad
input (a wrong number of joints, an observed mask of the wrong shape) is one UserError line;
``get_params`` survives ``clone``. A predictor class of :mod:`primspace.predict` that is not
registered, or a registered one without settings here, fails the first test.
"""

import importlib
import inspect
import pkgutil

import numpy as np
import pytest
from sklearn.base import clone

from primspace.predict import REGISTRY, MotionPredictor, Predictor, PriorPredictor
from primspace.train.observe import Observation
from primspace.utils.errors import UserError
from test_train import primitives, small_run

#: Fixed noise, temperature and blend of the priors: no K-fold choice.
FIXED = dict(noise=1e-3, temperature=10.0, blend=0.5)
#: Observed steps of the tiny case (of T = 16).
SEEN = 6


def _prior(run):
    return PriorPredictor(run, n_samples=100, **FIXED)


#: Small settings of every registered predictor: ``name -> run -> keywords``.
SETTINGS = {
    "auto": lambda run: dict(
        condition=False, prior_samples=100, reuse=False, peer_settings={"promp_tuned": dict(n_basis=5, n_iter=20)}
    ),
    "mixture": lambda run: dict(condition=False),
    "gradient": lambda run: dict(start="projection", epochs=2, iterations=1, progress=False),
    "prior": lambda run: dict(n_samples=100, **FIXED),
    "prior_map": lambda run: dict(prior=_prior(run), iterations=3),
    "encoder": lambda run: dict(prior=_prior(run), n_train=128, steps=10, hidden=8, batch_size=32),
    "promp": lambda run: dict(per_label=False),
    "nearest": lambda run: dict(),
    "mean_motion": lambda run: dict(),
    "raw_gaussian": lambda run: dict(per_label=False),
    "promp_tuned": lambda run: dict(per_label=False, n_basis=5, n_iter=20),
}
#: The online predictors whose prediction after step t is the offline one of that prefix.
ONLINE_IS_OFFLINE = ("auto", "mixture", "prior", "encoder")


@pytest.fixture(scope="module")
def case():
    train, test = primitives(4, seed=0, T=16), primitives(2, seed=100, T=16)
    run = small_run(train, epochs=5)
    return run, run.scaler.transform(train.motor), train, run.scaler.transform(test.motor), test


def build(name: str, run):
    spec = REGISTRY[name]
    settings = SETTINGS[name](run)
    return spec.cls(run, **settings) if spec.needs_run else spec.cls(**settings)


def fitted(name: str, case):
    run, scaled, train, _, _ = case
    predictor = build(name, run)
    assert predictor.fit(scaled, train.labels, train.valid_lengths) is predictor
    return predictor


def observed(test) -> np.ndarray:
    return np.repeat(np.arange(test.length)[None, :] < SEEN, len(test), axis=0)


def _concrete_predictors() -> set:
    """Every concrete Predictor subclass defined in a module of primspace.predict."""
    import primspace.predict as package

    for info in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"primspace.predict.{info.name}")
    found, todo = set(), [Predictor]
    while todo:
        cls = todo.pop()
        todo.extend(cls.__subclasses__())
        if cls.__module__.startswith("primspace.predict.") and not inspect.isabstract(cls):
            found.add(cls)
    return found


def test_every_predictor_is_registered_and_checked_here():
    assert set(SETTINGS) == set(REGISTRY)
    assert _concrete_predictors() == {spec.cls for spec in REGISTRY.values()}


def test_a_predictor_that_implements_neither_forecast_nor_predict_cannot_be_built():
    class Silent(Predictor):
        def fit(self, motor, labels=None, lengths=None, frames=None):
            return self

    class SilentMotion(MotionPredictor):
        def fit(self, motor, labels=None, lengths=None, frames=None):
            return self

    for cls in (Silent, SilentMotion):
        with pytest.raises(TypeError, match="abstract"):
            cls()


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_the_contract(name, case):
    run, _, _, scaled, test = case
    predictor = fitted(name, case)
    mask, labels, lengths = observed(test), test.labels, test.valid_lengths
    motion = predictor.predict(scaled, mask, labels, lengths)
    assert motion.shape == scaled.shape and np.isfinite(motion).all()
    np.testing.assert_array_equal(predictor.forecast(scaled, mask, labels, lengths).motor, motion)
    hidden = np.where(mask[..., None], scaled, scaled + 3.0)  # the unobserved steps changed: never read
    np.testing.assert_array_equal(predictor.predict(hidden, mask, labels, lengths), motion)
    again = fitted(name, case).predict(scaled, mask, labels, lengths)
    np.testing.assert_array_equal(again, motion)  # same seed, same numbers


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_bad_input_is_one_user_error_line(name, case):
    _, _, _, scaled, test = case
    predictor = fitted(name, case)
    mask, labels, lengths = observed(test), test.labels, test.valid_lengths
    for motor, seen in ((scaled[..., :-1], mask), (scaled, mask[:, :-1])):
        with pytest.raises(UserError) as refused:
            predictor.predict(motor, seen, labels, lengths)
        assert "\n" not in str(refused.value)


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_online_keeps_its_relation_to_the_offline_prediction(name, case):
    run, _, _, scaled, test = case
    predictor = fitted(name, case)
    labels, lengths = test.labels, test.valid_lengths
    if not REGISTRY[name].online:
        with pytest.raises(UserError, match="does not predict online"):
            predictor.predict_online(scaled, lengths, labels)
        return
    result = predictor.predict_online(scaled, lengths, labels, start_step=3, prediction_after=SEEN)
    assert result.codes.shape[:2] == result.errors.shape == (len(test), test.length - 2)
    assert result.latency.shape == (test.length - 2,) and (result.latency >= 0).all()
    if name in ONLINE_IS_OFFLINE:
        if name == "auto":  # online, it chooses among the candidates that predict online (not the peers)
            predictor.set_params(candidates=("mixture", "prior")).fit(*predictor.fitted_)
        offline = predictor.forecast(scaled, Observation.build(SEEN), labels, lengths).motor
        expected = run.scaler.inverse_transform(offline).astype(np.float32)
        np.testing.assert_allclose(result.prediction, expected, rtol=1e-5, atol=1e-5)
    else:  # gradient inference: no iteration leaves every code at its start
        still = clone(predictor).set_params(iterations=0).fit(None)
        result = still.predict_online(scaled, lengths, labels, start_step=3)
        np.testing.assert_array_equal(result.codes, np.repeat(result.start_codes[:, None], result.codes.shape[1], 1))


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_get_params_survive_clone(name, case):
    predictor = build(name, case[0])
    copy = clone(predictor)
    assert type(copy) is type(predictor) and copy.get_params().keys() == predictor.get_params().keys()
    for key, value in predictor.get_params(deep=False).items():
        if isinstance(value, (bool, int, float, str, type(None))):
            assert copy.get_params(deep=False)[key] == value, key
