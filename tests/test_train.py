"""fit / infer / reconstruct / evaluate and the run directory, on small synthetic primitives."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from primspace.data import MotionDataset
from primspace.model.config import ModelConfig
from primspace.train import (
    TrainConfig,
    TrainingDivergedError,
    evaluate,
    fit,
    infer,
    load_run,
    read_indices,
    reconstruct,
)
from primspace.utils.errors import OutputExistsError, UserError

SMALL = ModelConfig(latent_dim=6, layer_sizes=(16, 8), taus=(2.0, 8.0), p_hidden=32, motor_hidden=32)
FAST = dict(batch_size=12, threads=1)


def small_run(train: MotionDataset, **train_config):
    """A run of :data:`SMALL` fitted on ``train`` from the projection start (batch 12, one thread,
    no progress bar; ``train_config``: the other TrainConfig fields, e.g. ``epochs``)."""
    return fit(
        train,
        model_config=SMALL,
        init="projection",
        progress=False,
        train_config=TrainConfig(batch_size=12, threads=1, **train_config),
    )


def primitives(n_per: int, *, seed: int, T: int = 30, J: int = 4, K: int = 3, images: bool = False) -> MotionDataset:
    """K primitives, each a 2-parameter family of smooth joint trajectories: a minimum-jerk
    reach to an end posture linear in (x, y), plus a primitive-specific oscillation whose
    amplitude grows with x. The primitives are fixed; ``seed`` draws the (x, y)."""
    fixed = np.random.default_rng(1234)
    A = fixed.normal(0, 1, (K, J, 3))
    B = fixed.normal(0, 0.4, (K, J))
    w = fixed.uniform(1, 3, K)
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)
    s = 10 * t**3 - 15 * t**4 + 6 * t**5
    motor, labels, params = [], [], []
    for k in range(K):
        xy = rng.uniform(0, 1, (n_per, 2))
        end = np.c_[xy, np.ones(n_per)] @ A[k].T
        osc = np.sin(np.pi * w[k] * t)[None, :, None] * B[k][None, None, :] * (0.5 + xy[:, :1, None])
        motor.append(s[None, :, None] * end[:, None, :] + osc)
        labels += [k] * n_per
        params.append(xy)
    motor = np.concatenate(motor)
    frames = None
    if images:  # a bright square whose position follows the first two joints
        n = len(motor)
        frames = np.zeros((n, T, 8, 8, 3), dtype=np.uint8)
        pos = np.clip(((motor[..., :2] - motor[..., :2].min()) / np.ptp(motor[..., :2]) * 6).astype(int), 0, 6)
        for i in range(n):
            for tt in range(T):
                r, c = pos[i, tt]
                frames[i, tt, r : r + 2, c : c + 2] = 255
    return MotionDataset(motor, images=frames, labels=np.array(labels), params=np.concatenate(params))


@pytest.fixture(scope="module")
def train_set():
    return primitives(12, seed=0)


@pytest.fixture(scope="module")
def eval_set():
    return primitives(8, seed=100)


@pytest.fixture(scope="module")
def image_set():
    return primitives(4, seed=3, T=12, J=3, images=True)


def _tc(**kw):
    return TrainConfig(**{**FAST, **kw})


# ---------------------------------------------------------------------- learning


@pytest.mark.slow
def test_fit_reaches_a_low_loss(train_set, tmp_path):
    run = fit(
        train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=60), init="projection", progress=False
    )
    first, last = run.history[0]["loss"], run.history[-1]["loss"]
    assert run.epoch == 60 and len(run.history) == 61  # epoch 0 = before any update
    assert last < 0.01 and last < first / 20
    # the reconstruction comes back in physical units, consistent with the logged loss
    motor, frames = reconstruct(run)
    assert frames is None
    rms = np.sqrt(((motor - train_set.motor) ** 2).mean())
    assert rms < 0.2 * train_set.motor.std()
    scaled_mse = ((run.scaler.transform(motor) - run.scaler.transform(train_set.motor)) ** 2).mean()
    np.testing.assert_allclose(scaled_mse, evaluate(run, train_set)["motor"], rtol=1e-4)


@pytest.mark.slow
def test_infer_from_projection_ends_lower_than_from_random(train_set, eval_set, tmp_path):
    """The paper's intra-primitive result: trained (theta, Z) from a random-projection init
    encodes held-out samples of known primitives; from a random init it does not."""
    final = {}
    for init in ("random", "projection"):
        fit(train_set, tmp_path / init, model_config=SMALL, train_config=_tc(epochs=60), init=init, progress=False)
        ev = infer(tmp_path / init, eval_set, tmp_path / f"{init}-eval", epochs=30, progress=False)
        assert ev.init == init
        final[init] = ev.history[-1]["loss"]
    # measured: ~0.002 vs ~0.1 (several seeds and learning rates: a 20-100x gap)
    assert final["projection"] * 5 < final["random"], final


def test_infer_keeps_theta_frozen_and_only_moves_codes(train_set, eval_set, tmp_path):
    trained = fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2), progress=False)
    ev = infer(tmp_path / "run", eval_set, tmp_path / "eval", epochs=3, progress=False)
    for name, tensor in trained.model.state_dict().items():
        assert torch.equal(tensor, ev.model.state_dict()[name]), name
    assert ev.kind == "infer" and ev.parent == str((tmp_path / "run").resolve())
    assert ev.latents.shape == (len(eval_set), SMALL.latent_dim)
    assert not np.allclose(ev.latents, ev.initial_latents)
    # the run's P is reused for the new data
    scaled = trained.scaler.transform(eval_set.motor)
    np.testing.assert_allclose(ev.initial_latents, trained.initializer.transform(scaled), rtol=1e-6)
    # another init than the run's
    ev0 = infer(tmp_path / "run", eval_set, tmp_path / "eval0", epochs=1, init="zero", progress=False)
    assert ev0.init == "zero" and not ev0.initial_latents.any()


def test_images_are_trained_and_reconstructed(image_set, tmp_path):
    mc = ModelConfig(latent_dim=4, layer_sizes=(12, 6), image_channels=(8, 4, 4), p_hidden=16, motor_hidden=16)
    run = fit(
        image_set, tmp_path / "img", model_config=mc, train_config=_tc(epochs=8, lr=3e-3, batch_size=4), progress=False
    )
    assert run.model_config.image_size == (8, 8)
    assert all(h["vision"] is not None for h in run.history)
    assert run.history[-1]["vision"] < run.history[0]["vision"]
    motor, frames = reconstruct(run)
    assert motor.shape == image_set.motor.shape and frames.shape == image_set.images.shape
    assert frames.dtype == np.uint8
    # evaluate() uses the same definition as the log: loss = w_m motor + w_v vision, and the
    # initial model (same seed: an untrained run) with the initial codes gives epoch 0 of both runs
    again = evaluate(run, image_set, run.initial_latents)
    assert again["loss"] > 0 and again["loss"] == pytest.approx(again["motor"] + again["vision"], rel=1e-6)
    # the trained decoder reconstructs even the initial codes far better than epoch 0 (measured 0.27 vs 0.66)
    assert again["loss"] < 0.6 * run.history[0]["loss"], (again, run.history[0])
    logged = fit(
        image_set, tmp_path / "img0", model_config=mc, train_config=_tc(epochs=0, batch_size=4), progress=False
    )
    np.testing.assert_allclose(evaluate(logged, image_set)["loss"], logged.history[0]["loss"], rtol=1e-6)
    np.testing.assert_allclose(
        evaluate(logged, image_set, run.initial_latents)["loss"], run.history[0]["loss"], rtol=1e-6
    )
    # motor-only model on a data set with images
    plain = fit(
        image_set, tmp_path / "plain", model_config=mc, train_config=_tc(epochs=1), images=False, progress=False
    )
    assert plain.model.image_head is None and plain.history[-1]["vision"] is None


# ------------------------------------------------------------ determinism, resume


def test_same_seed_same_numbers_other_seed_differs(train_set, tmp_path):
    runs = [
        fit(train_set, tmp_path / name, model_config=SMALL, train_config=_tc(epochs=3, seed=seed), progress=False)
        for name, seed in (("a", 1), ("b", 1), ("c", 2))
    ]
    assert [h["loss"] for h in runs[0].history] == [h["loss"] for h in runs[1].history]
    np.testing.assert_array_equal(runs[0].latents, runs[1].latents)
    assert runs[0].history[-1]["loss"] != runs[2].history[-1]["loss"]


@pytest.mark.parametrize("with_images", [False, True])
def test_resume_continues_exactly(train_set, image_set, tmp_path, with_images):
    data = image_set if with_images else train_set
    mc = ModelConfig(latent_dim=4, layer_sizes=(12, 6), image_channels=(4, 4, 4), p_hidden=16, motor_hidden=16)
    # a constant rate: resuming 2 epochs up to 4 stretches a decaying schedule (fit's docstring)
    tc = _tc(epochs=4, batch_size=5, final_lr_fraction=1.0)
    straight = fit(data, tmp_path / "straight", model_config=mc, train_config=tc, progress=False)
    fit(data, tmp_path / "split", model_config=mc, train_config=replace(tc, epochs=2), progress=False)
    resumed = fit(data, tmp_path / "split", model_config=mc, train_config=tc, resume=True, progress=False)
    assert [h["epoch"] for h in resumed.history] == [0, 1, 2, 3, 4]
    for a, b in zip(straight.history, resumed.history):
        assert (a["loss"], a["motor"], a["vision"]) == (b["loss"], b["motor"], b["vision"])
    np.testing.assert_array_equal(straight.latents, resumed.latents)
    for name, tensor in straight.model.state_dict().items():
        assert torch.equal(tensor, resumed.model.state_dict()[name]), name
    np.testing.assert_array_equal(np.load(tmp_path / "split" / "latents.npy"), straight.latents)


def test_resume_of_infer_continues_exactly(train_set, eval_set, tmp_path):
    fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2), progress=False)
    constant = {"final_lr_fraction": 1.0}  # extended on resume: a decay would be stretched (fit's docstring)
    straight = infer(tmp_path / "run", eval_set, tmp_path / "a", epochs=4, progress=False, **constant)
    infer(tmp_path / "run", eval_set, tmp_path / "b", epochs=2, progress=False, **constant)
    resumed = infer(tmp_path / "run", eval_set, tmp_path / "b", epochs=4, resume=True, progress=False, **constant)
    assert [h["loss"] for h in straight.history] == [h["loss"] for h in resumed.history]
    np.testing.assert_array_equal(straight.latents, resumed.latents)


def test_resume_drops_metrics_written_after_the_last_checkpoint(train_set, tmp_path):
    constant = {"final_lr_fraction": 1.0}  # extended on resume: a decay would be stretched (fit's docstring)
    fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2, **constant), progress=False)
    with open(tmp_path / "run" / "metrics.jsonl", "a") as f:  # as if killed after logging epoch 3
        f.write(json.dumps({"epoch": 3, "loss": 9.0, "motor": 9.0, "vision": None}) + "\n")
    run = fit(
        train_set,
        tmp_path / "run",
        model_config=SMALL,
        train_config=_tc(epochs=3, **constant),
        resume=True,
        progress=False,
    )
    assert [h["epoch"] for h in run.history] == [0, 1, 2, 3]
    # epoch 3 is the one trained on resuming, as in an uninterrupted run, in memory and on disk
    straight = fit(
        train_set, tmp_path / "straight", model_config=SMALL, train_config=_tc(epochs=3, **constant), progress=False
    )
    assert [h["loss"] for h in run.history] == [h["loss"] for h in straight.history]
    logged = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert [(h["epoch"], h["loss"]) for h in logged] == [(h["epoch"], h["loss"]) for h in straight.history]


def test_resume_with_an_incompatible_config_is_refused(train_set, tmp_path):
    fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=1), progress=False)
    before = (tmp_path / "run" / "checkpoint.pt").read_bytes()
    with pytest.raises(UserError, match="cannot resume: model latent_dim differs"):
        fit(
            train_set,
            tmp_path / "run",
            model_config=ModelConfig(latent_dim=3, layer_sizes=(16, 8), p_hidden=32, motor_hidden=32),
            train_config=_tc(epochs=2),
            resume=True,
            progress=False,
        )
    with pytest.raises(UserError, match="cannot resume: train lr differs"):
        fit(
            train_set,
            tmp_path / "run",
            model_config=SMALL,
            train_config=_tc(epochs=2, lr=0.1),
            resume=True,
            progress=False,
        )
    with pytest.raises(UserError, match="cannot resume: init differs"):
        fit(
            train_set,
            tmp_path / "run",
            model_config=SMALL,
            train_config=_tc(epochs=2),
            init="zero",
            resume=True,
            progress=False,
        )
    with pytest.raises(UserError, match="cannot resume: data"):
        fit(
            primitives(12, seed=5),
            tmp_path / "run",
            model_config=SMALL,
            train_config=_tc(epochs=2),
            resume=True,
            progress=False,
        )
    assert (tmp_path / "run" / "checkpoint.pt").read_bytes() == before


def test_existing_run_dir_is_refused_and_untouched(train_set, tmp_path):
    fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=1), progress=False)
    snapshot = {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()}
    with pytest.raises(OutputExistsError, match="resume=True or overwrite=True"):
        fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=1), progress=False)
    assert {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()} == snapshot
    other = tmp_path / "notes"
    other.mkdir()
    (other / "x.txt").write_text("keep")
    with pytest.raises(UserError, match="not a primspace run directory"):
        fit(train_set, other, model_config=SMALL, train_config=_tc(epochs=1), overwrite=True, progress=False)
    assert (other / "x.txt").read_text() == "keep"
    again = fit(
        train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2), overwrite=True, progress=False
    )
    assert again.epoch == 2


def test_diverging_loss_stops_and_keeps_the_last_good_checkpoint(train_set, tmp_path):
    with pytest.raises(TrainingDivergedError, match=r"became (nan|inf) in epoch 1.*checkpoint \(epoch 0\) is kept"):
        fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=3, lr=1e30), progress=False)
    run = load_run(tmp_path / "run")
    assert run.epoch == 0 and [h["epoch"] for h in run.history] == [0]
    assert all(math.isfinite(v) for v in run.model.state_dict()["g.weight"].flatten().tolist())


# ------------------------------------------------------------------ the run dir


def test_run_directory_contents(train_set, tmp_path):
    idx = np.arange(0, 36, 2)
    run = fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=2), indices=idx, progress=False)
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["kind"] == "fit" and config["init"] == "projection"
    assert config["data"]["indices"] == idx.tolist() and config["model"]["n_joints"] == 4
    lines = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert [line["epoch"] for line in lines] == [0, 1, 2]
    assert set(lines[1]) == {"epoch", "loss", "motor", "vision", "seconds", "samples_per_s"}
    assert lines[1]["loss"] == lines[1]["motor"] and lines[1]["vision"] is None
    np.testing.assert_array_equal(np.load(tmp_path / "run" / "latents.npy"), run.latents)
    np.testing.assert_array_equal(np.load(tmp_path / "run" / "latents_init.npy"), run.initial_latents)
    np.testing.assert_array_equal(run.indices, idx)
    # the scaler was fitted on the selected samples only
    np.testing.assert_allclose(run.scaler.data_max_, train_set.motor[idx].max(axis=(0, 1)), rtol=1e-6)
    assert not list(tmp_path.glob("run/*.tmp"))


def test_weights_from_and_initial_latents(train_set, eval_set, tmp_path):
    first = fit(train_set, tmp_path / "first", model_config=SMALL, train_config=_tc(epochs=2), progress=False)
    given = np.full((len(eval_set), SMALL.latent_dim), np.nan)
    given[:5] = 7.0
    second = fit(
        eval_set,
        tmp_path / "second",
        train_config=_tc(epochs=0),
        weights_from=tmp_path / "first",
        initial_latents=given,
        progress=False,
    )
    assert second.parent == str((tmp_path / "first").resolve())
    for name, tensor in first.model.state_dict().items():
        assert torch.equal(tensor, second.model.state_dict()[name]), name
    np.testing.assert_array_equal(second.initial_latents[:5], 7.0)
    projected = first.initializer.transform(first.scaler.transform(eval_set.motor))
    np.testing.assert_allclose(second.initial_latents[5:], projected[5:], rtol=1e-6)
    np.testing.assert_array_equal(second.scaler.data_max_, first.scaler.data_max_)
    with pytest.raises(UserError, match="initial_latents must have shape"):
        fit(eval_set, tmp_path / "bad", model_config=SMALL, initial_latents=np.zeros((2, 6)), progress=False)


# --------------------------------------------------------------------- bad input


def test_bad_configuration_is_a_user_error(train_set, image_set, tmp_path):
    with pytest.raises(UserError, match="latent size"):
        fit(train_set, tmp_path / "a", model_config=ModelConfig(latent_dim=0), progress=False)
    with pytest.raises(UserError, match="unknown latent init"):
        fit(train_set, tmp_path / "a", init="sobol", progress=False)
    with pytest.raises(UserError, match="needs a CUDA device"):
        fit(train_set, tmp_path / "a", train_config=TrainConfig(device="cpu", amp=True), progress=False)
    with pytest.raises(UserError, match="has no images"):
        fit(train_set, tmp_path / "a", images=True, progress=False)
    with pytest.raises(UserError, match="cannot be produced by the image head"):
        fit(image_set, tmp_path / "a", model_config=ModelConfig(image_channels=(4, 4, 4, 4)), progress=False)
    assert not (tmp_path / "a").exists()
    if not torch.cuda.is_available():
        with pytest.raises(UserError, match="CUDA is not available"):
            fit(train_set, tmp_path / "a", train_config=TrainConfig(device="cuda"), progress=False)
    fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=0), progress=False)
    with pytest.raises(UserError, match="T=12 steps x J=3 joints, the model expects T=30 x J=4"):
        infer(tmp_path / "run", image_set, tmp_path / "e", epochs=1, progress=False)
    with pytest.raises(UserError, match="no such run directory"):
        load_run(tmp_path / "nowhere")


def test_read_indices(tmp_path):
    (tmp_path / "a.txt").write_text("# train split\n0, 3 5\n7\n")
    np.testing.assert_array_equal(read_indices(tmp_path / "a.txt"), [0, 3, 5, 7])
    np.save(tmp_path / "b.npy", np.array([4, 1]))
    np.testing.assert_array_equal(read_indices(tmp_path / "b.npy"), [4, 1])
    (tmp_path / "c.txt").write_text("1 x 2")
    with pytest.raises(UserError, match="c.txt, field 'indices'"):
        read_indices(tmp_path / "c.txt")
    (tmp_path / "d.txt").write_text("1 2 1")
    with pytest.raises(UserError, match="more than once"):
        read_indices(tmp_path / "d.txt")


def test_initial_latents_with_inf_are_refused(eval_set, tmp_path):
    bad = np.zeros((len(eval_set), SMALL.latent_dim))
    bad[3, 1] = np.inf
    with pytest.raises(UserError, match="row 3 contains inf"):
        fit(eval_set, tmp_path / "bad", model_config=SMALL, initial_latents=bad, progress=False)
    assert not (tmp_path / "bad").exists()


def test_cosine_learning_rate_schedule_ends_at_its_fraction():
    from primspace.train import lr_factor

    assert lr_factor(0, 10, 0.1) == 1.0
    assert abs(lr_factor(9, 10, 0.1) - 0.1) < 1e-12
    values = [lr_factor(e, 10, 0.1) for e in range(10)]
    assert all(a > b for a, b in zip(values, values[1:]))
    assert lr_factor(5, 10, 1.0) == 1.0


def test_resume_after_a_kill_continues_the_schedule_exactly(train_set, tmp_path, monkeypatch):
    """Interrupted mid-run (KeyboardInterrupt after the epoch-2 checkpoint), then resumed."""
    from primspace.train.loop import Session

    tc = _tc(epochs=4, batch_size=5, final_lr_fraction=0.1, checkpoint_every=1)
    straight = fit(train_set, tmp_path / "straight", model_config=SMALL, train_config=tc, progress=False)
    original = Session._checkpoint

    def checkpoint_then_die(self):
        original(self)
        if self.epoch == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(Session, "_checkpoint", checkpoint_then_die)
    with pytest.raises(KeyboardInterrupt):
        fit(train_set, tmp_path / "killed", model_config=SMALL, train_config=tc, progress=False)
    monkeypatch.undo()
    resumed = fit(train_set, tmp_path / "killed", model_config=SMALL, train_config=tc, resume=True, progress=False)
    assert [h["loss"] for h in resumed.history] == [h["loss"] for h in straight.history]
    np.testing.assert_array_equal(resumed.latents, straight.latents)
    constant = fit(
        train_set,
        tmp_path / "constant",
        model_config=SMALL,
        train_config=_tc(epochs=4, batch_size=5, final_lr_fraction=1.0),
        progress=False,
    )
    assert constant.history[-1]["loss"] != straight.history[-1]["loss"]  # the schedule does something


def test_train_config_json_roundtrip_and_unknown_field():
    cfg = TrainConfig(epochs=3, batch_size=5, lr=2e-3)
    assert TrainConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    with pytest.raises(UserError, match="unknown train config field.*: momentum"):
        TrainConfig.from_dict({**cfg.to_dict(), "momentum": 0.9})


@pytest.mark.slow
def test_inference_updates_do_not_depend_on_the_batch_size(train_set, eval_set, tmp_path):
    """With θ frozen every code steps on its own sample's gradient: batch 5 (24 samples,
    a short last batch every epoch), 7 and 24 give the same codes. Stepping on the
    batch-mean gradient differed by ~20% here."""
    fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=20), progress=False)
    codes = {}
    for b in (5, 7, 24):
        ev = infer(tmp_path / "run", eval_set, tmp_path / f"b{b}", epochs=15, batch_size=b, progress=False)
        codes[b] = ev.latents
        moved = np.abs(ev.latents - ev.initial_latents).max()
        assert moved > 0.05, moved
    for b in (5, 7):
        np.testing.assert_allclose(codes[b], codes[24], rtol=1e-4, atol=1e-5)


def test_a_given_scaler_is_used_and_recorded(train_set, tmp_path):
    from primspace.data import JointScaler

    wide = JointScaler().fit(np.concatenate([train_set.motor, 2 * train_set.motor]))
    run = fit(train_set, tmp_path / "run", model_config=SMALL, train_config=_tc(epochs=1), scaler=wide, progress=False)
    np.testing.assert_array_equal(run.scaler.data_max_, wide.data_max_)
    assert run.config["scaler"] == wide.to_dict()
    other = JointScaler().fit(train_set.motor)
    with pytest.raises(UserError, match="scaler differs"):
        fit(
            train_set,
            tmp_path / "run",
            model_config=SMALL,
            train_config=_tc(epochs=2),
            scaler=other,
            resume=True,
            progress=False,
        )
    with pytest.raises(UserError, match="not both"):
        fit(
            train_set,
            tmp_path / "r2",
            model_config=SMALL,
            train_config=_tc(epochs=1),
            scaler=wide,
            weights_from=tmp_path / "run",
            progress=False,
        )
