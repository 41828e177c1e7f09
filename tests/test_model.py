"""The MTRNN decoder: one layer step by hand, the batched dynamics, shapes, configs, FLOPs."""

import math

import numpy as np
import pytest
import torch
from torch.utils.flop_counter import FlopCounterMode

from primspace.model.decoder import ImageDecoder, ModelConfig, MTRNNDecoder, MTRNNLayer
from primspace.utils.errors import UserError


def _randomise(module: torch.nn.Module, seed: int = 0) -> None:
    """Give every parameter (LayerNorm's affine too) non-trivial values."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            p.copy_(torch.randn(p.shape, generator=g) * 0.5)


def test_layer_step_matches_hand_computation():
    k, l_, tau = 3, 2, 4.0
    layer = MTRNNLayer(k, l_, tau)
    _randomise(layer)
    d = np.array([[0.3, -1.2, 0.8]])
    u = np.array([[0.5, -0.7]])
    W, U, A, b = (p.detach().double().numpy() for p in (layer.W, layer.U, layer.A, layer.b))
    gamma, beta = layer.norm.weight.detach().double().numpy(), layer.norm.bias.detach().double().numpy()
    # the paper's formula, written out element by element
    h = np.zeros(k)
    for i in range(k):
        drive = b[i]
        for j in range(k):
            drive += W[i, j] * d[0, j]
        for m in range(l_):
            drive += U[i, m] * u[0, m]
        for j in range(k):
            for m in range(l_):
                drive += A[i, j, m] * d[0, j] * u[0, m]
        h[i] = (1 - 1 / tau) * d[0, i] + drive / tau
    mean = h.mean()
    var = ((h - mean) ** 2).mean()
    expected = (h - mean) / math.sqrt(var + layer.norm.eps) * gamma + beta

    got = layer.step(torch.tensor(d, dtype=torch.float32), torch.tensor(u, dtype=torch.float32))
    np.testing.assert_allclose(got.detach().numpy()[0], expected, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("sizes,taus", [((8, 6, 4), (1.5, 3.0, 6.0)), ((5,), (2.0,)), ((32, 12), (2.0, 8.0))])
def test_batched_dynamics_equal_step_by_step(sizes, taus):
    cfg = ModelConfig(latent_dim=5, layer_sizes=sizes, taus=taus, n_joints=3, length=9)
    torch.manual_seed(1)
    model = MTRNNDecoder(cfg)
    _randomise(model, seed=2)
    z = torch.randn(4, 5)
    fast = model.dynamics(z)
    # reference: every layer stepped with the paper's formula, top-down within a step
    states = model.initial_states(z)
    u_top = model.p(z)
    expected = []
    for _ in range(cfg.length):
        for i in range(len(sizes) - 1, -1, -1):
            u = u_top if i == len(sizes) - 1 else states[i + 1]
            states[i] = model.layers[i].step(states[i], u)
        expected.append(states[0])
    torch.testing.assert_close(fast, torch.stack(expected, 1), rtol=1e-4, atol=1e-5)


def test_shapes_without_images():
    cfg = ModelConfig(latent_dim=6, n_joints=9, length=61)
    out = MTRNNDecoder(cfg)(torch.randn(3, 6))
    assert out.motor.shape == (3, 61, 9)
    assert out.images is None
    assert out.fast_states.shape == (3, 61, 32)


def test_shapes_with_images_and_range():
    cfg = ModelConfig(latent_dim=6, n_joints=9, length=7, image_size=(48, 64), image_channels=(8, 4, 4))
    model = MTRNNDecoder(cfg)
    out = model(torch.randn(2, 6))
    assert out.motor.shape == (2, 7, 9)
    assert out.images.shape == (2, 7, 48, 64, 3)
    assert float(out.images.detach().min()) >= 0.0 and float(out.images.detach().max()) <= 1.0
    assert model(torch.randn(2, 6), images=False).images is None


def test_images_of_all_steps_come_from_one_head_call():
    cfg = ModelConfig(latent_dim=3, n_joints=2, length=5, image_size=(8, 8), image_channels=(4,) * 3)
    model = MTRNNDecoder(cfg)
    calls = []
    model.image_head.register_forward_hook(lambda mod, inp, out: calls.append(inp[0].shape))
    model(torch.randn(4, 3))
    assert calls == [torch.Size([4 * 5, 32])]


@pytest.mark.parametrize("size", [(50, 64), (48, 60), (4, 8)])
def test_image_size_the_head_cannot_produce_is_a_user_error(size):
    with pytest.raises(UserError, match="multiples of 8"):
        ModelConfig(latent_dim=4, n_joints=2, length=5, image_size=size).validate()
    with pytest.raises(UserError, match="cannot be produced"):
        ImageDecoder(32, size, (8, 8, 8))


@pytest.mark.parametrize(
    "kwargs,fragment",
    [
        ({"latent_dim": 0}, "latent size"),
        ({"taus": (2.0,)}, "taus has 1 values for 2 layers"),
        ({"taus": (0.5, 8.0)}, "tau must be"),
        ({"layer_sizes": ()}, "layer_sizes"),
        ({"n_joints": 0}, "n_joints"),
    ],
)
def test_model_config_validation(kwargs, fragment):
    base = {"latent_dim": 4, "n_joints": 3, "length": 5}
    base.update(kwargs)
    if "layer_sizes" in kwargs and "taus" not in kwargs:
        base["taus"] = ()
    with pytest.raises(UserError, match=fragment):
        ModelConfig(**base).validate()


def test_model_config_json_roundtrip_and_unknown_field():
    cfg = ModelConfig(latent_dim=7, n_joints=3, length=11, image_size=(16, 24))
    again = ModelConfig.from_dict(cfg.to_dict())
    assert again == cfg
    with pytest.raises(UserError, match="unknown model config field"):
        ModelConfig.from_dict({**cfg.to_dict(), "colour": 1})


def test_analytic_macs_match_torch_flop_counter():
    cfg = ModelConfig(latent_dim=5, n_joints=4, length=6, image_size=(16, 24), image_channels=(8, 4, 4))
    model = MTRNNDecoder(cfg)
    batch = 3
    with FlopCounterMode(display=False) as counter:
        model(torch.randn(batch, 5))
    assert counter.get_total_flops() == 2 * batch * model.macs_per_sample()
    with FlopCounterMode(display=False) as counter:
        model(torch.randn(batch, 5), images=False)
    assert counter.get_total_flops() == 2 * batch * model.macs_per_sample(images=False)


def test_same_seed_same_weights_and_output():
    cfg = ModelConfig(latent_dim=4, n_joints=3, length=5)
    outs = []
    for _ in range(2):
        torch.manual_seed(5)
        outs.append(MTRNNDecoder(cfg)(torch.ones(2, 4)).motor)
    torch.testing.assert_close(outs[0], outs[1], rtol=0, atol=0)
