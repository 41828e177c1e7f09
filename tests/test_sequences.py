"""Sequences of codes (issue 15): the decoder driven by one code per window, the
convolutional random projection that starts them, and the loss masked to each
sample's valid steps."""

import numpy as np
import pytest
import torch

from primspace.data import MotionDataset
from primspace.model.decoder import ModelConfig, MTRNNDecoder, code_interpolation
from primspace.model.latent import LatentInitializer
from primspace.train import TrainConfig, evaluate, fit, infer
from primspace.utils.errors import UserError

SMALL = dict(layer_sizes=(12, 6), p_hidden=16, motor_hidden=16)


def _tc(**kw):
    return TrainConfig(**{"epochs": 3, "batch_size": 4, "seed": 0, **kw})


def _long_demos(n=10, t=24, j=3, seed=0):
    """Sine sequences of different lengths, padded with the last valid value."""
    rng = np.random.default_rng(seed)
    steps = np.linspace(0, 1, t)
    motor = np.stack(
        [
            np.column_stack([np.sin(2 * np.pi * (a * steps + b)) for a, b in rng.uniform(0.5, 2, (j, 2))])
            for _ in range(n)
        ]
    )
    lengths = rng.integers(t // 2, t + 1, n)
    for i, length in enumerate(lengths):
        motor[i, length:] = motor[i, length - 1]
    valid = np.arange(t)[None, :] < lengths[:, None]
    segments = np.where(valid, (np.arange(t)[None, :] >= lengths[:, None] // 2).astype(int), -1)
    labels = np.where(valid, segments % 2, -1)
    return MotionDataset(motor, lengths=lengths, step_labels=labels, step_segments=segments)


# --------------------------------------------------------------- interpolation


def test_codes_are_interpolated_between_window_centres():
    phi = code_interpolation(10, 4)  # K = 3, centres 1.5, 5.5, 9.5
    assert phi.shape == (10, 3)
    torch.testing.assert_close(phi.sum(dim=1), torch.ones(10))
    torch.testing.assert_close(phi[:2], torch.tensor([[1.0, 0.0, 0.0]] * 2))  # before the first centre: z_1
    torch.testing.assert_close(phi[5], torch.tensor([0.125, 0.875, 0.0]))  # 5 is 0.5 before centre 5.5
    assert code_interpolation(5, 10).shape == (5, 1)


def test_the_decoder_reads_one_code_per_window():
    mc = ModelConfig(latent_dim=3, n_joints=2, length=10, code_window=4, **SMALL).validate()
    assert (mc.n_codes, mc.code_size) == (3, 9)
    model = MTRNNDecoder(mc).eval()
    z = torch.randn(2, 9)
    out = model(z)
    assert out.motor.shape == (2, 10, 2)
    changed = z.clone()
    changed[:, 6:] += 1.0  # the last code: its window and the half-window before it
    diff = (model(changed).motor - out.motor).abs().amax(dim=(0, 2))
    assert diff[:6].max() == 0 and diff[6:].min() > 0  # steps before the second centre (5.5) cannot see z_3
    assert "interpolation" not in model.state_dict()  # derived from the config, not a weight


def test_a_bad_code_window_is_refused():
    with pytest.raises(UserError, match="code window"):
        ModelConfig(latent_dim=3, n_joints=2, length=10, code_window=0).validate()
    with pytest.raises(UserError, match="code window"):
        LatentInitializer("projection", 3, window=0).fit(np.zeros((2, 4, 1)))


# ---------------------------------------------------------- the conv projection


def test_conv_projection_is_the_same_P_on_every_window():
    x = np.random.default_rng(1).normal(size=(3, 10, 2))
    init = LatentInitializer("projection", 4, random_state=0, window=4).fit(x)
    z = init.transform(x).reshape(3, 3, 4)
    p = init.projection_
    assert p.shape == (4, 8)
    np.testing.assert_allclose(z[1, 1], p @ x[1, 4:8].reshape(-1), rtol=1e-5)
    last = np.concatenate([x[2, 8:], x[2, [9, 9]]])  # the last window padded with the last step
    np.testing.assert_allclose(z[2, 2], p @ last.reshape(-1), rtol=1e-5, atol=1e-6)


def test_appendix_a_holds_window_by_window():
    """E[z_k(a)·z_k(b)] = a_k·b_k over draws of P (paper, Appendix A), for every window k."""
    rng = np.random.default_rng(2)
    x = rng.normal(size=(2, 12, 2))
    q, draws = 5, 3000
    products = np.empty((draws, 3))
    for s in range(draws):
        z = LatentInitializer("projection", q, random_state=s, window=4).fit(x).transform(x).reshape(2, 3, q)
        products[s] = np.einsum("kq,kq->k", z[0].astype(np.float64), z[1].astype(np.float64))
    windows = x.reshape(2, 3, 8)
    dots = np.einsum("kd,kd->k", windows[0], windows[1])
    stderr = products.std(axis=0, ddof=1) / np.sqrt(draws)
    assert np.all(np.abs(products.mean(axis=0) - dots) < 4 * stderr)
    # and the variance is the Gaussian one, (|a|²|b|² + (a·b)²)/q, per window
    na, nb = (windows**2).sum(axis=2)
    np.testing.assert_allclose(products.var(axis=0), (na * nb + dots**2) / q, rtol=0.15)


def test_zero_random_and_pca_fill_every_window():
    x = np.random.default_rng(3).normal(size=(4, 9, 2))
    for method in ("zero", "random", "pca"):
        z = LatentInitializer(method, 3, random_state=0, window=3).fit_transform(x)
        assert z.shape == (4, 9)
    assert not LatentInitializer("zero", 3, window=3).fit_transform(x).any()


def test_an_initialiser_saved_before_code_windows_loads():
    init = LatentInitializer("projection", 3, random_state=0).fit(np.zeros((2, 4, 1)))
    state = init.state_dict()
    del state["window"]
    assert LatentInitializer.from_state_dict(state).window is None


# ------------------------------------------------------------------- masking


def test_padding_never_enters_the_loss(tmp_path):
    data = _long_demos()
    mc = ModelConfig(latent_dim=3, code_window=6, **SMALL)
    run = fit(data, model_config=mc, train_config=_tc(), progress=False)
    moved = data.motor.copy()
    for i, length in enumerate(data.lengths):
        moved[i, length:] = 0.7  # other padding values (still inside the scaler's range)
    other = MotionDataset(moved, lengths=data.lengths, step_labels=data.step_labels, step_segments=data.step_segments)
    assert evaluate(run, data) == evaluate(run, other)
    assert (
        evaluate(run, MotionDataset(data.motor))["loss"] != evaluate(run, data)["loss"]
    )  # without lengths every step counts


def test_a_code_steps_on_its_own_sample_whatever_the_batch():
    data = _long_demos(n=8)
    mc = ModelConfig(latent_dim=3, code_window=6, **SMALL)
    run = fit(data, model_config=mc, train_config=_tc(epochs=1), progress=False)
    # inference with frozen weights: batch size 1 and 8 give the same codes
    one = infer(run, data, epochs=2, batch_size=1, progress=False)
    eight = infer(run, data, epochs=2, batch_size=8, progress=False)
    np.testing.assert_allclose(one.latents, eight.latents, rtol=1e-4, atol=1e-5)


def test_fit_and_infer_with_code_windows_resume_exactly(tmp_path):
    data = _long_demos()
    mc = ModelConfig(latent_dim=3, code_window=6, **SMALL)
    constant = {"final_lr_fraction": 1.0}  # extended on resume: a decay would be stretched (fit's docstring)
    straight = fit(data, tmp_path / "straight", model_config=mc, train_config=_tc(epochs=4, **constant), progress=False)
    fit(data, tmp_path / "split", model_config=mc, train_config=_tc(epochs=2, **constant), progress=False)
    resumed = fit(
        data, tmp_path / "split", model_config=mc, train_config=_tc(epochs=4, **constant), resume=True, progress=False
    )
    np.testing.assert_array_equal(straight.latents, resumed.latents)
    assert straight.latents.shape == (10, 12)  # K = 24 / 6 = 4 codes of 3
    a = infer(tmp_path / "straight", data, tmp_path / "a", epochs=3, progress=False)
    infer(tmp_path / "straight", data, tmp_path / "b", epochs=1, progress=False)
    b = infer(tmp_path / "straight", data, tmp_path / "b", epochs=3, resume=True, progress=False)
    np.testing.assert_array_equal(a.latents, b.latents)
    assert a.initializer.window == 6


def test_code_smoothness_is_the_total_variation_of_valid_windows():
    from primspace.train.loss import code_variation

    mc = ModelConfig(latent_dim=2, n_joints=1, length=9, code_window=3).validate()  # K = 3
    z = torch.tensor([[0.0, 0.0, 3.0, 4.0, 3.0, 4.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
    assert code_variation(z, mc, None).item() == pytest.approx((5.0 + 1.0) / 2)
    mask = torch.ones(2, 9)
    mask[1, 6:] = 0  # sample 1's last window is padding: its jump does not count
    assert code_variation(z, mc, mask).item() == pytest.approx(5.0 / 2)
    with pytest.raises(UserError, match="code_smoothness"):
        TrainConfig(code_smoothness=-1.0).validate()


def test_code_smoothness_makes_codes_change_less(tmp_path):
    data = _long_demos()
    mc = ModelConfig(latent_dim=3, code_window=6, **SMALL)
    from primspace.train.loss import code_variation

    rates = {"latent_lr": 0.05, "final_lr_fraction": 1.0}  # the 0.8 below was measured at a constant rate
    plain = fit(data, model_config=mc, train_config=_tc(epochs=10, **rates), progress=False)
    smooth = fit(data, model_config=mc, train_config=_tc(epochs=10, code_smoothness=5.0, **rates), progress=False)
    tv = [
        code_variation(torch.from_numpy(r.latents), r.model_config.fitted_to(data), None).item()
        for r in (plain, smooth)
    ]
    assert tv[1] < 0.8 * tv[0]
    assert smooth.history[-1]["loss"] > smooth.history[-1]["motor"]  # the logged loss includes the penalty
