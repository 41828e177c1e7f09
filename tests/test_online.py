"""Online inference as predictive coding (issue 25, item 3): the codes corrected after each
arriving step, the forecast of the remaining steps, and the offline reference."""

import numpy as np
import pytest

from primspace.data import MotionDataset
from primspace.model.config import ModelConfig
from primspace.predict.online import OnlineInference, infer_online, offline_errors
from primspace.train import TrainConfig, fit, infer, reconstruct
from primspace.utils.errors import UserError
from test_train import SMALL, primitives

FAST = dict(batch_size=12, threads=1, final_lr_fraction=1.0)  # online steps at a constant rate, as infer here
MODEL = ModelConfig(latent_dim=20, layer_sizes=(16, 8), taus=(2.0, 8.0), p_hidden=32, motor_hidden=32)


pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)


@pytest.fixture(scope="module")
def trained(one_thread):
    return fit(
        primitives(12, seed=0),
        model_config=MODEL,
        train_config=TrainConfig(epochs=100, **FAST),
        init="projection",
        progress=False,
    )


@pytest.fixture(scope="module")
def eval_set():
    return primitives(3, seed=100)  # 9 samples, T = 30, J = 4


def _padded(data: MotionDataset, lengths) -> MotionDataset:
    lengths = np.asarray(lengths)
    valid = np.arange(data.length)[None, :] < lengths[:, None]
    steps = np.where(valid, 0, -1)
    return MotionDataset(data.motor, lengths=lengths, step_labels=steps, step_segments=steps)


def _scaled_mse(run, predicted, data) -> float:
    return float(np.mean((run.scaler.transform(predicted) - run.scaler.transform(data.motor)) ** 2))


# ------------------------------------------------------------------ the same loss as infer


@pytest.mark.slow
def test_one_step_is_infer_from_that_many_steps(trained, eval_set):
    """The first arriving step's k iterations are infer(observe=t, epochs=k): same start, loss and Adam."""
    online = OnlineInference(trained, eval_set, iterations=15, start_step=10)
    online.step()
    offline = infer(trained, eval_set, epochs=15, observe=10, batch_size=len(eval_set), progress=False)
    assert not np.allclose(online.codes, online.start_codes, atol=1e-3)  # it moved
    np.testing.assert_allclose(online.codes, offline.latents, atol=2e-5)


def test_a_code_window_model_steps_as_infer(eval_set):
    """Codes per window: the whole sequence decoded, the unobserved steps masked; the smoothness term as infer's."""
    mc = ModelConfig(latent_dim=3, layer_sizes=(12, 6), p_hidden=16, motor_hidden=16, code_window=10)
    lengths = np.array([30, 20, 12, 30, 25, 16, 30, 8, 22])
    data = _padded(eval_set, lengths)
    run = fit(data, model_config=mc, train_config=TrainConfig(epochs=2, code_smoothness=0.1, **FAST), progress=False)
    online = OnlineInference(run, data, iterations=5, start_step=14)
    online.step()
    offline = infer(run, data, epochs=5, observe=14, batch_size=len(data), progress=False)
    assert online.codes.shape == (9, 9)
    np.testing.assert_allclose(online.codes, offline.latents, atol=2e-5)
    result = infer_online(run, data, iterations=1)
    assert np.isfinite(result.codes).all() and result.codes.shape == (9, 30, 9)


@pytest.mark.slow
def test_all_observed_reconstructs_about_as_well_as_infer(trained, eval_set):
    result = infer_online(trained, eval_set, iterations=10)
    assert result.steps.tolist() == list(range(1, 31)) and result.codes.shape == (9, 30, MODEL.latent_dim)
    assert np.isnan(result.errors[:, -1]).all()  # nothing left to forecast after the last step
    offline = infer(
        trained, eval_set, epochs=300, initial_latents=result.start_codes, batch_size=len(eval_set), progress=False
    )  # the same start, every step observed from the first epoch
    online_mse = _scaled_mse(trained, result.prediction, eval_set)
    offline_mse = _scaled_mse(trained, reconstruct(trained, offline.latents)[0], eval_set)
    start_mse = _scaled_mse(trained, reconstruct(trained, result.start_codes)[0], eval_set)
    np.testing.assert_allclose(result.prediction, reconstruct(trained, result.codes[:, -1])[0], atol=1e-5)
    assert online_mse < 0.1 * start_mse, (online_mse, start_mse)
    assert online_mse < 1.5 * offline_mse, (online_mse, offline_mse)  # about as well (here 1.05x)


# ------------------------------------------------------------------------ the forecast


@pytest.mark.slow
def test_the_forecast_improves_as_more_is_observed(trained, eval_set):
    result = infer_online(trained, eval_set, iterations=20)
    early, late = result.error_at(3), result.error_at(18)  # 10 % and 60 % of T = 30 observed
    assert late < 0.6 * early, (early, late)
    predicted = trained.scaler.transform(reconstruct(trained, result.codes[:, result.column(18)])[0])
    truth = trained.scaler.transform(eval_set.motor)
    expected = np.mean(((predicted - truth)[:, 18:]) ** 2, axis=(1, 2))  # the steps after 18, per sample
    np.testing.assert_allclose(result.errors[:, result.column(18)], expected, rtol=1e-4)
    assert result.latency.shape == (30,) and 0 < result.latency_mean <= result.latency_p95 <= result.latency.max()


def test_offline_errors_read_the_same_measure(trained, eval_set):
    offline = offline_errors(trained, eval_set, [3, 18], epochs=5, batch_size=len(eval_set))
    inferred = infer(trained, eval_set, epochs=5, observe=18, batch_size=len(eval_set), progress=False)
    predicted = trained.scaler.transform(reconstruct(trained, inferred.latents)[0])
    expected = np.mean(((predicted - trained.scaler.transform(eval_set.motor))[:, 18:]) ** 2, axis=(1, 2))
    np.testing.assert_allclose(offline["errors"][:, 1], expected, rtol=1e-4)
    assert offline["steps"].tolist() == [3, 18] and offline["mean_error"].shape == (2,)


# -------------------------------------------------------------- determinism, warm start


@pytest.mark.slow
def test_same_seed_same_codes_and_no_iterations_keep_the_start(trained, eval_set):
    a = infer_online(trained, eval_set, iterations=3, init="random", seed=7)
    b = infer_online(trained, eval_set, iterations=3, init="random", seed=7)
    assert np.array_equal(a.codes, b.codes) and np.array_equal(a.errors, b.errors, equal_nan=True)
    other = infer_online(trained, eval_set, iterations=3, init="random", seed=8)
    assert not np.array_equal(a.start_codes, other.start_codes)
    for init in ("projection", "random"):
        still = infer_online(trained, eval_set, iterations=0, init=init, start_step=4)
        assert still.steps.tolist() == list(range(4, 31))
        assert (still.codes == still.start_codes[:, None, :]).all()  # k = 0: the code stays the start
        start = infer(trained, eval_set, epochs=0, init=init, observe=4, progress=False).initial_latents
        assert np.array_equal(still.start_codes, start)  # infer(observe=start_step)'s start


def test_steps_not_yet_arrived_never_count(trained, eval_set):
    changed = eval_set.motor.copy()
    changed[:, 10:] += np.random.default_rng(0).normal(0, 0.5, changed[:, 10:].shape)
    other = MotionDataset(changed, labels=eval_set.labels)
    a = infer_online(trained, eval_set, iterations=2)
    b = infer_online(trained, other, iterations=2)
    assert np.array_equal(a.codes[:, :10], b.codes[:, :10])  # after steps 1..10: the same codes
    assert not np.array_equal(a.codes[:, 10], b.codes[:, 10])  # step 11 differs, and is seen


# --------------------------------------------------------------------------- padding


@pytest.mark.slow
def test_padding_never_counts(trained, eval_set):
    lengths = np.array([30, 20, 12, 30, 25, 16, 30, 8, 22])
    data = _padded(eval_set, lengths)
    moved = eval_set.motor.copy()
    pad = np.arange(30)[None, :] >= lengths[:, None]
    moved[pad] += 3.0  # only the padding changes
    other = _padded(MotionDataset(moved), lengths)
    a = infer_online(trained, data, iterations=3)
    b = infer_online(trained, other, iterations=3)
    assert np.array_equal(a.codes, b.codes)
    assert np.array_equal(a.errors, b.errors, equal_nan=True)
    left = a.steps[None, :] < lengths[:, None]  # valid steps remain after step t
    assert np.isnan(a.errors[~left]).all() and np.isfinite(a.errors[left]).all()
    whole = infer_online(trained, eval_set, iterations=3)
    assert not np.array_equal(a.codes[:, -1], whole.codes[:, -1])  # the valid lengths do matter
    column = a.column(10)
    predicted = trained.scaler.transform(reconstruct(trained, a.codes[:, column])[0])
    squared = ((predicted - trained.scaler.transform(eval_set.motor)) ** 2).mean(axis=2)
    expected = [squared[i, 10:n].mean() if n > 10 else np.nan for i, n in enumerate(lengths)]
    np.testing.assert_allclose(a.errors[:, column], expected, rtol=1e-4)  # steps 11..length only


# ------------------------------------------------------------------------------ frames


def test_frames_count_up_to_the_step_observed():
    data = primitives(3, seed=3, T=12, J=3, images=True)
    run = fit(data, model_config=SMALL, train_config=TrainConfig(epochs=2, **FAST), progress=False)
    with_frames = infer_online(run, data, iterations=2)
    motor_only = infer_online(run, data, iterations=2, images=False)
    assert not np.array_equal(with_frames.codes, motor_only.codes)  # the vision term counts
    changed = data.images.copy()
    changed[:, 6:] = 255 - changed[:, 6:]
    other = MotionDataset(data.motor, images=changed, labels=data.labels)
    moved = infer_online(run, other, iterations=2)
    assert np.array_equal(with_frames.codes[:, :6], moved.codes[:, :6])  # frames 7.. not yet seen
    assert not np.array_equal(with_frames.codes[:, 6], moved.codes[:, 6])
    online = OnlineInference(run, data, iterations=4, start_step=5)
    online.step()
    offline = infer(run, data, epochs=4, observe=5, batch_size=len(data), progress=False)
    np.testing.assert_allclose(online.codes, offline.latents, atol=2e-5)  # infer's loss, frames included


# ------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(iterations=-1), "iterations must be a whole number >= 0, got -1"),
        (dict(iterations=1.5), "iterations must be a whole number >= 0, got 1.5"),
        (dict(iterations=True), "iterations must be a whole number >= 0, got True"),
        (dict(iterations="3"), "iterations must be a whole number >= 0, got '3'"),
        (dict(iterations=1, init="bogus"), "unknown latent init 'bogus'"),
        (dict(iterations=1, start_step=0), "start_step must be a whole number >= 1, got 0"),
        (dict(iterations=1, start_step=31), "start_step must be in 1..T=30, got 31"),
        (dict(iterations=1, latent_lr=0.0), "latent_lr must be a finite number > 0, got 0.0"),
    ],
)
def test_bad_arguments_are_refused_in_one_line(trained, eval_set, kwargs, message):
    with pytest.raises(UserError) as info:
        infer_online(trained, eval_set, **kwargs)
    assert message in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    "shape, message",
    [
        ((9, 20, 4), "T=20 steps x J=4 joints, the model expects T=30 x J=4"),
        ((9, 30, 3), "T=30 steps x J=3 joints, the model expects T=30 x J=4"),
    ],
)
def test_data_of_another_shape_is_refused(trained, shape, message):
    data = MotionDataset(np.zeros(shape, dtype=np.float32))
    for call in (
        lambda: infer_online(trained, data, iterations=1),
        lambda: offline_errors(trained, data, [2], epochs=1),
    ):
        with pytest.raises(UserError) as info:
            call()
        assert message in str(info.value) and "\n" not in str(info.value)


def test_other_refusals(trained, eval_set):
    with pytest.raises(UserError, match="expected a MotionDataset"):
        infer_online(trained, eval_set.motor, iterations=1)
    with pytest.raises(UserError, match=r"steps must be one or more steps in 1..T=30, got \[31\]"):
        offline_errors(trained, eval_set, [31], epochs=1)
    online = OnlineInference(trained, eval_set, iterations=0, start_step=30)
    online.step()
    with pytest.raises(UserError, match="all T=30 steps have been observed"):
        online.step()
