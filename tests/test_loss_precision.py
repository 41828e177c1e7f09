"""TrainConfig.loss_reduction="precision": each modality's per-element mean squared error
weighed by a learned precision (one log-variance per modality, part of the decoder's
parameters), and the reductions that stay as they were."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from primspace.data import JointScaler, MotionDataset
from primspace.experiments.presets import resolve_preset
from primspace.model.decoder import MTRNNDecoder
from primspace.model.precision import MODALITIES, ModalityPrecision
from primspace.train import TrainConfig, evaluate, fit, infer, load_run
from primspace.train.loss import DataTensors, batch_loss
from primspace.train.packed import fit_packed
from primspace.utils.errors import UserError
from test_loss_reduction import IMAGE_MODEL, SMALL_ARGS
from test_train import SMALL

pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)

SHORT = TrainConfig(epochs=6, batch_size=4, threads=1)
NOGRAD = torch.no_grad()


# ------------------------------------------------------------ the other reductions, pinned


def test_motor_only_mean_is_pinned(loss_motor_set):
    """Same seed, same numbers: the default loss on motor data, as before the precision loss."""
    run = fit(loss_motor_set, model_config=SMALL, train_config=SHORT, progress=False)
    last = run.history[-1]
    assert (last["loss"], last["motor"]) == pytest.approx((0.10001925296253628, 0.10001925296253628), rel=1e-6)
    assert float(abs(run.latents).sum()) == pytest.approx(73.30300903320312, rel=1e-6)


def test_mean_with_frames_is_pinned(loss_image_set):
    run = fit(loss_image_set, model_config=IMAGE_MODEL, train_config=replace(SHORT, vision_frames=2), progress=False)
    last = run.history[-1]
    assert (last["loss"], last["motor"], last["vision"]) == pytest.approx(
        (0.3601820071538289, 0.1170315792163213, 0.24315041800340018), rel=1e-6
    )
    assert float(abs(run.latents).sum()) == pytest.approx(28.082548141479492, rel=1e-6)
    assert not any("precision" in name for name in run.model.state_dict())


# ------------------------------------------------------------------------ the objective


def _model(data, images: bool, raw=(0.0, 0.0)):
    """A random decoder with learned precisions ``s = RATE · raw``, the data's tensors, codes."""
    torch.manual_seed(0)
    mc = replace(IMAGE_MODEL if images else SMALL, learned_precision=True).fitted_to(data, images=images)
    model = MTRNNDecoder(mc).eval()
    with torch.no_grad():
        model.precision.raw.copy_(torch.tensor(raw))
    tensors = DataTensors.build(data, JointScaler().fit(data.motor), images, torch.device("cpu"))
    return model, tensors, torch.randn(len(data), mc.code_size)


def test_precision_loss_by_hand(loss_image_set):
    """Σ_m ½ (e^{-s_m} · w_m · MSE_m + s_m) with the decoder's s, and the logged MSEs as under "mean"."""
    model, tensors, z = _model(loss_image_set, images=True, raw=(-0.3, 0.1))
    idx = torch.tensor([0, 2, 5])
    s_m, s_v = -0.3 * ModalityPrecision.RATE, 0.1 * ModalityPrecision.RATE
    with torch.no_grad():
        out = model(z[idx])
        motor = F.mse_loss(out.motor, tensors.motor[idx]).double().item()
        vision = F.mse_loss(out.images, tensors.images[idx].float() / 255.0).double().item()
        tc = TrainConfig(loss_reduction="precision", motor_weight=2.0, vision_weight=0.5)
        loss, parts = batch_loss(model, z[idx], idx, tensors, tc, torch.no_grad())
        by_hand = 0.5 * (math.exp(-s_m) * 2.0 * motor + s_m) + 0.5 * (math.exp(-s_v) * 0.5 * vision + s_v)
        assert loss.item() == pytest.approx(by_hand, rel=1e-6)
        assert parts.tolist() == pytest.approx([by_hand, motor, vision], rel=1e-6)
        # a modality at weight 0 has no term (its s alone would fall without end)
        loss, _ = batch_loss(model, z[idx], idx, tensors, replace(tc, motor_weight=0.0), torch.no_grad())
        assert loss.item() == pytest.approx(0.5 * (math.exp(-s_v) * 0.5 * vision + s_v), rel=1e-6)
        # motor only: the motor term alone
        only = replace(tensors, images=None)
        loss, parts = batch_loss(model, z[idx], idx, only, tc, torch.no_grad())
        assert loss.item() == pytest.approx(0.5 * (math.exp(-s_m) * 2.0 * motor + s_m), rel=1e-6)
        assert parts[2].item() == 0.0


def test_precision_needs_a_decoder_with_learned_precisions(loss_image_set):
    torch.manual_seed(0)
    model = MTRNNDecoder(IMAGE_MODEL.fitted_to(loss_image_set, images=True))
    assert model.precision is None and model(torch.zeros(1, 5)).log_variances is None
    tensors = DataTensors.build(loss_image_set, JointScaler().fit(loss_image_set.motor), True, torch.device("cpu"))
    with pytest.raises(UserError, match="needs a decoder with learned log-variances"):
        batch_loss(model, torch.zeros(2, 5), torch.arange(2), tensors, TrainConfig(loss_reduction="precision"), NOGRAD)


def test_bad_reduction_refused_in_one_line(run_cli, loss_motor_set, tmp_path):
    with pytest.raises(UserError) as err:
        TrainConfig(loss_reduction="gradnorm").validate()
    assert str(err.value) == "loss_reduction must be 'mean', 'sum' or 'precision', got 'gradnorm'"
    assert TrainConfig(loss_reduction="precision").validate().loss_reduction == "precision"
    data = tmp_path / "d.h5"
    loss_motor_set.save(data)
    res = run_cli("train", data, "--out", tmp_path / "bad", "--loss-reduction", "gradnorm", *SMALL_ARGS)
    assert res.code == 2 and "gradnorm" in res.err and not (tmp_path / "bad").exists()
    assert "Traceback" not in res.err


# ---------------------------------------------------------------------- training


def test_log_variances_move_toward_log_mse(loss_image_set):
    """On a tiny fit each s_m goes from 0 toward log MSE_m, its minimiser, and ends near it."""
    tc = TrainConfig(epochs=60, batch_size=6, threads=1, lr=2e-2, loss_reduction="precision")
    run = fit(loss_image_set, model_config=IMAGE_MODEL, train_config=tc, progress=False)
    assert run.model_config.learned_precision
    learned = run.model.precision.summary()
    final = evaluate(run, loss_image_set)
    for m in MODALITIES:
        target = math.log(final[m])
        s = learned[m]["log_variance"]
        assert abs(s - target) < 0.5 * abs(target), (m, s, target)  # from |0 - log MSE| at the start
        assert learned[m]["weight"] == pytest.approx(math.exp(-s))
    assert final["loss"] == pytest.approx(
        sum(0.5 * (final[m] * learned[m]["weight"] + learned[m]["log_variance"]) for m in MODALITIES), rel=1e-4
    )


def test_checkpoint_round_trip_and_resume(loss_image_set, tmp_path):
    """The s_m are saved, loaded and resumed with θ: two epochs and two more are four at once."""
    tc = replace(SHORT, epochs=4, loss_reduction="precision", vision_frames=2, final_lr_fraction=1.0)
    whole = fit(loss_image_set, tmp_path / "whole", model_config=IMAGE_MODEL, train_config=tc, progress=False)
    fit(loss_image_set, tmp_path / "part", model_config=IMAGE_MODEL, train_config=replace(tc, epochs=2), progress=False)
    resumed = fit(
        loss_image_set, tmp_path / "part", model_config=IMAGE_MODEL, train_config=tc, resume=True, progress=False
    )
    loaded = load_run(tmp_path / "whole")
    assert json.loads((tmp_path / "whole" / "config.json").read_text())["model"]["learned_precision"] is True
    assert torch.equal(loaded.model.precision.raw, whole.model.precision.raw)
    assert float(whole.model.precision.raw.detach().abs().min()) > 0  # they trained
    assert torch.allclose(resumed.model.precision.raw, whole.model.precision.raw, atol=1e-6, rtol=0)
    assert np.allclose(resumed.latents, whole.latents, atol=1e-5)


def test_a_run_without_it_loads_and_parents_a_precision_fit(loss_motor_set, tmp_path):
    fit(loss_motor_set, tmp_path / "mean", model_config=SMALL, train_config=replace(SHORT, epochs=1), progress=False)
    parent = load_run(tmp_path / "mean")
    assert parent.model.precision is None and not parent.model_config.learned_precision
    with pytest.raises(UserError, match="fitted with 'mean'"):
        infer(parent, loss_motor_set, epochs=1, loss_reduction="precision", progress=False)
    child = fit(
        loss_motor_set,
        model_config=SMALL,
        train_config=replace(SHORT, epochs=1, loss_reduction="precision"),
        weights_from=parent,
        progress=False,
    )
    assert child.model_config.learned_precision and child.model.precision is not None
    own = {k: v for k, v in child.model.state_dict().items() if not k.startswith("precision.")}
    assert own.keys() == parent.model.state_dict().keys()


def test_inference_keeps_the_precisions_and_each_code_its_own(loss_image_set):
    """θ frozen, s_m frozen: a code's steps do not depend on the other samples of its batch."""
    tc = replace(SHORT, epochs=3, loss_reduction="precision")
    run = fit(loss_image_set, model_config=IMAGE_MODEL, train_config=tc, progress=False)
    one, all_ = (infer(run, loss_image_set, epochs=3, batch_size=b, progress=False) for b in (1, 6))
    assert torch.equal(one.model.precision.raw, run.model.precision.raw)
    assert torch.equal(all_.model.precision.raw, run.model.precision.raw)
    assert np.allclose(one.latents, all_.latents, atol=1e-5)


def test_packed_and_captured_steps_carry_the_precisions(loss_image_set):
    tc = replace(SHORT, epochs=3, loss_reduction="precision", vision_frames=2)
    jobs = [
        dict(dataset=loss_image_set, model_config=IMAGE_MODEL, train_config=replace(tc, seed=seed), init=init)
        for seed, init in ((0, "projection"), (1, "zero"))
    ]
    alone = [fit(**job, progress=False) for job in jobs]
    captured = fit(**(jobs[0] | {"train_config": replace(tc, step="captured")}), progress=False)
    for a, p in zip([alone[0], *alone], [captured, *fit_packed(jobs, progress=False)]):
        assert torch.allclose(a.model.precision.raw, p.model.precision.raw, atol=1e-5, rtol=0)
        assert np.abs(a.latents - p.latents).max() < 1e-5
    assert not torch.equal(alone[0].model.precision.raw, alone[1].model.precision.raw)


def test_preset_override():
    demo = resolve_preset("demo").with_overrides(loss_reduction="precision", images=True)
    assert demo.train.loss_reduction == "precision" and not demo.model.learned_precision  # the fit sets it


def test_loss_balance_shows_the_learned_weights(loss_image_set):
    from primspace.experiments.loss_balance import loss_balance

    tc = replace(SHORT, epochs=3, loss_reduction="precision")
    run = fit(loss_image_set, model_config=IMAGE_MODEL, train_config=tc, progress=False)
    result = loss_balance(run, loss_image_set)
    learned = run.model.precision.summary()
    assert result["precision"] == learned and result["loss_reduction"] == "precision"
    by_hand = {m: 0.5 * (learned[m]["weight"] * result["mse"][m] + learned[m]["log_variance"]) for m in MODALITIES}
    assert [result["terms"][m] for m in MODALITIES] == pytest.approx([by_hand[m] for m in MODALITIES], rel=1e-5)
    weighed = {m: learned[m]["weight"] * result["mse"][m] for m in MODALITIES}
    assert result["vision_share"] == pytest.approx(weighed["vision"] / sum(weighed.values()), rel=1e-9)
    assert sorted(result["gradients"]["theta"]["motor"]) == ["all", "dynamics", "image_head", "motor_head"]
    assert (
        loss_balance(fit(loss_image_set, model_config=IMAGE_MODEL, train_config=SHORT, progress=False), loss_image_set)[
            "precision"
        ]
        is None
    )


def test_the_command_prints_the_learned_weights(run_cli, loss_image_set, tmp_path):
    data = loss_image_set.save(tmp_path / "data.h5")
    tc = replace(SHORT, epochs=2, loss_reduction="precision")
    run = fit(MotionDataset.load(data), tmp_path / "run", model_config=IMAGE_MODEL, train_config=tc, progress=False)
    res = run_cli("diagnose", "loss-balance", tmp_path / "run", "--no-gradients")
    assert res.code == 0, res.err
    s = run.model.precision.summary()
    line = next(x for x in res.out.splitlines() if x.startswith("learned precisions"))
    assert f"motor log-variance s {s['motor']['log_variance']:.3g}, weight exp(-s) {s['motor']['weight']:.3g}" in line
    assert f"vision log-variance s {s['vision']['log_variance']:.3g}" in line
