"""AutoDecoder: the model in scikit-learn's words, the same numbers as fit / infer /
reconstruct, in memory unless asked to write, and functions that accept each other's runs."""

import numpy as np
import pytest
import torch
from sklearn.base import clone

from primspace import AutoDecoder
from primspace.train import TrainConfig, fit, infer, load_run, reconstruct
from primspace.utils.errors import OutputExistsError, UserError
from test_train import SMALL, primitives

# a constant rate: a saved run is extended on resume below, which stretches a decay (fit's docstring)
TC = TrainConfig(epochs=3, batch_size=12, threads=1, seed=3, final_lr_fraction=1.0)


@pytest.fixture(scope="module")
def data():
    return primitives(10, seed=0, images=True)


@pytest.fixture(scope="module")
def new():
    return primitives(6, seed=100, images=True)


@pytest.fixture(scope="module")
def fitted(data):
    model = AutoDecoder(SMALL, TC, init="projection", progress=False)
    codes = model.fit_transform(data)
    return model, codes


def _parameters(model):
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def test_fit_transform_equals_fit_and_writes_nothing(fitted, data, tmp_path, monkeypatch):
    model, codes = fitted
    assert codes.shape == (len(data), SMALL.latent_dim) and codes.dtype == np.float32
    assert model.run_.run_dir is None and model.history_[0]["epoch"] == 0 and model.history_[-1]["epoch"] == 3
    assert model.history_[-1]["vision"] is not None  # the data has frames: the image head trained
    monkeypatch.chdir(tmp_path)
    on_disk = fit(data, tmp_path / "run", model_config=SMALL, train_config=TC, progress=False)
    np.testing.assert_array_equal(codes, on_disk.latents)
    assert [h["loss"] for h in model.history_] == [h["loss"] for h in on_disk.history]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # only the directory asked for


def test_codes_follow_the_order_of_the_data(data):
    """Training on the same samples in another order gives each sample the same code only up to
    the batch order; what is promised is the row order: row i is the code of the i-th sample given."""
    order = np.arange(len(data))[::-1].copy()
    model = AutoDecoder(SMALL, TrainConfig(epochs=0, threads=1, seed=3), init="projection", progress=False)
    codes = model.fit_transform(data.subset(order))
    straight = AutoDecoder(SMALL, TrainConfig(epochs=0, threads=1, seed=3), init="projection", progress=False)
    # with 0 epochs the codes are P m: the projection of each sample, whatever its position
    np.testing.assert_allclose(codes, straight.fit_transform(data)[order], rtol=1e-6, atol=1e-7)


def test_transform_equals_infer_and_leaves_the_model_alone(fitted, new):
    model, _ = fitted
    before = _parameters(model.run_.model)
    grads = [p.requires_grad for p in model.run_.model.parameters()]
    Z = model.transform(new, epochs=2)
    direct = infer(model.run_, new, epochs=2, progress=False)
    np.testing.assert_array_equal(Z, direct.latents)
    assert Z.shape == (len(new), SMALL.latent_dim)
    assert model.inference_.kind == "infer" and model.inference_.epoch == 2
    after = _parameters(model.run_.model)
    assert all(torch.equal(before[k], after[k]) for k in before)
    assert [p.requires_grad for p in model.run_.model.parameters()] == grads


def test_inverse_transform_is_reconstruct_in_physical_units(fitted, data):
    model, codes = fitted
    motor, frames = model.inverse_transform(codes)
    ref_motor, ref_frames = reconstruct(model.run_, codes)
    np.testing.assert_array_equal(motor, ref_motor)
    np.testing.assert_array_equal(frames, ref_frames)
    assert motor.shape == data.motor.shape and frames.dtype == np.uint8 and frames.shape[:2] == motor.shape[:2]
    # physical units: the decoder's scaled output mapped back through the run's joint scaler
    with torch.no_grad():
        raw = model.run_.model(torch.from_numpy(codes), images=False).motor.numpy()
    np.testing.assert_allclose(model.run_.scaler.transform(motor), raw, rtol=1e-4, atol=1e-5)
    assert not np.allclose(motor, raw, atol=1e-2)
    assert model.inverse_transform(codes, images=False)[1] is None


def test_save_load_roundtrip_and_resume_of_an_in_memory_fit(fitted, data, new, tmp_path):
    model, codes = fitted
    path = model.save(tmp_path / "saved")
    loaded = AutoDecoder.load(path, progress=False)
    np.testing.assert_array_equal(loaded.codes_, codes)
    assert loaded.get_params()["init"] == "projection" and loaded.model_config.latent_dim == SMALL.latent_dim
    np.testing.assert_array_equal(loaded.transform(new, epochs=2), model.transform(new, epochs=2))
    with pytest.raises(OutputExistsError, match="overwrite=True"):
        model.save(path)
    model.save(path, overwrite=True)
    # the saved run continues exactly like one that never stopped
    longer = TrainConfig(**{**TC.to_dict(), "epochs": 5})
    resumed = fit(data, path, model_config=SMALL, train_config=longer, resume=True, progress=False)
    straight = AutoDecoder(SMALL, longer, progress=False).fit(data)
    np.testing.assert_array_equal(resumed.latents, straight.codes_)
    assert [h["loss"] for h in resumed.history] == [h["loss"] for h in straight.history_]


def test_get_params_set_params_clone(fitted):
    model, _ = fitted
    params = model.get_params()
    assert set(params) == {"model_config", "train_config", "init", "images", "checkpoint_dir", "progress", "log_to"}
    copy = clone(model)
    assert not hasattr(copy, "run_") and copy.get_params()["train_config"] == TC
    assert copy.train_config is not model.train_config  # clone copies, it does not share
    copy.set_params(init="zero", train_config=TrainConfig(epochs=1, threads=1))
    assert copy.init == "zero" and copy.train_config.epochs == 1 and model.init == "projection"


def test_functions_accept_what_each_other_return(data, new, tmp_path):
    run = fit(data, model_config=SMALL, train_config=TC, progress=False)  # in memory
    inferred = infer(run, new, epochs=1, progress=False)
    assert inferred.parent is None and inferred.latents.shape == (len(new), SMALL.latent_dim)
    motor, _ = reconstruct(inferred)
    assert motor.shape == new.motor.shape
    child = fit(data, weights_from=run, train_config=TC, progress=False)
    assert child.model_config == run.model_config
    on_disk = infer(
        fit(data, tmp_path / "fit", model_config=SMALL, train_config=TC, progress=False),
        new,
        tmp_path / "infer",
        epochs=1,
        progress=False,
    )
    assert load_run(tmp_path / "infer").parent == str((tmp_path / "fit").resolve()) == on_disk.parent


def test_library_errors_speak_python(data, tmp_path):
    fit(data, tmp_path / "run", model_config=SMALL, train_config=TC, progress=False)
    with pytest.raises(OutputExistsError) as exc:
        fit(data, tmp_path / "run", model_config=SMALL, train_config=TC, progress=False)
    assert "resume=True or overwrite=True" in str(exc.value) and "--" not in str(exc.value)
    with pytest.raises(UserError, match="resume=True needs the out_dir"):
        fit(data, model_config=SMALL, train_config=TC, resume=True, progress=False)
    with pytest.raises(UserError, match="not fitted yet"):
        AutoDecoder().transform(data)
    with pytest.raises(UserError, match="unknown latent init 'bogus'"):
        AutoDecoder(SMALL, TC, init="bogus").fit(data)
    with pytest.raises(UserError, match="expected a TrainedRun or a run directory, got int"):
        infer(3, data, epochs=1)


def test_reconstruct_does_not_move_or_switch_the_callers_model(fitted):
    model, codes = fitted
    net = model.run_.model
    net.train()
    reconstruct(model.run_, codes[:2])
    assert net.training and next(net.parameters()).device.type == "cpu"
    net.eval()
