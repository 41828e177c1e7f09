"""Calibrated projection (issue 16): the ridge map from initial to fitted codes, its place in
a run (fitted at the end of fit, saved, carried, resumable) and ``init="calibrated"``."""

import json

import numpy as np
import pytest
import torch

from conftest import assert_user_error
from primspace.model.calibration import CodeCalibration
from primspace.train import evaluate, fit, infer, load_run
from primspace.utils.errors import UserError
from test_train import SMALL, _tc, eval_set, primitives, train_set  # noqa: F401 (the fixtures, shared)


@pytest.fixture(scope="module")
def trained(train_set, tmp_path_factory):
    """A projection-init run whose codes move (a high latent learning rate)."""
    out = tmp_path_factory.mktemp("cal") / "run"
    return fit(
        train_set,
        out,
        model_config=SMALL,
        train_config=_tc(epochs=40, latent_lr=0.05),
        init="projection",
        progress=False,
    )


# ------------------------------------------------------------------- the ridge map


def _planted(n=200, q=5, noise=0.01, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, q))
    B = rng.normal(size=(q, q))
    c = rng.normal(size=q)
    return x, x @ B.T + c + noise * rng.normal(size=(n, q)), B, c


def test_the_ridge_map_recovers_a_planted_linear_map():
    x, y, B, c = _planted()
    cal = CodeCalibration(latent_dim=5).fit(x, y)
    np.testing.assert_allclose(cal.coef_, B, atol=0.01)
    np.testing.assert_allclose(cal.intercept_, c, atol=0.01)
    assert cal.heldout_r2_ > 0.999
    assert cal.identity_r2_ < 0.5  # the raw start is a poor prediction of y here
    assert cal.movement_ == pytest.approx(np.linalg.norm(y - x) / np.linalg.norm(x))
    np.testing.assert_allclose(cal.transform(x[:3]), y[:3], atol=0.05)


def test_unrelated_codes_have_no_held_out_r2_and_leave_the_identity():
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=(60, 4)), rng.normal(size=(60, 4))
    cal = CodeCalibration(latent_dim=4).fit(x, y)
    assert cal.heldout_r2_ < 0.1 and cal.identity_r2_ < -0.5
    # the data pull B from the identity (the prior) towards zero
    assert np.abs(np.diag(cal.coef_)).max() < 0.4
    np.testing.assert_allclose(cal.intercept_, y.mean(axis=0), atol=0.3)


def test_the_identity_prior_beats_the_zero_prior_when_codes_barely_move():
    """Few samples in many dimensions, codes moved a little and shifted: pulling B towards
    the identity predicts held-out codes better than pulling it towards zero (which loses
    to P m itself), the case measured on small real training parts."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(24, 12))
    y = x + 0.3 + 0.15 * rng.normal(size=x.shape)
    towards_identity = CodeCalibration(latent_dim=12).fit(x, y)
    towards_zero = CodeCalibration(latent_dim=12, prior="zero").fit(x, y)
    assert towards_identity.heldout_r2_ > towards_zero.heldout_r2_
    assert towards_identity.heldout_r2_ > towards_identity.identity_r2_  # the shift is learned
    with pytest.raises(UserError, match="prior must be"):
        CodeCalibration(latent_dim=12, prior="ones").fit(x, y)


def test_windows_are_pooled_into_one_map():
    x, y, B, c = _planted(n=150, q=3)
    xs, ys = x.reshape(50, 9), y.reshape(50, 9)  # 3 windows of q = 3 per sample
    cal = CodeCalibration(latent_dim=3).fit(xs, ys)
    np.testing.assert_allclose(cal.coef_, B, atol=0.02)
    assert cal.n_samples_ == 50
    assert cal.transform(xs).shape == (50, 9)


def test_identical_codes_map_to_themselves():
    x = np.random.default_rng(2).normal(size=(40, 3))
    cal = CodeCalibration(latent_dim=3).fit(x, x)
    assert cal.movement_ == 0.0 and cal.identity_r2_ == 1.0
    np.testing.assert_allclose(cal.transform(x), x, atol=1e-4)


def test_bad_codes_are_refused_with_the_sample():
    x = np.zeros((5, 3))
    y = x.copy()
    y[3, 1] = np.nan
    with pytest.raises(UserError, match="fitted code of sample 3 is not finite"):
        CodeCalibration(latent_dim=3).fit(x, y)
    with pytest.raises(UserError, match="must both be"):
        CodeCalibration(latent_dim=3).fit(x, np.zeros((5, 4)))


def test_state_dict_roundtrip_through_a_weights_only_load(tmp_path):
    x, y, _, _ = _planted(n=30, q=4)
    cal = CodeCalibration(latent_dim=4).fit(x, y)
    torch.save({"c": cal.state_dict()}, tmp_path / "c.pt")
    back = CodeCalibration.from_state_dict(torch.load(tmp_path / "c.pt", weights_only=True)["c"])
    np.testing.assert_array_equal(back.transform(x), cal.transform(x))
    assert back.diagnostics() == cal.diagnostics()
    with pytest.raises(UserError, match="not a CodeCalibration state"):
        CodeCalibration.from_state_dict({"latent_dim": 4})


# ---------------------------------------------------------------- in a trained run


def test_a_projection_fit_ends_with_its_calibration_saved(trained):
    cal = trained.calibration
    assert cal is not None and cal.n_samples_ == len(trained.indices)
    scaled = trained.scaler.transform(primitives(12, seed=0).motor)
    pm = trained.initializer.transform(scaled)
    again = CodeCalibration(SMALL.latent_dim).fit(pm, trained.latents)
    np.testing.assert_allclose(cal.coef_, again.coef_, rtol=1e-10)
    # the map moves the training codes' start closer to where they ended than P m itself
    assert np.linalg.norm(cal.transform(pm) - trained.latents) < np.linalg.norm(pm - trained.latents)
    assert 0.0 < cal.movement_
    loaded = load_run(trained.run_dir)
    np.testing.assert_array_equal(loaded.calibration.coef_, cal.coef_)
    diagnostics = json.loads((trained.run_dir / "calibration.json").read_text())
    assert diagnostics.pop("prior") == "identity" and diagnostics.pop("latent_dim") == SMALL.latent_dim
    assert diagnostics == pytest.approx(cal.diagnostics())


def test_infer_calibrated_starts_from_the_map_and_resumes_exactly(trained, eval_set, tmp_path):
    scaled = trained.scaler.transform(eval_set.motor)
    expected = trained.calibration.transform(trained.initializer.transform(scaled))
    constant = {"final_lr_fraction": 1.0}  # extended on resume below: a decay would be stretched (fit's docstring)
    full = infer(trained.run_dir, eval_set, tmp_path / "full", epochs=6, init="calibrated", progress=False, **constant)
    assert full.init == "calibrated"
    np.testing.assert_allclose(full.initial_latents, expected, rtol=1e-6)
    assert not (tmp_path / "full" / "calibration.json").exists()  # only the fit's diagnostics are written
    # the inferred run carries the map: it can start another inference the same way
    np.testing.assert_array_equal(full.calibration.coef_, trained.calibration.coef_)
    tc = replace_epochs(trained.train_config, 3, **constant)
    infer(trained.run_dir, eval_set, tmp_path / "part", init="calibrated", epochs=3, train_config=tc, progress=False)
    resumed = infer(
        trained.run_dir,
        eval_set,
        tmp_path / "part",
        init="calibrated",
        epochs=6,
        resume=True,
        progress=False,
        **constant,
    )
    np.testing.assert_array_equal(resumed.latents, full.latents)
    # a calibrated start is lower than the raw projection's on these primitives
    raw = evaluate(trained, eval_set, trained.initializer.transform(scaled))["loss"]
    assert evaluate(trained, eval_set, expected)["loss"] < raw


def replace_epochs(tc, epochs, **changes):
    from dataclasses import replace

    return replace(tc, epochs=epochs, threads=1, **changes)


def test_calibrated_is_refused_without_a_projection_or_pca_fit(train_set, eval_set, tmp_path):
    zero = fit(
        train_set, tmp_path / "zero", model_config=SMALL, train_config=_tc(epochs=1), init="zero", progress=False
    )
    assert zero.calibration is None and not (tmp_path / "zero" / "calibration.json").exists()
    with pytest.raises(
        UserError, match="needs a run fitted with projection or pca init; this run's codes start from 'zero'"
    ):
        infer(zero, eval_set, tmp_path / "x", epochs=1, init="calibrated", progress=False)
    assert not (tmp_path / "x").exists()
    with pytest.raises(UserError, match="starts from a trained run's calibration map"):
        fit(
            train_set, tmp_path / "y", model_config=SMALL, train_config=_tc(epochs=1), init="calibrated", progress=False
        )
    pca = fit(train_set, None, model_config=SMALL, train_config=_tc(epochs=1), init="pca", progress=False)
    assert pca.calibration is not None


def test_a_fit_saved_without_calibration_gets_it_on_resume(train_set, eval_set, tmp_path):
    run = fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2), progress=False)
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    state["calibration"] = None  # as written by primspace 0.4
    torch.save(state, tmp_path / "run" / "checkpoint.pt")
    with pytest.raises(UserError, match="resume its fit once"):
        infer(tmp_path / "run", eval_set, tmp_path / "x", epochs=1, init="calibrated", progress=False)
    again = fit(
        train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2), resume=True, progress=False
    )
    np.testing.assert_array_equal(again.latents, run.latents)
    np.testing.assert_array_equal(again.calibration.coef_, run.calibration.coef_)
    # a map fitted another way (towards zero, as early 0.5 did) is refitted the current way
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    state["calibration"] = (
        CodeCalibration(SMALL.latent_dim, prior="zero").fit(run.initial_latents, run.latents).state_dict()
    )
    torch.save(state, tmp_path / "run" / "checkpoint.pt")
    assert load_run(tmp_path / "run").calibration.prior == "zero"
    third = fit(
        train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2), resume=True, progress=False
    )
    assert third.calibration.prior == "identity" and load_run(tmp_path / "run").calibration.prior == "identity"
    np.testing.assert_array_equal(third.calibration.coef_, run.calibration.coef_)


def test_extending_a_fit_refits_its_calibration_at_the_new_end(train_set, tmp_path):
    fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2), progress=False)
    longer = fit(
        train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=4), resume=True, progress=False
    )
    scaled = longer.scaler.transform(train_set.motor)
    again = CodeCalibration(SMALL.latent_dim).fit(longer.initializer.transform(scaled), longer.latents)
    np.testing.assert_allclose(longer.calibration.coef_, again.coef_, rtol=1e-10)


def test_weights_from_with_calibrated_codes_for_the_new_samples(trained, eval_set, tmp_path):
    second = fit(
        eval_set,
        tmp_path / "second",
        train_config=_tc(epochs=1),
        weights_from=trained,
        init="calibrated",
        progress=False,
    )
    scaled = trained.scaler.transform(eval_set.motor)
    expected = trained.calibration.transform(trained.initializer.transform(scaled))
    np.testing.assert_allclose(second.initial_latents, expected, rtol=1e-6)
    assert second.init == "calibrated" and second.calibration is not None  # its own map, at its own end


def test_infer_with_given_initial_latents(trained, eval_set):
    given = np.full((len(eval_set), SMALL.latent_dim), np.nan)
    given[:4] = 0.5
    ev = infer(trained, eval_set, None, epochs=0, initial_latents=given, progress=False)
    np.testing.assert_array_equal(ev.initial_latents[:4], 0.5)
    scaled = trained.scaler.transform(eval_set.motor)
    np.testing.assert_allclose(ev.initial_latents[4:], trained.initializer.transform(scaled)[4:], rtol=1e-6)


# ------------------------------------------------------------------------ the CLI


def test_cli_infer_calibrated_and_its_refusal(run_cli, train_set, eval_set, tmp_path):
    data = tmp_path / "d.h5"
    train_set.save(data)
    args = ("--latent-dim", "4", "--epochs", "3", "--layers", "12,6", "--threads", "1", "--batch-size", "12")
    res = run_cli("train", data, "--out", tmp_path / "proj", *args)
    assert res.code == 0, res.err
    assert "calibration (for --init calibrated): the fitted codes moved" in res.out
    res = run_cli(
        "infer",
        tmp_path / "proj",
        data,
        "--init",
        "calibrated",
        "--epochs",
        "2",
        "--out",
        tmp_path / "ev",
        "--threads",
        "1",
    )
    assert res.code == 0, res.err
    assert "infer, 36 samples, init calibrated" in res.out
    res = run_cli("train", data, "--init", "zero", "--out", tmp_path / "zero", *args)
    assert res.code == 0 and "calibration" not in res.out
    res = run_cli("infer", tmp_path / "zero", data, "--init", "calibrated", "--epochs", "2", "--out", tmp_path / "ev0")
    assert_user_error(res, "zero", "init 'calibrated' needs a run fitted with projection or pca init")
    assert not (tmp_path / "ev0").exists()
    res = run_cli("train", data, "--init", "calibrated", "--out", tmp_path / "c", *args)
    assert_user_error(res, "starts from a trained run's calibration map")


def test_the_estimator_transforms_from_the_calibrated_start(train_set, eval_set):
    from primspace import AutoDecoder

    model = AutoDecoder(SMALL, _tc(epochs=3), init="projection", progress=False).fit(train_set)
    z = model.transform(eval_set, epochs=0, init="calibrated")
    run = model.run_
    expected = run.calibration.transform(run.initializer.transform(run.scaler.transform(eval_set.motor)))
    np.testing.assert_allclose(z, expected, rtol=1e-6)
