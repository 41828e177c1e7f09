"""TrainConfig.loss_reduction: the paper's summed loss (``"sum"``, *Main Results*:
``L = Σ_i ‖d(θ, z_i) − o_i‖²``) beside primspace's per-element means (``"mean"``, the
default): the objective against hand-computed sums (motor, frames, padding, drawn frames),
what is logged, the command line, experiment presets, and training under the sum."""

import itertools
import json
import math
from dataclasses import replace

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from conftest import assert_user_error
from primspace.data import JointScaler
from primspace.experiments import presets as experiment_presets
from primspace.experiments.presets import default_train, resolve_preset
from primspace.experiments.workspace import ExperimentDir
from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.train import TrainConfig, evaluate, fit
from primspace.train.loss import DataTensors, batch_loss
from primspace.utils.errors import UserError
from test_train import SMALL

IMAGE_MODEL = ModelConfig(
    latent_dim=5, layer_sizes=(16, 8), taus=(2.0, 8.0), p_hidden=16, motor_hidden=16, image_channels=(8, 4)
)
CPU = torch.device("cpu")
NO_AUTOCAST = torch.no_grad()


pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)


def _setup(data, images: bool, lengths=None):
    """A random decoder, the data's tensors (with a padding mask from ``lengths``), codes."""
    torch.manual_seed(0)
    mc = (IMAGE_MODEL if images else SMALL).fitted_to(data, images=images)
    model = MTRNNDecoder(mc).eval()
    tensors = DataTensors.build(data, JointScaler().fit(data.motor), images, CPU)
    if lengths is not None:
        t = tensors.motor.shape[1]
        tensors.mask = (torch.arange(t)[None, :] < torch.as_tensor(lengths)[:, None]).float()
    z = torch.randn(len(data), mc.code_size)
    return model, tensors, z


def _errors(model, z, tensors, idx):
    """Per sample and step, the summed squared error of motor and of the frame (float64)."""
    with torch.no_grad():
        out = model(z, images=tensors.images is not None)
    motor = (out.motor.double() - tensors.motor[idx].double()).pow(2).sum(dim=2)
    if tensors.images is None:
        return motor, None
    frames = tensors.images[idx].double() / 255.0
    return motor, (out.images.double() - frames).pow(2).flatten(2).sum(dim=2)


def _loss(model, z, idx, tensors, tc, steps=None):
    with torch.no_grad():
        loss, parts = batch_loss(model, z, idx, tensors, tc, NO_AUTOCAST, steps)
    return loss.item(), parts.tolist()


# ------------------------------------------------------------------ the objective


def test_sum_of_motor_errors_by_hand(loss_motor_set):
    model, tensors, z = _setup(loss_motor_set, images=False)
    idx = torch.tensor([0, 4, 7, 8])
    tc = TrainConfig(loss_reduction="sum", motor_weight=0.5)
    loss, (logged, motor, vision) = _loss(model, z[idx], idx, tensors, tc)
    errors, _ = _errors(model, z[idx], tensors, idx)
    assert loss == pytest.approx(0.5 * errors.sum(dim=1).mean().item(), rel=1e-6)
    assert logged == pytest.approx(loss, rel=1e-6) and vision == 0.0
    # what is logged as motor is the per-element MSE, whichever reduction
    _, (_, motor_mean, _) = _loss(model, z[idx], idx, tensors, replace(tc, loss_reduction="mean"))
    assert motor == pytest.approx(motor_mean, rel=1e-6)
    assert motor == pytest.approx(errors.mean().item() / 4, rel=1e-6)  # 4 joints


def test_sum_of_motor_and_pixel_errors_by_hand(loss_image_set):
    model, tensors, z = _setup(loss_image_set, images=True)
    idx = torch.tensor([5, 1, 2])
    tc = TrainConfig(loss_reduction="sum", motor_weight=2.0, vision_weight=0.25)
    loss, (_, motor, vision) = _loss(model, z[idx], idx, tensors, tc)
    m, s = _errors(model, z[idx], tensors, idx)
    assert loss == pytest.approx((2.0 * m.sum(dim=1) + 0.25 * s.sum(dim=1)).mean().item(), rel=1e-6)
    _, (_, motor_mean, vision_mean) = _loss(model, z[idx], idx, tensors, replace(tc, loss_reduction="mean"))
    assert (motor, vision) == pytest.approx((motor_mean, vision_mean), rel=1e-6)
    assert vision == pytest.approx(s.mean().item() / (8 * 8 * 3), rel=1e-6)


def test_padded_steps_never_count(loss_image_set):
    lengths = [6, 3, 4, 6, 1, 5]
    model, tensors, z = _setup(loss_image_set, images=True, lengths=lengths)
    idx = torch.arange(6)
    tc = TrainConfig(loss_reduction="sum")
    loss, (_, motor, vision) = _loss(model, z, idx, tensors, tc)
    m, s = _errors(model, z, tensors, idx)
    valid = tensors.mask.double()
    assert loss == pytest.approx(((m + s) * valid).sum(dim=1).mean().item(), rel=1e-6)
    # logged: each sample's per-element mean over its valid steps, then the mean over samples
    n_valid = valid.sum(dim=1)
    assert motor == pytest.approx(((m * valid).sum(dim=1) / n_valid / 3).mean().item(), rel=1e-6)
    assert vision == pytest.approx(((s * valid).sum(dim=1) / n_valid / 192).mean().item(), rel=1e-6)
    # anything at a padded step leaves the loss unchanged
    moved = DataTensors(tensors.motor.clone(), tensors.images.clone(), tensors.mask)
    moved.motor[tensors.mask == 0] += 5.0
    moved.images[tensors.mask == 0] = 255 - moved.images[tensors.mask == 0]
    again, parts = _loss(model, z, idx, moved, tc)
    assert [again, *parts] == pytest.approx([loss, loss, motor, vision], rel=1e-6)


@pytest.mark.parametrize("lengths", [None, [6, 3, 4, 6, 1, 5]])
def test_drawn_frames_scaled_by_t_over_k(loss_image_set, lengths):
    """K drawn frames, their sum times T / K: with K = T exactly the all-frame sum, and for
    K < T its mean over all C(T, K) equally likely draws is exactly the all-frame sum."""
    model, tensors, z = _setup(loss_image_set, images=True, lengths=lengths)
    idx = torch.arange(6)
    tc = TrainConfig(loss_reduction="sum", motor_weight=0.0)  # the vision term alone
    exact, _ = _loss(model, z, idx, tensors, tc)
    _, s = _errors(model, z, tensors, idx)
    valid = torch.ones_like(s) if lengths is None else tensors.mask.double()
    assert exact == pytest.approx((s * valid).sum(dim=1).mean().item(), rel=1e-6)

    every = torch.stack([torch.randperm(6) for _ in range(6)])  # K = T, in any order
    assert _loss(model, z, idx, tensors, tc, every)[0] == pytest.approx(exact, rel=1e-6)

    for k in (1, 2):
        draws = [
            _loss(model, z, idx, tensors, tc, torch.tensor(c).expand(6, k))[0]
            for c in itertools.combinations(range(6), k)
        ]
        assert np.std(draws) > 0
        assert np.mean(draws) == pytest.approx(exact, rel=1e-6)
        c = (0, 3)[:k]  # one draw by hand: T / K times the sum over its valid drawn frames
        by_hand = 6 / k * (s[:, list(c)] * valid[:, list(c)]).sum(dim=1).mean().item()
        assert _loss(model, z, idx, tensors, tc, torch.tensor(c).expand(6, k))[0] == pytest.approx(by_hand, rel=1e-6)


def test_mean_is_unchanged(loss_image_set):
    """The default reduction is the per-element mean, computed exactly as before."""
    assert TrainConfig().loss_reduction == "mean"
    model, tensors, z = _setup(loss_image_set, images=True)
    idx = torch.tensor([0, 3])
    tc = TrainConfig(motor_weight=0.7, vision_weight=1.3)
    with torch.no_grad():
        loss, parts = batch_loss(model, z[idx], idx, tensors, tc, NO_AUTOCAST)
        out = model(z[idx], images=True)
        motor = F.mse_loss(out.motor.float(), tensors.motor[idx])
        vision = F.mse_loss(out.images.float(), tensors.images[idx].float().div_(255.0))
    assert torch.equal(loss, 0.7 * motor + 1.3 * vision)
    assert torch.equal(parts, torch.stack([loss, motor, vision]))


def test_validate_refuses_another_reduction():
    with pytest.raises(UserError) as err:
        TrainConfig(loss_reduction="median").validate()
    assert str(err.value) == "loss_reduction must be 'mean', 'sum' or 'precision', got 'median'"
    assert TrainConfig(loss_reduction="sum").validate().loss_reduction == "sum"
    assert TrainConfig.from_dict({"epochs": 3}).loss_reduction == "mean"  # configs saved without it


# ---------------------------------------------------------------------- training


@pytest.mark.slow
def test_training_under_the_sum_is_stable_with_the_default_learning_rates(loss_motor_set, loss_image_set):
    """Default lr / latent_lr: finite, decreasing. Motor only, the sum is T·J times the
    mean, and Adam (eps aside) ignores a constant factor: the same path as under "mean"."""
    tc = TrainConfig(epochs=40, batch_size=4, threads=1)
    runs = {
        r: fit(loss_motor_set, model_config=SMALL, train_config=replace(tc, loss_reduction=r), progress=False)
        for r in ("mean", "sum")
    }
    history = runs["sum"].history
    losses = [h["loss"] for h in history]
    assert all(math.isfinite(v) for v in losses)
    assert losses[-1] < losses[10] < losses[0] / 2 and losses[-1] < losses[0] / 10
    for h in history:  # logged: the objective (T·J = 40 times the motor MSE here) and the MSE
        assert h["loss"] == pytest.approx(40 * h["motor"], rel=1e-5)
    mean_motor = [h["motor"] for h in runs["mean"].history]
    assert [h["motor"] for h in history] == pytest.approx(mean_motor, rel=0.02)
    ev = evaluate(runs["sum"], loss_motor_set)  # follows the run's reduction
    assert ev["loss"] == pytest.approx(40 * ev["motor"], rel=1e-5)
    assert ev["motor"] == pytest.approx(evaluate(runs["mean"], loss_motor_set)["motor"], rel=0.05)

    # with frames, on 2 of 6 drawn frames: finite and decreasing too (to half at a constant rate)
    run = fit(
        loss_image_set,
        model_config=IMAGE_MODEL,
        progress=False,
        train_config=replace(tc, loss_reduction="sum", vision_frames=2, final_lr_fraction=1.0),
    )
    losses = [h["loss"] for h in run.history]
    assert all(math.isfinite(v) for v in losses) and losses[-1] < losses[0] / 2
    ev = evaluate(run, loss_image_set)
    assert ev["loss"] == pytest.approx(6 * (3 * ev["motor"] + 192 * ev["vision"]), rel=1e-5)


def test_a_run_does_not_resume_under_another_reduction(loss_motor_set, tmp_path):
    tc = TrainConfig(epochs=2, batch_size=9, threads=1, loss_reduction="sum")
    fit(loss_motor_set, tmp_path / "run", model_config=SMALL, train_config=tc, progress=False)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["train"]["loss_reduction"] == "sum"
    with pytest.raises(UserError, match="cannot resume: train loss_reduction differs"):
        fit(
            loss_motor_set,
            tmp_path / "run",
            model_config=SMALL,
            train_config=replace(tc, epochs=3, loss_reduction="mean"),
            resume=True,
            progress=False,
        )


def test_a_run_saved_before_the_field_resumes(loss_motor_set, tmp_path):
    from primspace.train.rundir import CHECKPOINT_NAME

    tc = TrainConfig(epochs=1, batch_size=9, threads=1)
    fit(loss_motor_set, tmp_path / "run", model_config=SMALL, train_config=tc, progress=False)
    ckpt = torch.load(tmp_path / "run" / CHECKPOINT_NAME, weights_only=False)
    del ckpt["config"]["train"]["loss_reduction"]  # as written before loss_reduction existed
    torch.save(ckpt, tmp_path / "run" / CHECKPOINT_NAME)
    run = fit(
        loss_motor_set,
        tmp_path / "run",
        model_config=SMALL,
        train_config=replace(tc, epochs=2),
        resume=True,
        progress=False,
    )
    assert run.epoch == 2


# ------------------------------------------------------------ command line, presets


SMALL_ARGS = ("--layers", "12,6", "--latent-dim", "3", "--threads", "1", "--batch-size", "4", "--epochs", "2")


def test_cli_flag_reaches_the_config(run_cli, loss_motor_set, tmp_path):
    data = tmp_path / "d.h5"
    loss_motor_set.save(data)
    run = tmp_path / "run"
    res = run_cli("train", data, "--out", run, "--loss-reduction", "sum", *SMALL_ARGS)
    assert res.code == 0, res.err
    assert json.loads((run / "config.json").read_text())["train"]["loss_reduction"] == "sum"
    last = json.loads((run / "metrics.jsonl").read_text().splitlines()[-1])
    assert last["loss"] == pytest.approx(10 * 4 * last["motor"], rel=1e-5)

    res = run_cli("infer", run, data, "--out", tmp_path / "inf", "--epochs", "1", "--threads", "1")
    assert res.code == 0, res.err  # the run's reduction by default
    assert json.loads((tmp_path / "inf" / "config.json").read_text())["train"]["loss_reduction"] == "sum"
    res = run_cli(
        "infer", run, data, "--out", tmp_path / "inf2", "--epochs", "1", "--threads", "1", "--loss-reduction", "mean"
    )
    assert res.code == 0, res.err
    assert json.loads((tmp_path / "inf2" / "config.json").read_text())["train"]["loss_reduction"] == "mean"

    res = run_cli("train", data, "--out", tmp_path / "bad", "--loss-reduction", "median", *SMALL_ARGS)
    assert res.code == 2 and "median" in res.err and not (tmp_path / "bad").exists()


def test_preset_override_goes_into_the_train_config():
    demo = resolve_preset("demo")
    summed = demo.with_overrides(loss_reduction="sum", vision_frames=8)
    assert summed.train == replace(demo.train, loss_reduction="sum", vision_frames=8)
    assert demo.with_overrides(loss_reduction=None) == demo
    with pytest.raises(UserError, match="loss_reduction must be 'mean', 'sum' or 'precision'"):
        demo.with_overrides(loss_reduction="median")


TINY = experiment_presets.ExperimentPreset(
    name="tiny-sum",
    data_preset="demo",
    train_fraction=0.5,
    inits=("zero",),
    latent_dims=(3,),
    fit_epochs=2,
    infer_epochs=1,
    train=replace(default_train(), batch_size=8),
    images=False,
    model=replace(SMALL, latent_dim=3),
)


@pytest.mark.slow
def test_experiment_flag_and_a_changed_reduction_refused(run_cli, loss_motor_set, tmp_path, monkeypatch):
    monkeypatch.setitem(experiment_presets.PRESETS, "tiny-sum", TINY)
    data, out = tmp_path / "d.h5", tmp_path / "exp"
    loss_motor_set.save(data)
    args = (
        "experiment",
        "intra",
        "--preset",
        "tiny-sum",
        "--data",
        data,
        "--out",
        out,
        "--workers",
        "1",
        "--no-report",
    )
    res = run_cli(*args, "--loss-reduction", "sum")
    assert res.code == 0, res.err
    meta = json.loads((out / "experiment.json").read_text())
    assert meta["preset_config"]["train"]["loss_reduction"] == "sum"
    configs = list((out / "runs").glob("intra/*/*/config.json"))  # fit and infer
    assert configs and all(json.loads(c.read_text())["train"]["loss_reduction"] == "sum" for c in configs)
    assert_user_error(run_cli(*args), "made with other settings", "train.loss_reduction=sum")


def test_experiment_directory_without_the_field_opens(loss_motor_set, tmp_path):
    """experiment.json written before loss_reduction existed: the default, "mean", is
    what it was made with; "sum" is another setting."""
    data = tmp_path / "d.h5"
    loss_motor_set.save(data)
    exp = ExperimentDir(tmp_path / "old", TINY, data=data)
    exp.save_meta()
    meta = json.loads((exp.path / "experiment.json").read_text())
    del meta["preset_config"]["train"]["loss_reduction"]
    (exp.path / "experiment.json").write_text(json.dumps(meta))
    assert ExperimentDir(exp.path, TINY, data=data).preset.train.loss_reduction == "mean"
    with pytest.raises(UserError, match="train.loss_reduction=mean"):
        ExperimentDir(exp.path, TINY.with_overrides(loss_reduction="sum"), data=data)
