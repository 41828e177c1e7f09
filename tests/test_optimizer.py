"""TrainConfig.optimizer: "sgd" is the paper's plain gradient descent of θ and the codes."""

import numpy as np
import pytest
import torch

from primspace.data import JointScaler, MotionDataset
from primspace.model.config import ModelConfig
from primspace.model.latent import LatentTable
from primspace.train import TrainConfig, fit, infer
from primspace.train.loss import DataTensors, batch_loss
from primspace.train.packed import fit_packed
from primspace.utils.errors import UserError

MC = ModelConfig(latent_dim=3, layer_sizes=(6, 4))


def _data():
    rng = np.random.default_rng(1)
    return MotionDataset(motor=rng.standard_normal((6, 10, 2)).astype(np.float32))


def _tc(**kw):
    return TrainConfig(**({"batch_size": 6, "final_lr_fraction": 1.0, "log_initial": False} | kw))


def test_sgd_is_plain_gradient_descent():
    ds = _data()
    tc = _tc(epochs=1, optimizer="sgd", lr=0.1, latent_lr=0.5)
    start = fit(ds, model_config=MC, train_config=_tc(epochs=0, optimizer="sgd"), progress=False)
    run = fit(ds, model_config=MC, train_config=tc, progress=False)
    # by hand: one batch of all six samples, from the same weights and codes
    model = start.model.train()
    z = torch.from_numpy(start.initial_latents).requires_grad_(True)
    tensors = DataTensors.build(ds, JointScaler().fit(ds.motor), False, torch.device("cpu"))
    loss, _ = batch_loss(model, z, torch.arange(6), tensors, tc, torch.autocast("cpu", enabled=False))
    loss.backward()
    for (name, p), after in zip(model.named_parameters(), run.model.parameters()):
        assert torch.allclose(p.detach() - 0.1 * p.grad, after, atol=1e-6), name
    # each code on its own sample's loss: 6 x the gradient of the batch mean
    assert np.allclose(start.initial_latents - 0.5 * 6 * z.grad.numpy(), run.latents, atol=1e-6)
    assert not np.allclose(run.latents, start.initial_latents)


def test_adam_stays_the_default_and_sgd_runs_infer_and_pack():
    assert TrainConfig().optimizer == "adam"
    ds = _data()
    runs = [
        fit(ds, model_config=MC, train_config=_tc(epochs=3, optimizer=o, batch_size=4), progress=False)
        for o in ("adam", "sgd")
    ]
    assert np.abs(runs[0].latents - runs[1].latents).max() > 1e-4  # the optimiser changes the numbers
    inferred = infer(runs[1], ds, epochs=2, progress=False)
    assert inferred.train_config.optimizer == "sgd"  # an SGD run infers with SGD
    job = dict(dataset=ds, model_config=MC, train_config=_tc(epochs=3, optimizer="sgd", batch_size=4))
    packed = fit_packed([job, dict(job, init="zero")], progress=False)
    assert np.abs(packed[0].latents - runs[1].latents).max() < 1e-5


def test_the_optimizer_is_kept_and_checked(tmp_path):
    table = LatentTable(torch.zeros(3, 2), 0.1, optimizer="sgd")
    assert LatentTable.from_state_dict(table.state_dict()).optimizer == "sgd"
    old = LatentTable(torch.zeros(3, 2), 0.1).state_dict()
    del old["optimizer"]  # a table saved before the field: Adam
    assert LatentTable.from_state_dict(old).optimizer == "adam"
    with pytest.raises(UserError, match="optimizer must be one of adam, sgd"):
        TrainConfig(optimizer="rmsprop").validate()
    ds = _data()
    fit(ds, tmp_path / "run", model_config=MC, train_config=_tc(epochs=1), progress=False)
    with pytest.raises(UserError, match="optimizer"):
        fit(
            ds,
            tmp_path / "run",
            model_config=MC,
            train_config=_tc(epochs=2, optimizer="sgd"),
            resume=True,
            progress=False,
        )


def test_experiments_take_the_optimizer_its_rates_and_the_step():
    from primspace.experiments.presets import resolve_preset

    preset = resolve_preset("paper").with_overrides(optimizer="sgd", lr=0.03, latent_lr=30.0, step="captured")
    assert (preset.train.optimizer, preset.train.lr, preset.train.latent_lr, preset.train.step) == (
        "sgd",
        0.03,
        30.0,
        "captured",
    )
    assert resolve_preset("paper").train.optimizer == "adam"  # every preset names its optimiser: Adam
    with pytest.raises(UserError, match="optimizer must be one of"):
        resolve_preset("paper").with_overrides(optimizer="lbfgs")
