"""`primspace train | infer | reconstruct` end to end, and their errors (exit 2, one line)."""

import json

import h5py
import numpy as np
import pytest

from conftest import assert_figure, assert_user_error
from primspace.data import MotionDataset

SMALL_ARGS = ("--layers", "12,6", "--image-channels", "4,4,4", "--threads", "1", "--batch-size", "4")


def _dataset(n=8, T=10, J=3, size=(8, 8), seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)
    a = rng.uniform(0.5, 1.5, (n, 1, 1))
    motor = np.concatenate([a * np.sin(4 * t)[None, :, None], a**2 * t[None, :, None], np.cos(a * t[None, :, None])], 2)
    images = None if size is None else rng.integers(0, 255, (n, T, *size, 3), dtype=np.uint8)
    return MotionDataset(motor[..., :J], images=images, labels=np.arange(n) % 2, dt=0.5)


@pytest.fixture(scope="module")
def data_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "d.h5"
    _dataset().save(path)
    return path


@pytest.mark.slow
def test_train_infer_reconstruct(run_cli, data_file, tmp_path):
    (tmp_path / "train.txt").write_text("0 2 4 6\n")
    np.save(tmp_path / "eval.npy", np.array([1, 3, 5, 7]))
    run, ev = tmp_path / "run", tmp_path / "eval"
    res = run_cli(
        "train",
        data_file,
        "--init",
        "projection",
        "--latent-dim",
        "3",
        "--epochs",
        "2",
        "--indices",
        tmp_path / "train.txt",
        "--out",
        run,
        *SMALL_ARGS,
    )
    assert res.code == 0, res.err
    assert "fit, 4 samples, init projection, q=3, epoch 2" in res.out
    config = json.loads((run / "config.json").read_text())
    assert config["data"]["indices"] == [0, 2, 4, 6] and config["model"]["image_size"] == [8, 8]
    assert config["model"]["layer_sizes"] == [12, 6] and config["train"]["threads"] == 1
    assert np.load(run / "latents.npy").shape == (4, 3)

    res = run_cli(
        "infer", run, data_file, "--epochs", "2", "--indices", tmp_path / "eval.npy", "--out", ev, "--threads", "1"
    )
    assert res.code == 0, res.err
    assert "infer, 4 samples, init projection" in res.out
    assert np.load(ev / "latents.npy").shape == (4, 3)

    res = run_cli("reconstruct", ev, "--sample", "3", "--out", tmp_path / "s3.png")
    assert res.code == 0, res.err
    assert_figure(tmp_path / "s3.png", height=(200, 3000), width=(300, 4000))
    res = run_cli("reconstruct", run, "--sample", "3", "--out", tmp_path / "x.png")
    assert_user_error(res, "sample 3 is not one of the run's 4 samples")
    assert not (tmp_path / "x.png").exists()

    # resume to more epochs; an existing run without --resume is refused
    res = run_cli(
        "train",
        data_file,
        "--latent-dim",
        "3",
        "--epochs",
        "3",
        "--indices",
        tmp_path / "train.txt",
        "--out",
        run,
        "--resume",
        *SMALL_ARGS,
    )
    assert res.code == 0, res.err
    assert "epoch 3" in res.out
    before = (run / "metrics.jsonl").read_text()
    res = run_cli("train", data_file, "--latent-dim", "3", "--epochs", "3", "--out", run, *SMALL_ARGS)
    assert_user_error(res, str(run), "--resume or --overwrite")
    assert (run / "metrics.jsonl").read_text() == before
    res = run_cli(
        "train",
        data_file,
        "--latent-dim",
        "5",
        "--epochs",
        "4",
        "--indices",
        tmp_path / "train.txt",
        "--out",
        run,
        "--resume",
        *SMALL_ARGS,
    )
    assert_user_error(res, "cannot resume", "latent_dim")


@pytest.mark.slow
def test_train_without_images(run_cli, data_file, tmp_path):
    res = run_cli(
        "train",
        data_file,
        "--init",
        "pca",
        "-q",
        "2",
        "--epochs",
        "1",
        "--no-images",
        "--out",
        tmp_path / "run",
        *SMALL_ARGS,
    )
    assert res.code == 0, res.err
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["model"]["image_size"] is None and config["data"]["images"] is False
    res = run_cli("reconstruct", tmp_path / "run", "--sample", "0", "--out", tmp_path / "r.png")
    assert res.code == 0, res.err
    assert_figure(tmp_path / "r.png", height=(200, 3000), width=(300, 4000))


def test_data_set_without_motor_is_refused(run_cli, tmp_path):
    path = tmp_path / "nomotor.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("labels", data=np.zeros(3, dtype=np.int32))
    res = run_cli("train", path, "--epochs", "1", "--out", tmp_path / "run")
    assert_user_error(res, "nomotor.h5", "motor")
    assert not (tmp_path / "run").exists()


def test_latent_size_below_one_is_refused(run_cli, data_file, tmp_path):
    res = run_cli("train", data_file, "--latent-dim", "0", "--epochs", "1", "--out", tmp_path / "run")
    assert_user_error(res, "latent size", "at least 1")
    assert not (tmp_path / "run").exists()


def test_image_size_the_head_cannot_produce_is_refused(run_cli, tmp_path):
    path = tmp_path / "odd.h5"
    _dataset(size=(12, 20)).save(path)
    res = run_cli("train", path, "--epochs", "1", "--out", tmp_path / "run")
    assert_user_error(
        res,
        "image size 12x20 cannot be produced",
        "multiples of 8",
    )
    assert not (tmp_path / "run").exists()
    # it trains once the head fits (2 deconvolutions: multiples of 4) or without images
    res = run_cli(
        "train",
        path,
        "--epochs",
        "1",
        "--image-channels",
        "4,4",
        "--out",
        tmp_path / "run",
        "--threads",
        "1",
        "--layers",
        "8,4",
    )
    assert res.code == 0, res.err


@pytest.mark.parametrize(
    "args,fragments",
    [
        (("--init", "sobol"), ("sobol",)),
        (("--taus", "2,x"), ("--taus",)),
        (("--device", "tpu"), ("device",)),
        (("--amp", "--device", "cpu"), ("needs a CUDA device",)),
        (("--lr", "-1"), ("lr must be",)),
    ],
)
def test_bad_options_are_refused(run_cli, data_file, tmp_path, args, fragments):
    res = run_cli("train", data_file, "--epochs", "1", "--out", tmp_path / "run", *args)
    assert res.code == 2, res.err
    assert "Traceback" not in res.err
    for fragment in fragments:
        assert fragment in res.err
    assert not (tmp_path / "run").exists()


def test_bad_indices_and_runs_are_refused(run_cli, data_file, tmp_path):
    (tmp_path / "bad.txt").write_text("0 99\n")
    res = run_cli("train", data_file, "--epochs", "1", "--indices", tmp_path / "bad.txt", "--out", tmp_path / "run")
    assert_user_error(res, "bad.txt", "sample 99 is out of range for the 8 samples")
    res = run_cli("infer", tmp_path / "nothing", data_file, "--epochs", "1", "--out", tmp_path / "e")
    assert_user_error(res, "nothing", "no such run directory")
    res = run_cli("reconstruct", tmp_path / "nothing", "--sample", "0", "--out", tmp_path / "x.png")
    assert_user_error(res, "no such run directory")


def test_loss_curve_figure(tmp_path):
    from primspace.plots import plot_loss_curves, save_figure

    def history(scale):
        return [{"epoch": e, "loss": scale / (e + 1), "motor": scale / (e + 1), "vision": None} for e in range(5)]

    fig = plot_loss_curves({"zero q=20": history(1.0), "projection q=20": [history(0.5), history(0.7)]})
    ax = fig.axes[0]
    assert [line.get_label() for line in ax.get_lines()] == ["zero q=20", "projection q=20"]
    np.testing.assert_allclose(ax.get_lines()[1].get_ydata(), 0.6 / np.arange(1, 6))  # mean of the two runs
    assert ax.get_lines()[1].get_color() == "tab:green"
    save_figure(fig, tmp_path / "curves.png")
    assert_figure(tmp_path / "curves.png", min_coloured=200, colours=("tab:blue", "tab:green"))


def test_loss_band_stays_positive_on_a_log_axis():
    from primspace.plots import plot_loss_curves

    def history(values):
        return [{"epoch": e, "loss": v} for e, v in enumerate(values)]

    # mean - std < 0 at epoch 1 (one fold spikes): the band must stop at the lowest fold, not cross zero
    runs = [history([1.0, 1e-4, 1e-4]), history([1.0, 1e-4, 1e-4]), history([1.0, 1.0, 1e-4])]
    fig = plot_loss_curves({"projection": runs}, log_scale=True)
    band = fig.axes[0].collections[0].get_paths()[0].vertices
    assert band[:, 1].min() == pytest.approx(1e-4)
    fig = plot_loss_curves({"projection": runs}, log_scale=False)
    assert fig.axes[0].collections[0].get_paths()[0].vertices[:, 1].min() < 0  # linear axis: plain mean - std
