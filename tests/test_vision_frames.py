"""The vision loss on K drawn frames per sequence (TrainConfig.vision_frames): the same
frames as the full decoder, an unbiased estimate of the full loss, exact resume, and
K >= T identical to the exact loss."""

import numpy as np
import pytest
import torch

from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.train import TrainConfig, evaluate, fit
from primspace.train.loss import DataTensors, batch_loss
from primspace.utils.errors import UserError
from test_train import primitives

SMALL = ModelConfig(
    latent_dim=5, layer_sizes=(16, 8), taus=(2.0, 8.0), p_hidden=16, motor_hidden=16, image_channels=(8, 4)
)


@pytest.fixture(scope="module")
def data():
    return primitives(4, seed=0, T=12, images=True)  # 12 sequences of 12 steps, 8x8 frames


def test_frames_at_given_steps_are_the_full_decoders_frames(data):
    torch.manual_seed(0)
    model = MTRNNDecoder(SMALL.fitted_to(data, images=True)).eval()
    z = torch.randn(3, 5)
    steps = torch.tensor([[0, 5, 11], [7, 7, 2], [3, 1, 10]])
    with torch.no_grad():
        full = model(z).images
        some = model(z, frame_steps=steps).images
    assert some.shape == (3, 3, 8, 8, 3)
    for b in range(3):
        torch.testing.assert_close(some[b], full[b, steps[b]], rtol=1e-5, atol=1e-6)


def test_k_frame_loss_is_an_unbiased_estimate(data):
    torch.manual_seed(1)
    mc = SMALL.fitted_to(data, images=True)
    model = MTRNNDecoder(mc).eval()
    tc = TrainConfig(vision_frames=3)
    from primspace.data import JointScaler

    tensors = DataTensors.build(data, JointScaler().fit(data.motor), True, torch.device("cpu"))
    idx = torch.arange(len(data))
    z = torch.randn(len(data), 5)
    ctx = torch.no_grad()
    with ctx:
        exact = batch_loss(model, z, idx, tensors, tc, torch.no_grad())[1][2].item()
        g = torch.Generator().manual_seed(0)
        draws = [
            batch_loss(
                model, z, idx, tensors, tc, torch.no_grad(), torch.rand(len(data), 12, generator=g).argsort(1)[:, :3]
            )[1][2].item()
            for _ in range(400)
        ]
    spread = np.std(draws) / np.sqrt(len(draws))
    assert np.std(draws) > 0  # the draws differ: K frames are a real sample
    assert abs(np.mean(draws) - exact) < 4 * spread  # unbiased, within 4 standard errors


def test_k_at_least_t_is_the_exact_loss_and_k_changes_the_run(data, tmp_path):
    base = dict(epochs=2, batch_size=6, threads=1, seed=0)
    exact = fit(data, model_config=SMALL, train_config=TrainConfig(**base), progress=False)
    same = fit(data, model_config=SMALL, train_config=TrainConfig(**base, vision_frames=12), progress=False)
    np.testing.assert_array_equal(exact.latents, same.latents)
    k4 = fit(data, model_config=SMALL, train_config=TrainConfig(**base, vision_frames=4), progress=False)
    assert not np.array_equal(k4.latents, exact.latents)
    assert [h["epoch"] for h in k4.history] == [0, 1, 2] and k4.history[0] == pytest.approx(
        {**exact.history[0], "seconds": k4.history[0]["seconds"], "samples_per_s": k4.history[0]["samples_per_s"]}
    )
    full = evaluate(k4, data)  # evaluate always uses every frame
    assert full["vision"] is not None and full["vision"] > 0


def test_resume_with_k_frames_continues_exactly(data, tmp_path):
    tc = TrainConfig(
        epochs=4, batch_size=6, threads=1, seed=0, vision_frames=3, checkpoint_every=1, final_lr_fraction=1.0
    )  # extended on resume: a decay would be stretched (fit's docstring)
    straight = fit(data, tmp_path / "straight", model_config=SMALL, train_config=tc, progress=False)
    half = TrainConfig(**{**tc.to_dict(), "epochs": 2})
    fit(data, tmp_path / "split", model_config=SMALL, train_config=half, progress=False)
    resumed = fit(data, tmp_path / "split", model_config=SMALL, train_config=tc, resume=True, progress=False)
    np.testing.assert_array_equal(resumed.latents, straight.latents)
    assert [h["loss"] for h in resumed.history] == [h["loss"] for h in straight.history]


def test_bad_vision_frames_is_refused():
    with pytest.raises(UserError, match="vision_frames must be a whole number >= 1"):
        TrainConfig(vision_frames=0).validate()
