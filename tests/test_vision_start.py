"""The vision-informed start ``projection-vision`` (primspace.train.vision_start): the motor and the
keypoint trajectories of a spatial autoencoder's encoder, projected together."""

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.model.config import ModelConfig
from primspace.model.latent import LatentInitializer
from primspace.train import fit, infer
from primspace.train.config import TrainConfig
from primspace.train.vision_start import VisionProjection, initializer_from_state
from primspace.utils.errors import UserError
from test_train import primitives

MC = ModelConfig(latent_dim=4, layer_sizes=(12, 6), p_hidden=16, motor_hidden=16)
TC = TrainConfig(epochs=1, seed=0, batch_size=6, threads=1)


@pytest.fixture(scope="module")
def frames_set():
    """6 sequences of 10 steps, 3 joints, 8x8 frames of a bright square following two joints."""
    return primitives(2, seed=3, T=10, J=3, images=True)


def _scaled(data):
    from primspace.data import JointScaler

    return JointScaler().fit(data.motor).transform(data.motor)


def _fitted(data, keypoints=2, seed=5, epochs=2):
    vision = VisionProjection(4, keypoints, random_state=seed, epochs=epochs)
    return vision.fit(_scaled(data), data.images, data.valid_lengths)


def _codes(vision, data, **kwargs):
    return vision.transform(_scaled(data), images=data.images, lengths=data.valid_lengths, **kwargs)


def _motor_only(data, seed=5):
    scaled = _scaled(data)
    return LatentInitializer("projection", 4, random_state=seed).fit(scaled).transform(scaled)


def test_same_seed_same_start_and_another_seed_another(frames_set):
    a, b = _codes(_fitted(frames_set), frames_set), _codes(_fitted(frames_set), frames_set)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (6, 4) and a.dtype == np.float32
    assert not np.allclose(a, _codes(_fitted(frames_set, seed=6), frames_set))


def test_the_start_differs_from_the_motor_projection_when_frames_differ(frames_set):
    vision = _fitted(frames_set)
    codes, motor = _codes(vision, frames_set), _motor_only(frames_set)
    kp = vision.trajectories(frames_set.images, frames_set.valid_lengths)
    assert kp.shape == (6, 10, 4)
    # each coordinate scaled as a joint is: its range over the fitted valid steps onto [-1, 1]
    np.testing.assert_allclose(kp.reshape(-1, 4).min(axis=0), -1.0, atol=1e-9)
    np.testing.assert_allclose(kp.reshape(-1, 4).max(axis=0), 1.0, atol=1e-9)
    assert np.ptp(kp, axis=0).max() > 1e-3  # the samples' keypoints differ
    assert not np.allclose(codes, motor, atol=1e-3)
    # the vision part is P_v applied to the keypoint trajectories: z = P_m m + P_v k
    np.testing.assert_allclose(codes, motor + vision.vision.transform(kp), rtol=1e-5, atol=1e-5)


def test_without_keypoints_the_start_is_the_motor_projection(frames_set):
    vision = _fitted(frames_set, keypoints=0)
    np.testing.assert_array_equal(_codes(vision, frames_set), _motor_only(frames_set))
    np.testing.assert_array_equal(vision.transform(_scaled(frames_set)), _motor_only(frames_set))  # no frames read


def test_frames_equal_in_every_sample_move_every_code_by_one_vector(frames_set):
    same = np.repeat(frames_set.images[:1], len(frames_set), axis=0)
    data = MotionDataset(frames_set.motor, images=same)
    shift = _codes(_fitted(data), data).astype(np.float64) - _motor_only(data)
    assert np.abs(shift).max() > 1e-3
    np.testing.assert_allclose(shift, np.repeat(shift[:1], len(shift), axis=0), atol=1e-5)


def test_only_the_observed_steps_count(frames_set):
    vision = _fitted(frames_set)
    every = np.ones((6, 10), dtype=bool)
    np.testing.assert_array_equal(_codes(vision, frames_set, observed=every), _codes(vision, frames_set))
    prefix = every.copy()
    prefix[:, 5:] = False
    changed = frames_set.images.copy()
    changed[:, 5:] = 0  # what was not observed does not move the start
    data = MotionDataset(frames_set.motor, images=changed)
    np.testing.assert_allclose(_codes(vision, data, observed=prefix), _codes(vision, frames_set, observed=prefix))


def test_the_state_round_trips(frames_set):
    vision = _fitted(frames_set)
    again = initializer_from_state(vision.state_dict())
    assert isinstance(again, VisionProjection)
    np.testing.assert_array_equal(_codes(again, frames_set), _codes(vision, frames_set))
    assert isinstance(
        initializer_from_state(LatentInitializer("zero", 4).fit(_scaled(frames_set)).state_dict()), LatentInitializer
    )


def test_inference_start_of_a_fitted_sample_equals_its_fit_start(frames_set, tmp_path):
    run = fit(frames_set, tmp_path / "run", model_config=MC, train_config=TC, init="projection-vision", progress=False)
    assert run.init == "projection-vision" and isinstance(run.initializer, VisionProjection)
    assert not np.allclose(
        run.initial_latents, fit(frames_set, None, model_config=MC, train_config=TC, progress=False).initial_latents
    )
    ev = infer(tmp_path / "run", frames_set, None, epochs=0, progress=False)  # the checkpoint's encoder and P
    np.testing.assert_array_equal(ev.initial_latents, run.initial_latents)
    some = infer(run, frames_set, None, epochs=0, indices=[4, 1], progress=False)
    np.testing.assert_array_equal(some.initial_latents, run.initial_latents[[4, 1]])


def test_refuses_data_without_frames(frames_set, tmp_path):
    with pytest.raises(UserError, match="projection-vision.*has no"):
        fit(
            frames_set.without_images(),
            None,
            model_config=MC,
            train_config=TC,
            init="projection-vision",
            progress=False,
        )
    run = fit(frames_set, None, model_config=MC, train_config=TC, init="projection", progress=False)
    with pytest.raises(UserError, match="run fitted with it"):
        infer(run, frames_set, None, epochs=0, init="projection-vision", progress=False)


def test_cli_trains_and_infers_with_it_and_refuses_data_without_frames(run_cli, frames_set, tmp_path):
    data, bare = tmp_path / "d.h5", tmp_path / "bare.h5"
    frames_set.save(data)
    frames_set.without_images().save(bare)
    args = ("--latent-dim", "4", "--epochs", "1", "--layers", "12,6", "--threads", "1", "--batch-size", "6")
    res = run_cli("train", data, "--init", "projection-vision", "--out", tmp_path / "run", *args)
    assert res.code == 0, res.err
    assert "init projection-vision" in res.out
    res = run_cli("infer", tmp_path / "run", data, "--epochs", "0", "--out", tmp_path / "ev", "--threads", "1")
    assert res.code == 0, res.err
    res = run_cli("train", bare, "--init", "projection-vision", "--out", tmp_path / "no", *args)
    assert_user_error(res, "projection-vision", "frames")
    assert not (tmp_path / "no").exists()
