"""Inference from partial observations (issue 25, item 1): the observation masks, the
masked loss, the starts under observation and Appendix A for the observed part."""

import numpy as np
import pytest

from primspace import AutoDecoder
from primspace.data import MotionDataset
from primspace.model.latent import appendix_a_observed
from primspace.train import TrainConfig, fit, infer
from primspace.train.loss import DataTensors
from primspace.train.observe import Observation, observation_masks
from primspace.utils.errors import UserError
from test_train import SMALL, primitives

FAST = dict(batch_size=12, threads=1)
STARTS = ("zero", "random", "pca", "projection", "calibrated", "nearest")


@pytest.fixture(scope="module")
def train_set():
    return primitives(8, seed=0)


@pytest.fixture(scope="module")
def eval_set():
    return primitives(4, seed=100)


@pytest.fixture(scope="module")
def trained(train_set):
    return fit(
        train_set, model_config=SMALL, train_config=TrainConfig(epochs=30, **FAST), init="projection", progress=False
    )


@pytest.fixture(scope="module")
def image_set():
    return primitives(3, seed=3, T=12, J=3, images=True)


@pytest.fixture(scope="module")
def image_run(image_set):
    return fit(image_set, model_config=SMALL, train_config=TrainConfig(epochs=2, **FAST), progress=False)


def _infer(run, data, **kw):
    return infer(run, data, epochs=kw.pop("epochs", 3), progress=False, **kw)


# ------------------------------------------------------------------------ the rule


def test_the_rule_gives_prefixes_within_the_valid_steps():
    lengths = np.array([10, 4, 1])
    motor, frames = Observation.build(0.25, "first").masks(lengths, 10)
    assert motor.sum(axis=1).tolist() == [3, 1, 1]  # ceil(2.5), ceil(1.0), at least 1
    assert (motor == (np.arange(10) < motor.sum(axis=1, keepdims=True))).all()  # prefixes
    assert frames.sum(axis=1).tolist() == [1, 1, 1] and frames[:, 0].all()
    motor, frames = Observation.build(6).masks(lengths, 10)
    assert motor.sum(axis=1).tolist() == [6, 4, 1] and (frames == motor).all()  # capped; frames follow motor
    motor, frames = Observation.build("none", 0.5).masks(lengths, 10)
    assert not motor.any() and frames.sum(axis=1).tolist() == [5, 2, 1]
    assert Observation.build(None) is None
    motor, _ = Observation.build(0.1).masks(np.array([30]), 30)
    assert motor.sum() == 3  # 0.1 * 30 is 3 steps, not 4 by floating point


@pytest.mark.parametrize("bad", [0, -2, 0.0, 1.5, -0.1, float("nan"), "half", True, [0.5]])
def test_bad_observe_values_are_refused(bad):
    with pytest.raises(UserError, match="observe"):
        Observation.build(bad)


def test_bad_frames_values_and_nothing_observed_are_refused():
    with pytest.raises(UserError, match="observe_frames"):
        Observation.build(0.5, "second")
    with pytest.raises(UserError, match="observe_frames"):
        Observation.build(0.5, 0)
    with pytest.raises(UserError, match="nothing to infer from"):
        Observation.build("none")
    with pytest.raises(UserError, match="nothing to infer from"):
        Observation.build("none", "none")


def test_refusals_of_infer(trained, train_set, eval_set, image_set):
    with pytest.raises(UserError, match="has no frames"):
        _infer(trained, eval_set, observe=0.5, observe_frames="first")
    with pytest.raises(UserError, match="no image head"):
        _infer(trained, eval_set, observe="none", observe_frames="first")
    with pytest.raises(UserError, match="must be in"):
        _infer(trained, eval_set, observe=2.0)
    with pytest.raises(UserError, match="no data file"):
        _infer(trained, eval_set, init="nearest")
    with pytest.raises(UserError, match="not its data"):
        _infer(trained, eval_set, init="nearest", fitted_data=eval_set)
    with pytest.raises(UserError, match="unknown latent init 'nearest'"):
        fit(train_set, model_config=SMALL, train_config=TrainConfig(epochs=1, **FAST), init="nearest", progress=False)
    no_head = fit(
        image_set, model_config=SMALL, train_config=TrainConfig(epochs=1, **FAST), images=False, progress=False
    )
    with pytest.raises(UserError, match="no image head"):
        _infer(no_head, image_set, observe="none", observe_frames="first")
    with pytest.raises(UserError, match="does not use frames"):
        _infer(no_head, image_set, observe=0.5, observe_frames="first")


# ------------------------------------------------------------------------ the loss


def test_observe_one_is_todays_inference_bit_for_bit(trained, eval_set):
    today = _infer(trained, eval_set)
    full = _infer(trained, eval_set, observe=1.0)
    assert np.array_equal(today.latents, full.latents)
    assert [h["loss"] for h in today.history] == [h["loss"] for h in full.history]
    assert "observe" not in today.config and full.config["observe"] == {"motor": 1.0, "frames": 1.0}


@pytest.mark.parametrize("init", ["zero", "projection"])
def test_the_loss_ignores_unobserved_entries(trained, eval_set, init):
    changed = eval_set.motor.copy()
    changed[:, 10:] += np.random.default_rng(0).normal(0, 0.5, changed[:, 10:].shape)  # after 10 of 30 steps
    other = MotionDataset(changed, labels=eval_set.labels)
    a = _infer(trained, eval_set, observe=10, init=init)
    b = _infer(trained, other, observe=10, init=init)
    assert np.array_equal(a.latents, b.latents)
    assert not np.array_equal(a.latents, _infer(trained, other, init=init).latents)  # all steps: they differ


def test_frame_masks_first_and_none(image_run, image_set):
    first = DataTensors.build(image_set, image_run.scaler, True, "cpu", Observation.build(None, "first"))
    assert first.motor_mask is None  # every joint value observed: the padding mask (none here)
    assert first.frame_mask[:, 0].eq(1).all() and first.frame_mask[:, 1:].eq(0).all()
    changed = image_set.images.copy()
    changed[:, 1:] = 255 - changed[:, 1:]
    other = MotionDataset(image_set.motor, images=changed, labels=image_set.labels)
    a = _infer(image_run, image_set, observe_frames="first")
    b = _infer(image_run, other, observe_frames="first")
    assert np.array_equal(a.latents, b.latents)  # frames after the first are not seen
    none = _infer(image_run, image_set, observe=0.5, observe_frames="none")
    assert all(h["vision"] == 0.0 for h in none.history)
    frames_only = _infer(image_run, image_set, observe="none", observe_frames="first", init="zero")
    assert all(h["motor"] == 0.0 for h in frames_only.history) and frames_only.history[-1]["vision"] > 0
    with pytest.raises(UserError, match="observe='none' observes none"):
        _infer(image_run, image_set, observe="none", observe_frames="first", init="projection")


# ------------------------------------------------------------------------ the starts


@pytest.mark.parametrize("init", STARTS)
def test_each_start_runs_under_observation(trained, train_set, eval_set, init):
    run = _infer(trained, eval_set, observe=0.25, init=init, fitted_data=train_set, epochs=2)
    assert run.latents.shape == (len(eval_set), SMALL.latent_dim)
    assert np.isfinite(run.latents).all() and np.isfinite(run.final_loss)


def test_projection_start_is_p_of_the_zero_filled_sequence(trained, eval_set):
    run = _infer(trained, eval_set, observe=0.4, init="projection", epochs=0)
    observed = observation_masks(Observation.build(0.4), eval_set)[0]
    zero_filled = trained.scaler.transform(eval_set.motor) * observed[..., None]
    expected = zero_filled.reshape(len(eval_set), -1) @ trained.initializer.projection_.T
    np.testing.assert_allclose(run.initial_latents, expected, rtol=1e-5, atol=1e-6)
    assert np.array_equal(run.initial_latents, trained.initializer.transform(zero_filled))


def test_nearest_returns_a_fitted_code(trained, train_set, eval_set):
    run = _infer(trained, eval_set, observe=0.5, init="nearest", fitted_data=train_set, epochs=0)
    for row in run.initial_latents:
        assert any(np.array_equal(row, code) for code in trained.latents)
    own = _infer(trained, train_set, observe=0.5, init="nearest", fitted_data=train_set, epochs=0)
    assert np.array_equal(own.initial_latents, trained.latents)  # each fitted sample is nearest to itself


def test_calibrated_for_the_fraction_is_kept_by_the_predictor_and_starts_lower(trained, train_set, eval_set):
    from primspace.predict import GradientPredictor, fit_predictor
    from primspace.train.observe import Observation

    cal = _infer(trained, eval_set, observe=0.25, init="calibrated", fitted_data=train_set, epochs=0)
    assert np.isfinite(cal.initial_latents).all()
    predictor = fit_predictor(GradientPredictor(trained, "calibrated", epochs=0), trained, train_set)
    rule = Observation.build(0.25)
    start = predictor.start_codes(eval_set, trained.scaler.transform(eval_set.motor), rule)
    ((key, cached),) = predictor.cache_.items()
    assert key == (0.25, 0.25)
    np.testing.assert_allclose(start, cal.initial_latents, rtol=1e-5, atol=1e-6)  # the same start as infer's
    predictor.start_codes(eval_set, trained.scaler.transform(eval_set.motor), rule)
    assert predictor.cache_[key] is cached  # reused, not fitted again
    raw = _infer(trained, eval_set, observe=0.25, init="projection", epochs=0)
    assert cal.history[0]["loss"] < raw.history[0]["loss"]


def test_observation_is_recorded_and_checked_on_resume(trained, eval_set, tmp_path):
    run = infer(trained, eval_set, tmp_path / "ev", epochs=2, observe=0.5, progress=False)
    assert run.config["observe"] == {"motor": 0.5, "frames": 0.5}
    with pytest.raises(UserError, match="observe differs"):
        infer(trained, eval_set, tmp_path / "ev", epochs=3, observe=0.25, resume=True, progress=False)
    with pytest.raises(UserError, match="observe differs"):
        infer(trained, eval_set, tmp_path / "ev", epochs=3, resume=True, progress=False)
    more = infer(trained, eval_set, tmp_path / "ev", epochs=3, observe=0.5, resume=True, progress=False)
    assert more.epoch == 3


def test_autodecoder_transform_under_observation(train_set, eval_set):
    model = AutoDecoder(SMALL, TrainConfig(epochs=2, **FAST), init="projection", progress=False).fit(train_set)
    z = model.transform(eval_set, epochs=1, observe=0.5, init="nearest")
    assert z.shape == (len(eval_set), SMALL.latent_dim)
    assert model.inference_.config["observe"]["motor"] == 0.5


# ---------------------------------------------------------------------- Appendix A


def test_appendix_a_holds_for_the_observed_part():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(12, 3)), rng.normal(size=(12, 3))
    b += 0.8 * a  # correlated, so the scalar product is well away from 0
    observed = np.arange(12) < 5
    out = appendix_a_observed(a, b, observed, latent_dim=8, n_draws=4000, random_state=1)
    dot_obs = float(np.sum(a[:5] * b[:5]))
    assert out["dot"] == pytest.approx(dot_obs)
    assert abs(out["mean_z"]) < 4
    assert out["var"] <= out["var_bound"] * 1.1
    assert abs(out["var"] / out["var_exact"] - 1) < 0.15
    assert abs(dot_obs - float(np.sum(a * b))) > 5 * out["mean_stderr"]  # the observed part's product, not the whole's
    with pytest.raises(UserError):
        appendix_a_observed(a, b, observed[:4], latent_dim=8)


# ------------------------------------------------------------- the frames-only start


def _linear_scene(n: int, seed: int):
    """Frames whose first frame is ``base + a1 pattern1 + a2 pattern2`` (a in [0, 1]²); the rest noise."""
    fixed = np.random.default_rng(77)
    base, patterns = fixed.uniform(40, 120, (8, 8, 3)), fixed.uniform(-1, 1, (2, 8, 8, 3)) * 60
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 1, (n, 2))
    frames = rng.integers(0, 256, (n, 6, 8, 8, 3)).astype(np.uint8)
    frames[:, 0] = np.clip(np.round(base + np.einsum("nk,khwc->nhwc", a, patterns)), 0, 255).astype(np.uint8)
    motor = rng.normal(0, 1, (n, 6, 2)).cumsum(axis=1)
    return MotionDataset(motor, images=frames), a


@pytest.fixture(scope="module")
def linear_scene():
    """A tiny image run whose fitted codes are set to a linear function of the first frame's parameters."""
    import dataclasses

    train, a = _linear_scene(16, seed=0)
    test, b = _linear_scene(6, seed=1)
    run = fit(train, model_config=SMALL, train_config=TrainConfig(epochs=1, **FAST), progress=False)
    weights = np.random.default_rng(5).normal(0, 1, (2, SMALL.latent_dim))
    codes = lambda x: (0.5 + x @ weights).astype(np.float32)  # noqa: E731
    run = dataclasses.replace(run, latents=codes(a))
    return run, train, test, codes(b)


def _frames_start(run, data, rule, fitted, cache=None):
    """The frames start of ``data`` (infer's ``calibrated`` under ``observe='none'``), fitted on ``fitted``."""
    from primspace.train.starts import FittedDemonstrations, fitted_samples, fitted_start

    demos = FittedDemonstrations.of(run, fitted_samples(run, fitted))
    observed = observation_masks(rule, data)[0]
    return fitted_start(run, "calibrated", demos, data, run.scaler.transform(data.motor), observed, rule, cache)


def test_the_frames_start_recovers_codes_linear_in_the_first_frame(linear_scene):
    run, train, test, truth = linear_scene
    rule = Observation.build("none", "first")
    start = _frames_start(run, test, rule, train)
    err_frames = float(np.sqrt(np.mean((start - truth) ** 2)))
    err_zero = float(np.sqrt(np.mean(truth**2)))
    assert err_frames < 0.1 * err_zero, (err_frames, err_zero)
    changed = test.images.copy()
    changed[:, 1:] = 255 - changed[:, 1:]  # frames after the first are not observed
    again = _frames_start(run, MotionDataset(test.motor, images=changed), rule, train)
    np.testing.assert_array_equal(again, start)
    inferred = infer(
        run,
        test,
        epochs=0,
        observe="none",
        observe_frames="first",
        init="calibrated",
        fitted_data=train,
        progress=False,
    )  # infer's own start is this one
    np.testing.assert_allclose(inferred.initial_latents, start, rtol=1e-5, atol=1e-6)
    cache = {}
    _frames_start(run, test, rule, train, cache)
    assert ("frames", "none", "first") in cache  # a predictor keeps it


def test_the_frames_start_is_deterministic_for_a_seed(linear_scene):
    import dataclasses

    from primspace.train.frames_start import frame_matrix

    run, train, test, _ = linear_scene
    rule = Observation.build("none", 0.5)
    fresh = lambda r: r  # noqa: E731 - nothing is cached on a run
    a = _frames_start(fresh(run), test, rule, train)
    b = _frames_start(fresh(run), test, rule, train)
    np.testing.assert_array_equal(a, b)
    assert np.array_equal(frame_matrix(0, 3, 6, 10), frame_matrix(0, 3, 6, 10))
    assert not np.array_equal(frame_matrix(0, 3, 6, 10), frame_matrix(1, 3, 6, 10))  # another run seed
    assert not np.array_equal(frame_matrix(0, 3, 6, 10), frame_matrix(0, 4, 6, 10))  # another step
    other = fresh(dataclasses.replace(run, train_config=dataclasses.replace(run.train_config, seed=9)))
    assert not np.array_equal(_frames_start(other, test, rule, train), a)


def test_the_frames_projection_in_chunks_is_the_whole_projection():
    from primspace.train.frames_start import frame_matrix, frames_projection

    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (5, 4, 3, 2, 3)).astype(np.uint8)
    observed = np.arange(4)[None, :] < np.array([1, 2, 3, 4, 0])[:, None]
    mean = rng.uniform(0, 1, (3, 2, 3))
    x = (images.astype(np.float64) / 255 - mean).reshape(5, 4, -1) * observed[..., None]
    whole = sum(x[:, t] @ frame_matrix(3, t, 5, 18).T.astype(np.float64) for t in range(4))
    chunked = frames_projection(images, observed, mean, 5, 3, budget=1)  # one step at a time
    np.testing.assert_allclose(chunked, whole, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(frames_projection(images, observed, mean, 5, 3), whole, rtol=1e-4, atol=1e-5)
    assert np.all(chunked[4] == 0)  # nothing observed: the mean frame, projected to zero


def test_the_frames_start_refuses_in_one_line(linear_scene, image_set):
    run, train, test, _ = linear_scene
    rule = Observation.build("none", "first")
    with pytest.raises(UserError, match=r"^init 'calibrated' from frames alone .* the data set has no frames$"):
        _frames_start(run, test.without_images(), rule, train)
    with pytest.raises(UserError, match="the fitted data has no frames"):
        _frames_start(run, test, rule, train.without_images())
    no_head = fit(
        image_set, model_config=SMALL, train_config=TrainConfig(epochs=1, **FAST), images=False, progress=False
    )
    with pytest.raises(UserError, match="needs a run with an image head"):
        _frames_start(no_head, image_set, rule, image_set)
    with pytest.raises(UserError, match="start by 'calibrated' \\(from the frames\\)"):
        _infer(run, test, observe="none", observe_frames="first", init="pca", fitted_data=train)
    with pytest.raises(UserError, match="has no frames"):  # infer's own check, before any start
        _infer(run, test.without_images(), observe="none", observe_frames="first", init="calibrated", fitted_data=train)


def test_nearest_without_observed_joints_is_refused(image_run, image_set):
    """Issue 38, item 3: with no joint observed, 'nearest' has nothing to compare and started
    every sample from fitted demonstration 0; it is refused in one line, as the other starts are."""
    from primspace.predict import predict

    with pytest.raises(UserError, match=r"'nearest' .* observe='none' observes none"):
        _infer(image_run, image_set, observe="none", observe_frames="first", init="nearest", fitted_data=image_set)
    with pytest.raises(UserError, match=r"'nearest' .* observe='none' observes none"):
        predict(
            image_run,
            image_set,
            observe="none",
            observe_frames="first",
            init="nearest",
            fitted_data=image_set,
            epochs=1,
        )
