"""Predicting the rest of a motion (issue 25, items 2 and 6): `predict`, the mixture over
the fitted codes, the continuity correction, the predicted data set and `primspace predict`."""

import json

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.predict import AUTO, MIXTURE, predict
from primspace.predict.candidates import NOISE_GRID, CodeMixture, continuity_correction
from primspace.predict.metrics import unobserved_mse
from primspace.train import TrainConfig, fit
from primspace.utils.errors import UserError
from test_train import SMALL, primitives

FAST = dict(batch_size=12, threads=1)
# the small runs of the observation tests, shared (pytest registers the imported fixtures here)
from test_observe import eval_set, image_run, image_set, train_set, trained  # noqa: E402, F401

# ------------------------------------------------------------------ the mixture


def test_continuity_correction_closes_the_gap_and_leaves_the_observed_part():
    pred = np.zeros((2, 5, 1))
    truth = np.ones((2, 5, 1))
    observed = np.array([[1, 1, 0, 0, 0], [1, 0, 0, 0, 0]], bool)
    valid = np.array([[1, 1, 1, 1, 1], [1, 1, 1, 0, 0]], bool)
    out = continuity_correction(pred, truth, observed, valid)
    assert out[0, :, 0].tolist() == pytest.approx([0, 0, 2 / 3, 1 / 3, 0])  # residual 1 at step 1, 0 at the end
    assert out[1, :, 0].tolist() == pytest.approx([0, 0.5, 0, 0, 0])  # ends at the last valid step; padding untouched
    assert (pred == 0).all()  # the input is not changed


def test_the_mixture_recovers_a_decoded_candidate_and_weighs_by_the_observed_part():
    grid = np.linspace(0, 1, 20)

    def decode(codes):  # a line per code: offset + slope * t, (n, 20, 1)
        return codes[:, None, :1] + codes[:, None, 1:2] * grid[None, :, None]

    codes = np.array([[0.0, 1.0], [0.0, -1.0], [2.0, 0.0]])
    mixture = CodeMixture(codes, decode, neighbours=1, points=(0.5,))
    assert len(mixture.candidates) == 3 + 3  # the codes and one midpoint per code
    truth = decode(codes[[0, 2]])
    observed = np.zeros((2, 20), bool)
    observed[:, :8] = True
    scaled, modes = mixture.predict(truth, observed, noise=1e-4)
    np.testing.assert_allclose(scaled, truth, atol=1e-6)  # each prefix names its own line
    np.testing.assert_allclose(modes, codes[[0, 2]])
    wide, _ = mixture.predict(truth[:1], np.eye(1, 20, dtype=bool), noise=10.0)  # one step, both lines start at 0
    assert abs(wide[0, -1, 0] - truth[0, -1, 0]) > 0.3  # an ambiguous prefix averages the candidates
    with pytest.raises(UserError, match="noise"):
        CodeMixture(codes, decode).predict(truth, observed)


def _lines(codes, grid=np.linspace(0, 1, 20)):  # a line per code: offset + slope * t, (n, 20, 1)
    return codes[:, None, :1] + codes[:, None, 1:2] * grid[None, :, None]


def test_the_conditioned_ensemble_is_gaussian_conditioning_and_finds_a_motion_between_candidates():
    offsets, slopes = np.meshgrid(np.linspace(-1, 1, 5), np.linspace(-1, 1, 5))
    codes = np.stack([offsets.ravel(), slopes.ravel()], axis=1)
    mixture = CodeMixture(codes, _lines, neighbours=0)
    truth = _lines(np.array([[0.3, 0.7]]))  # between the candidates
    observed = np.zeros((1, 20), bool)
    observed[:, :6] = True
    w = mixture.weights(truth, observed, noise=0.1)
    mean, conditioned = mixture.posterior_mean(w), mixture.conditioned(w, truth, observed, 1e-6)
    left = ~observed[0]
    assert np.abs(conditioned[0, left] - truth[0, left]).max() < 1e-3  # a line is fixed by its beginning
    assert np.abs(mean[0, left] - truth[0, left]).max() > 0.05  # the average of the candidates is not
    # the same as conditioning the weighted Gaussian in the sequence's own space
    y = mixture.decoded.reshape(len(codes), -1)
    mu = w[0] @ y
    cov = (w[0][:, None] * (y - mu)).T @ (y - mu)
    o, r = observed[0], 1e-3
    expect = mu + cov[:, o] @ np.linalg.solve(cov[np.ix_(o, o)] + r * np.eye(o.sum()), truth[0, o, 0] - mu[o])
    np.testing.assert_allclose(mixture.conditioned(w, truth, observed, r)[0, :, 0], expect, atol=1e-8)


def test_the_noise_choice_may_take_the_conditioning_and_predict_follows_it():
    offsets, slopes = np.meshgrid(np.linspace(-1, 1, 6), np.linspace(-1, 1, 6))
    codes = np.stack([offsets.ravel(), slopes.ravel()], axis=1)
    mixture = CodeMixture(codes, _lines, neighbours=2, points=(0.5,))
    fitted = _lines(codes)
    observed = np.zeros(fitted.shape[:2], bool)
    observed[:, :5] = True
    choice = mixture.choose_noise(fitted, observed, np.ones_like(observed), grid=(1e-3, 1e-1), conditions=(None, 1e-4))
    assert set(choice["loo"]) == {"0.001/none", "0.001/0.0001", "0.1/none", "0.1/0.0001"}
    assert choice["condition"] == 1e-4  # lines are a linear family: conditioning predicts them best
    truth = _lines(np.array([[0.1, -0.35]]))
    chosen, _ = mixture.predict(truth, observed[:1])
    mean, _ = mixture.predict(truth, observed[:1], condition=None)
    assert np.abs(chosen - truth).max() < 0.1 * np.abs(mean - truth).max()
    only_mean = mixture.choose_noise(fitted, observed, np.ones_like(observed), grid=(1e-3,), conditions=(None,))
    assert only_mean["condition"] is None and mixture.condition is None


def test_choose_noise_uses_the_fitted_demonstrations_only(trained, train_set):
    scaled = trained.scaler.transform(train_set.motor)
    decode_calls = []

    def decode(codes):
        decode_calls.append(len(codes))
        return scaled[np.argmin(((codes[:, None] - trained.latents[None]) ** 2).sum(-1), axis=1)]

    mixture = CodeMixture(trained.latents, decode)
    observed = np.zeros(scaled.shape[:2], bool)
    observed[:, :10] = True
    choice = mixture.choose_noise(scaled, observed, np.ones_like(observed))
    assert mixture.noise == choice["noise"] in NOISE_GRID and mixture.condition == choice["condition"]
    assert min(choice["loo"], key=choice["loo"].get).split("/")[0] == f"{choice['noise']:g}"
    assert decode_calls == [len(mixture.candidates)]  # decoded once


# ------------------------------------------------------------------ predict


@pytest.mark.parametrize("init", ["projection", "nearest", MIXTURE])
def test_predict_measures_the_unobserved_steps_only(trained, train_set, eval_set, init):
    p = predict(trained, eval_set, observe=0.3, init=init, epochs=5, fitted_data=train_set, frames=False)
    assert p.motor.shape == eval_set.motor.shape and p.codes.shape == (len(eval_set), SMALL.latent_dim)
    assert p.motor_observed.sum(axis=1).tolist() == [9] * len(eval_set)  # ceil(0.3 * 30)
    scaler = trained.scaler
    expect = unobserved_mse(scaler.transform(p.motor), scaler.transform(eval_set.motor), p.motor_observed)
    np.testing.assert_allclose(p.errors["motor_mse"], expect, rtol=1e-5)
    assert np.isfinite(p.errors["motor_mse"]).all() and p.summary()["mean"]["motor_mse"] > 0


@pytest.mark.slow
def test_more_observed_predicts_better_with_the_mixture(trained, train_set, eval_set):
    early = predict(trained, eval_set, observe=0.1, init=MIXTURE, fitted_data=train_set, frames=False)
    late = predict(trained, eval_set, observe=0.6, init=MIXTURE, fitted_data=train_set, frames=False)
    assert late.summary()["mean"]["motor_mse"] < early.summary()["mean"]["motor_mse"]


def test_continuity_lowers_the_error_right_after_the_observed_part(trained, train_set, eval_set):
    kw = dict(observe=0.5, init="nearest", epochs=0, fitted_data=train_set, frames=False)
    plain, joined = predict(trained, eval_set, continuity=False, **kw), predict(trained, eval_set, **kw)
    truth, s = trained.scaler.transform(eval_set.motor), 15
    gap = lambda p: np.abs(trained.scaler.transform(p.motor)[:, s] - truth[:, s]).mean()  # noqa: E731
    assert gap(joined) < gap(plain)
    np.testing.assert_allclose(joined.motor[:, :s], plain.motor[:, :s], rtol=1e-5, atol=1e-6)


def test_same_seed_same_prediction(trained, train_set, eval_set):
    a = predict(trained, eval_set, observe=0.5, init="projection", epochs=5, frames=False)
    b = predict(trained, eval_set, observe=0.5, init="projection", epochs=5, frames=False)
    assert np.array_equal(a.motor, b.motor) and np.array_equal(a.codes, b.codes)


def test_the_prediction_is_a_data_set_of_the_same_schema(trained, eval_set, tmp_path):
    p = predict(trained, eval_set, observe=0.5, init="zero", epochs=3, indices=[3, 1], frames=False)
    ds = p.to_dataset(eval_set)
    assert ds.labels.tolist() == eval_set.labels[[3, 1]].tolist()
    np.testing.assert_array_equal(ds.motor, p.motor)
    back = MotionDataset.load(ds.save(tmp_path / "p.h5"))
    np.testing.assert_array_equal(back.motor, p.motor)
    assert "predicted by primspace" in back.source


def test_frames_are_predicted_and_scored_on_the_unobserved_frames(image_run, image_set):
    p = predict(image_run, image_set, observe=0.5, observe_frames="first", init="zero", epochs=2)
    assert p.frames.shape == image_set.images.shape and p.frames.dtype == np.uint8
    assert p.frames_observed.sum(axis=1).tolist() == [1] * len(image_set)
    assert (p.errors["vision_mse"] > 0).all() and np.allclose(
        p.errors["psnr"], 10 * np.log10(1 / p.errors["vision_mse"])
    )


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(observe=0), "at least 1 step"),
        (dict(observe=1.5), r"\(0, 1\]"),
        (dict(observe=None), "nothing to predict"),
        (dict(observe=0.5, init="oracle"), "unknown start"),
        (dict(observe=0.5, observe_frames="first"), "has no frames"),
        (dict(observe="none", observe_frames=None), "nothing to infer"),
    ],
)
def test_bad_requests_are_refused_in_one_line(trained, eval_set, kw, match):
    with pytest.raises(UserError, match=match):
        predict(trained, eval_set, epochs=1, **kw)


# ------------------------------------------------------------------ the command


@pytest.mark.slow
def test_predict_command_writes_data_result_and_figure(run_cli, train_set, eval_set, tmp_path):
    run_dir, data = tmp_path / "run", tmp_path / "data.h5"
    train_set.save(tmp_path / "train.h5")
    fit(
        MotionDataset.load(tmp_path / "train.h5"),
        run_dir,
        model_config=SMALL,
        train_config=TrainConfig(epochs=5, **FAST),
        progress=False,
    )
    eval_set.save(data)
    out = tmp_path / "pred"
    args = ["predict", run_dir, data, "--observe", "0.25", "--init", "mixture", "--out", out]
    res = run_cli(*args)
    assert res.code == 0, res.err
    assert "motions predicted" in res.out
    result = json.loads((out / "result.json").read_text())
    assert result["n"] == len(eval_set) and result["mean"]["motor_mse"] > 0 and result["success"] is None
    assert result["model_share"] == 1.0  # the mixture decodes codes: all of it comes through the decoder
    assert len(result["per_sample"]["motor_mse"]) == len(eval_set)
    assert MotionDataset.load(out / "predicted.h5").motor.shape == eval_set.motor.shape
    assert (out / "prediction.png").stat().st_size > 1000
    assert_user_error(run_cli(*args), "exists")  # never replaced without --overwrite
    assert run_cli(*args, "--overwrite").code == 0


@pytest.mark.parametrize(
    "flags, match",
    [
        (["--observe-steps", "0"], "at least 1 step"),
        (["--observe", "0.25", "--observe-steps", "5"], "not both"),
        (["--observe", "1.5"], "(0, 1]"),
        (["--observe", "half"], "--observe 'half'"),
        (["--observe", "0.5", "--observe-frames", "first"], "has no frames"),
    ],
)
def test_predict_command_refuses_bad_input_with_exit_2(run_cli, eval_set, tmp_path, flags, match):
    run_dir, data = tmp_path / "run", tmp_path / "data.h5"
    fit(eval_set, run_dir, model_config=SMALL, train_config=TrainConfig(epochs=1, **FAST), progress=False)
    eval_set.save(data)
    assert_user_error(run_cli("predict", run_dir, data, "--out", tmp_path / "o", *flags), match)
    assert not (tmp_path / "o").exists()


def test_the_estimator_predicts_in_physical_units(train_set, eval_set):
    from primspace import AutoDecoder

    model = AutoDecoder(
        model_config=SMALL, train_config=TrainConfig(epochs=10, **FAST), init="projection", progress=False
    ).fit(train_set)
    motor, frames = model.predict(eval_set, observe=0.5)
    assert motor.shape == eval_set.motor.shape and frames is None
    assert model.prediction_.init == AUTO and np.isfinite(model.prediction_.errors["motor_mse"]).all()
    np.testing.assert_allclose(motor[:, :1], eval_set.motor[:, :1], atol=np.ptp(eval_set.motor))  # physical scale


def test_online_prediction_reports_latency_and_the_error_against_time(run_cli, trained, train_set, eval_set, tmp_path):
    p = predict(trained, eval_set, observe=0.5, init="nearest", online=2, fitted_data=train_set, frames=False)
    online = p.details["online"]
    assert online["steps_observed"] == 15 and online["iterations"] == 2 and online["latency_ms_mean"] > 0
    assert len(online["remaining_error"]) == eval_set.length and online["remaining_error"][-1] is None  # nothing left
    assert np.isfinite(p.errors["motor_mse"]).all()
    with pytest.raises(UserError, match="iterations"):
        predict(trained, eval_set, observe=0.5, init="zero", online=-1)


@pytest.mark.slow
def test_predict_on_an_imported_csv_folder(run_cli, tmp_path):
    """The README's path for one's own demonstrations: a CSV folder imported, fitted, predicted."""
    data = primitives(4, seed=7, T=20, J=3)
    for i, (motion, label) in enumerate(zip(data.motor, data.labels)):
        folder = tmp_path / "csv" / f"prim{label}"
        folder.mkdir(parents=True, exist_ok=True)
        rows = "\n".join(",".join(f"{v:.6f}" for v in step) for step in motion)
        (folder / f"demo{i}.csv").write_text("j0,j1,j2\n" + rows + "\n")
    assert (
        run_cli("import", tmp_path / "csv", "--format", "csv", "--length", "20", "--out", tmp_path / "d.h5").code == 0
    )
    assert (
        run_cli("train", tmp_path / "d.h5", "--epochs", "3", "--latent-dim", "4", "--out", tmp_path / "run").code == 0
    )
    res = run_cli(
        "predict",
        tmp_path / "run",
        tmp_path / "d.h5",
        "--observe-steps",
        "5",
        "--init",
        "nearest",
        "--epochs",
        "2",
        "--out",
        tmp_path / "pred",
    )
    assert res.code == 0, res.err
    result = json.loads((tmp_path / "pred" / "result.json").read_text())
    assert result["observe"] == {"motor": 5, "frames": 5} and result["mean"]["motor_mse"] > 0
    assert (
        MotionDataset.load(tmp_path / "pred" / "predicted.h5").label_names
        == MotionDataset.load(tmp_path / "d.h5").label_names
    )
    # every number traces to a recording: the csv file of each predicted sample, and of each fitted one
    ids = [str(v) for v in MotionDataset.load(tmp_path / "d.h5").source_ids]
    assert ids[0] == "csv:csv/prim" + ids[0].split("/prim", 1)[1] and ids[0].endswith(".csv")
    assert result["source_ids"] == [ids[i] for i in result["indices"]]
    assert list(MotionDataset.load(tmp_path / "pred" / "predicted.h5").source_ids) == result["source_ids"]
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["data"]["source_ids"] == [ids[i] for i in config["data"]["indices"]]


def test_the_mixture_is_decoded_once_per_predictor_and_nothing_is_cached_on_the_run(trained, train_set, eval_set):
    """Issue 37: the prepared state lives in the predictor (fitted once), never on the run."""
    from primspace.predict import MixturePredictor, fit_predictor
    from primspace.train.observe import Observation

    predictor = fit_predictor(MixturePredictor(trained), trained, train_set)
    built = predictor.mixture_
    scaled = trained.scaler.transform(eval_set.motor)
    first = predictor.forecast(scaled, Observation.build(0.2), lengths=eval_set.lengths)
    second = predictor.forecast(scaled, Observation.build(0.6), lengths=eval_set.lengths)
    assert predictor.mixture_ is built  # the second fraction reuses the decoded candidates
    assert first.details["mixture"]["candidates"] == second.details["mixture"]["candidates"] == len(built.candidates)
    assert not hasattr(trained, "mixture") and not hasattr(trained, "observed_calibrations")
    via_predict = predict(trained, eval_set, observe=0.2, init=MIXTURE, fitted_data=train_set, frames=False)
    np.testing.assert_allclose(trained.scaler.transform(via_predict.motor), first.motor, rtol=1e-5, atol=1e-6)


def test_one_leave_one_out_search_per_rule(trained, train_set, eval_set, monkeypatch):
    from primspace.predict import MixturePredictor, code_mixture, fit_predictor
    from primspace.train.observe import Observation

    searches = []
    original = CodeMixture.choose_noise

    def counted(self, *args, **kwargs):
        searches.append(kwargs.get("conditions"))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(CodeMixture, "choose_noise", counted)
    shared = code_mixture(trained)  # one set of candidates for the three predictors
    make = lambda **kw: fit_predictor(MixturePredictor(trained, candidates=shared, **kw), trained, train_set)  # noqa: E731
    scaled, lengths = trained.scaler.transform(eval_set.motor), eval_set.lengths
    plain = make().forecast(scaled, Observation.build(0.3), lengths=lengths)
    joined = make(continuity=False).forecast(scaled, Observation.build(0.3), lengths=lengths)  # the same search
    make(condition=False).forecast(scaled, Observation.build(0.3), lengths=lengths)  # posterior mean only: its own
    make().forecast(scaled, Observation.build(0.5), lengths=lengths)  # another rule
    assert len(searches) == 3 and searches[1] == (None,)
    assert plain.details["mixture"] == joined.details["mixture"]


def test_predict_overwrite_never_replaces_what_it_did_not_write(run_cli, eval_set, tmp_path):
    run_dir, data = tmp_path / "run", tmp_path / "data.h5"
    eval_set.save(data)
    fit(
        MotionDataset.load(data),
        run_dir,
        model_config=SMALL,
        train_config=TrainConfig(epochs=1, **FAST),
        progress=False,
    )
    foreign = tmp_path / "notes"
    foreign.mkdir()
    (foreign / "result.json").write_text('{"mine": 1}')
    res = run_cli("predict", run_dir, data, "--observe", "0.5", "--epochs", "1", "--out", foreign, "--overwrite")
    assert_user_error(res, "not a primspace predict output")
    assert (foreign / "result.json").read_text() == '{"mine": 1}' and len(list(foreign.iterdir())) == 1


def test_the_predicted_subset_keeps_each_labels_share_and_follows_the_seed():
    from primspace.experiments.prediction import predicted_subset

    idx = np.arange(100, 200)
    labels = np.repeat([0, 1, 2], [60, 30, 10])
    assert predicted_subset(idx, labels, 100, 0) is idx and predicted_subset(idx, labels, None, 0) is idx
    sub = predicted_subset(idx, labels, 21, seed=3)
    assert len(sub) == 21 and (np.diff(sub) > 0).all() and set(sub) <= set(idx)
    assert np.bincount(labels[sub - 100]).tolist() == [13, 6, 2]  # 12.6 / 6.3 / 2.1: the remainder to the largest
    np.testing.assert_array_equal(sub, predicted_subset(idx, labels, 21, seed=3))
    assert not np.array_equal(sub, predicted_subset(idx, labels, 21, seed=4))


# ------------------------------------------------------------------ the mixture online


def test_the_online_mixture_is_the_offline_mixture_after_every_step(trained, train_set, eval_set):
    """One object, offline and online: after step t the online prediction is the offline one of
    the same prefix without the ensemble conditioning (condition=False)."""
    from primspace.predict import MixturePredictor, fit_predictor

    predictor = fit_predictor(MixturePredictor(trained, condition=False), trained, train_set)
    scaled = trained.scaler.transform(eval_set.motor)
    result = predictor.predict_online(scaled, eval_set.lengths, start_step=4, prediction_after=9)
    assert result.steps.tolist() == list(range(4, 31)) and result.iterations == 0 and (result.latency > 0).all()
    for t in (4, 9, 20):
        offline = predict(
            trained,
            eval_set,
            observe=t,
            init=MIXTURE,
            fitted_data=train_set,
            frames=False,
            condition=False,
            continuity=True,
        )
        np.testing.assert_allclose(result.errors[:, result.column(t)], offline.errors["motor_mse"], rtol=1e-6)
        if t == 9:
            np.testing.assert_allclose(result.prediction, offline.motor, rtol=1e-5, atol=1e-6)
    assert result.error_at(20) < result.error_at(4)  # the posterior sharpens as steps arrive
    with pytest.raises(UserError, match="prediction_after"):
        predictor.predict_online(scaled, eval_set.lengths, start_step=4, prediction_after=2)


def test_predict_online_with_the_mixture_keeps_the_prediction_after_the_observed_steps(trained, train_set, eval_set):
    online = predict(
        trained, eval_set, observe=12, init=MIXTURE, online=0, fitted_data=train_set, frames=False, continuity=True
    )
    offline = predict(
        trained,
        eval_set,
        observe=12,
        init=MIXTURE,
        fitted_data=train_set,
        frames=False,
        condition=False,
        continuity=True,
    )
    np.testing.assert_allclose(online.errors["motor_mse"], offline.errors["motor_mse"], rtol=1e-5)
    curve = online.details["online"]["remaining_error"]
    assert len(curve) == eval_set.length and online.details["online"]["latency_ms_mean"] > 0


def test_the_best_predictor_is_the_default_of_python_the_estimator_and_the_command_line():
    """The predictor chosen by held-out evidence (auto, with the continuity correction; docs/predict.md)
    is what `predict`, `AutoDecoder.predict` and `primspace predict` do when nothing is named."""
    import inspect

    from primspace import AutoDecoder
    from primspace.cli.predict import predict_command
    from primspace.predict import DEFAULT_PREDICTOR, PredictRequest

    assert DEFAULT_PREDICTOR == AUTO
    python = PredictRequest()  # predict's keywords are a request's fields
    estimator = inspect.signature(AutoDecoder.predict).parameters
    cli = inspect.signature(predict_command).parameters
    assert python.init == estimator["init"].default == AUTO
    assert python.continuity is estimator["continuity"].default is True
    assert cli["init"].default.default is None and cli["continuity"].default.default is True  # None: DEFAULT_PREDICTOR


def test_the_predicted_data_set_keeps_the_data_files_sample_numbers(trained, train_set, eval_set):
    """Issue 37, section 3: predicted.h5 names each row by the data file's index, as result.json does."""
    p = predict(trained, eval_set, observe=0.5, indices=[3, 1], fitted_data=train_set, frames=False)
    assert p.indices.tolist() == [3, 1]
    assert list(p.to_dataset(eval_set).source_ids) == ["sample 3", "sample 1"]


def test_predicted_joints_stay_within_their_recorded_range(trained, train_set, eval_set):
    """Issue 37, section 3: a predicted joint (a gripper) never leaves the range the fitted
    demonstrations recorded, whatever the predictor."""
    lo, hi = trained.scaler.data_min_, trained.scaler.data_max_
    for init in ("random", MIXTURE):  # random's prediction leaves the range here without the bound
        p = predict(trained, eval_set, observe=0.25, init=init, epochs=3, fitted_data=train_set, frames=False)
        assert (p.motor >= lo - 1e-5).all() and (p.motor <= hi + 1e-5).all(), init
    raw = predict(trained, eval_set, observe=0.25, init="zero", epochs=3, fitted_data=train_set, frames=False)
    assert np.isfinite(raw.errors["motor_mse"]).all()


def test_a_gradient_predictor_predicts_from_arrays_of_motions_of_different_lengths(trained, train_set, eval_set):
    """The predictor interface on arrays alone (no data set): given lengths went through a
    MotionDataset without the step fields padded samples need, and failed."""
    from primspace.predict import GradientPredictor, fit_predictor
    from primspace.train.observe import Observation

    predictor = fit_predictor(GradientPredictor(trained, "projection", epochs=2, progress=False), trained, train_set)
    truth = trained.scaler.transform(eval_set.motor)
    full = np.full(len(eval_set), eval_set.length)
    scaled = predictor.predict(truth, Observation.build(0.5), lengths=full)
    via_data = predict(trained, eval_set, observe=0.5, init="projection", epochs=2, frames=False, fitted_data=train_set)
    np.testing.assert_allclose(np.clip(scaled, -1, 1), trained.scaler.transform(via_data.motor), atol=1e-4)
    shorter = full.copy()
    shorter[0] = eval_set.length - 5  # a motion that ends early: padded, with the step fields made for it
    assert np.isfinite(predictor.predict(truth, Observation.build(0.5), lengths=shorter)).all()
