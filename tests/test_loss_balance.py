"""primspace.experiments.loss_balance (issue 42, item 3): the loss's motor and vision terms
of a trained run, their gradients, and the motor error per primitive and joint, checked on
tiny runs with frames trained here under both reductions, and the command's refusals."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math

import numpy as np
import pytest
import torch

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.experiments.loss_balance import loss_balance
from primspace.model.config import ModelConfig
from primspace.train import TrainConfig, fit, reconstruct
from primspace.train.loss import DataTensors, batch_loss
from primspace.utils.errors import UserError
from test_train import primitives

IMAGE_MODEL = ModelConfig(
    latent_dim=4, layer_sizes=(12, 6), taus=(2.0, 8.0), p_hidden=12, motor_hidden=12, image_channels=(8, 4)
)


pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)


@pytest.fixture(scope="module")
def image_set():
    return primitives(4, seed=3, T=6, J=3, K=2, images=True)  # 8 sequences of 6 steps, 8x8 frames, 2 primitives


@pytest.fixture(scope="module")
def runs(image_set):
    tc = TrainConfig(epochs=3, batch_size=4, threads=1)
    return {
        r: fit(
            image_set,
            model_config=IMAGE_MODEL,
            init="zero",
            train_config=dataclasses.replace(tc, loss_reduction=r),
            images=True,
            progress=False,
        )
        for r in ("mean", "sum")
    }


@pytest.fixture(scope="module")
def results(runs, image_set):
    return {r: loss_balance(run, image_set, batch_size=3) for r, run in runs.items()}


def _whole_batch_loss(run, data) -> float:
    """:func:`batch_loss` of the run's own loss over every sample in one batch."""
    tensors = DataTensors.build(data, run.scaler, True, torch.device("cpu"))
    with torch.no_grad():
        loss, _ = batch_loss(
            run.model, torch.from_numpy(run.latents), torch.arange(len(data)), tensors, run.train_config,
            contextlib.nullcontext(),
        )  # fmt: skip
    return float(loss)


@pytest.mark.parametrize("reduction", ["mean", "sum"])
def test_the_terms_add_up_to_the_runs_loss(runs, results, image_set, reduction):
    result = results[reduction]
    assert result["loss_reduction"] == reduction and result["images"]
    terms = result["terms"]
    assert terms["motor"] + terms["vision"] == pytest.approx(terms["total"], rel=1e-12)
    assert terms["total"] == pytest.approx(_whole_batch_loss(runs[reduction], image_set), rel=1e-5)
    n = sum(p["n"] for p in result["per_primitive"].values())
    assert n == result["n_samples"] == len(image_set)
    mean_of_groups = sum(p["n"] * p["terms"]["total"] for p in result["per_primitive"].values()) / n
    assert mean_of_groups == pytest.approx(terms["total"], rel=1e-9)


def test_the_sum_gives_the_frames_the_larger_share(results):
    assert results["sum"]["vision_share"] > results["mean"]["vision_share"]
    # a frame (8x8x3 = 192 values) against 3 joints: under the sum the frames carry nearly all of it
    assert results["sum"]["vision_share"] > 0.9


@pytest.mark.parametrize("reduction", ["mean", "sum"])
def test_gradient_norms_are_positive_and_finite(results, reduction):
    grads = results[reduction]["gradients"]
    for term in ("motor", "vision"):
        for part in ("dynamics", "all"):
            value = grads["theta"][term][part]
            assert value > 0 and math.isfinite(value)
        assert grads["codes"][term] > 0 and math.isfinite(grads["codes"][term])
    assert grads["theta"]["motor"]["motor_head"] > 0 and grads["theta"]["motor"]["image_head"] == 0
    assert grads["theta"]["vision"]["image_head"] > 0 and grads["theta"]["vision"]["motor_head"] == 0
    for cosine in (grads["theta"]["cosine"]["all"], grads["theta"]["cosine"]["dynamics"], grads["codes"]["cosine"]):
        assert -1 - 1e-9 <= cosine <= 1 + 1e-9


def test_joint_rms_per_primitive_and_joint_against_a_direct_computation(runs, results, image_set):
    run, result = runs["mean"], results["mean"]
    rms = np.asarray(result["joint_rms"]["values"])
    assert rms.shape == (2, image_set.n_joints)
    assert result["primitives"] == list(image_set.label_names)
    motor, _ = reconstruct(run, images=False)
    error = motor.astype(np.float64) - image_set.motor
    for k in range(2):
        expected = np.sqrt((error[image_set.labels == k] ** 2).mean(axis=(0, 1)))
        np.testing.assert_allclose(rms[k], expected, rtol=1e-4)
    np.testing.assert_allclose(result["joint_rms"]["all"], np.sqrt((error**2).mean(axis=(0, 1))), rtol=1e-4)
    scaled = np.asarray(result["joint_rms_scaled"]["values"])
    np.testing.assert_allclose(scaled, rms / run.scaler.half_range_, rtol=1e-9)


def test_joint_rms_is_zero_where_the_predictions_are_the_targets(runs, image_set):
    run = runs["sum"]
    motor, _ = reconstruct(run, images=False)
    exact = dataclasses.replace(image_set, motor=motor.astype(np.float64))
    data = {k: v for k, v in run.config["data"].items() if k != "motor_sha1"}  # other joint values, same samples
    result = loss_balance(dataclasses.replace(run, config={**run.config, "data": data}), exact, gradients=False)
    assert np.asarray(result["joint_rms"]["values"]).max() < 1e-5
    assert result["terms"]["motor"] < 1e-9
    assert "gradients" not in result


def test_refusals(runs, image_set):
    unlabelled = MotionDataset(image_set.motor, images=image_set.images)
    with pytest.raises(UserError, match="has no labels"):
        loss_balance(runs["mean"], unlabelled)
    with pytest.raises(UserError, match="batch_size"):
        loss_balance(runs["mean"], image_set, batch_size=0)


def test_the_command_refuses_a_missing_run_in_one_line(run_cli, tmp_path):
    assert_user_error(run_cli("diagnose", "loss-balance", tmp_path / "nope"), "no such run directory")


def test_the_command_prints_the_tables_and_writes_json(run_cli, image_set, tmp_path):
    data = image_set.save(tmp_path / "data.h5")
    fit(
        MotionDataset.load(data),
        tmp_path / "run",
        model_config=IMAGE_MODEL,
        init="zero",
        train_config=TrainConfig(epochs=1, batch_size=4, threads=1, loss_reduction="sum"),
        images=True,
        progress=False,
    )
    out = tmp_path / "balance.json"
    res = run_cli("diagnose", "loss-balance", tmp_path / "run", "--json", out, "--batch-size", "4")
    assert res.code == 0, res.err
    assert "motor RMS error per primitive and joint" in res.out and "vision share" in res.out
    saved = json.loads(out.read_text())
    assert saved["writer"] == "primspace diagnose loss-balance" and saved["loss_reduction"] == "sum"
    assert_user_error(run_cli("diagnose", "loss-balance", tmp_path / "run", "--json", out), "--overwrite")
    assert run_cli("diagnose", "loss-balance", tmp_path / "run", "--json", out, "--overwrite").code == 0
    bare = tmp_path / "bare.h5"
    MotionDataset(image_set.motor, images=image_set.images).save(bare)
    assert_user_error(run_cli("diagnose", "loss-balance", tmp_path / "run", "--data", bare), "has no labels")
