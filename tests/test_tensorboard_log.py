"""`--log-to tensorboard DIR` / ``log_to=("tensorboard", DIR)``: metrics.jsonl's numbers as
TensorBoard event files, read back with TensorBoard's own reader (issue 26, item 6)."""

import json
import sys

import numpy as np
import pytest
from sklearn.base import clone
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

from conftest import assert_user_error
from primspace import AutoDecoder
from primspace.train import TrainConfig, fit, infer
from primspace.train.logger import TensorBoardLogger, scalars
from primspace.utils.errors import UserError
from test_train import SMALL, primitives

TC = TrainConfig(epochs=3, batch_size=4, threads=1)
CLI_ARGS = ("--layers", "12,6", "--threads", "1", "--batch-size", "4", "--no-images", "--latent-dim", "3")


@pytest.fixture(scope="module")
def data():
    return primitives(2, seed=0, T=12, J=3)


@pytest.fixture(scope="module")
def data_file(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("data") / "d.h5"
    data.save(path)
    return path


def read_scalars(folder) -> dict[str, list[tuple[int, float]]]:
    """What TensorBoard shows of ``folder``: (step, value) per scalar tag, in step order."""
    acc = EventAccumulator(str(folder))
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def assert_same_as_metrics(folder, history: list[dict]) -> None:
    """Every numeric value of every metrics line at its epoch, once, and nothing else."""
    shown = read_scalars(folder)
    expected: dict[str, list[tuple[int, float]]] = {}
    for line in history:
        for tag, value in scalars(line).items():
            expected.setdefault(tag, []).append((line["epoch"], value))
    assert set(shown) == set(expected), (set(shown), set(expected))
    for tag, points in expected.items():
        assert [s for s, _ in shown[tag]] == [s for s, _ in points], tag  # every epoch exactly once, in order
        for (step, value), (_, logged) in zip(shown[tag], points):
            assert np.float32(value) == np.float32(logged), (tag, step, value, logged)  # stored as float32


def test_fit_writes_every_metric_of_every_epoch(data, tmp_path):
    run = fit(
        data,
        tmp_path / "run",
        model_config=SMALL,
        train_config=TC,
        progress=False,
        log_to=("tensorboard", tmp_path / "tb"),
    )
    lines = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert [h["epoch"] for h in lines] == [0, 1, 2, 3] and lines == run.history
    assert_same_as_metrics(tmp_path / "tb", lines)
    assert set(read_scalars(tmp_path / "tb")) == {"loss", "motor", "seconds", "samples_per_s"}  # vision: null


def test_a_killed_then_resumed_run_shows_each_epoch_once(data, tmp_path, monkeypatch):
    """Killed after logging epoch 3, whose checkpoint (every 2 epochs) never came: the resume
    redoes epoch 3 from the epoch-2 checkpoint, and TensorBoard shows it once."""
    from primspace.train.loop import Session

    tc = TrainConfig(epochs=5, batch_size=4, threads=1, checkpoint_every=2)
    log_to = ("tensorboard", tmp_path / "tb")
    original = Session._log

    def log_then_die(self, epoch, values, seconds):
        original(self, epoch, values, seconds)
        if epoch == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(Session, "_log", log_then_die)
    with pytest.raises(KeyboardInterrupt):
        fit(data, tmp_path / "run", model_config=SMALL, train_config=tc, progress=False, log_to=log_to)
    monkeypatch.undo()
    assert [s for s, _ in read_scalars(tmp_path / "tb")["loss"]] == [0, 1, 2, 3]
    resumed = fit(
        data, tmp_path / "run", model_config=SMALL, train_config=tc, resume=True, progress=False, log_to=log_to
    )
    assert [h["epoch"] for h in resumed.history] == [0, 1, 2, 3, 4, 5]
    assert_same_as_metrics(tmp_path / "tb", resumed.history)
    # the event files do hold epoch 3 twice: the resume's restart marker hides the first
    raw = [
        e.step
        for f in sorted((tmp_path / "tb").iterdir())
        for e in EventFileLoader(str(f)).Load()
        if e.HasField("summary") and e.summary.value[0].tag == "loss"
    ]
    assert sorted(raw) == [0, 1, 2, 3, 3, 4, 5]


def test_a_finished_resume_and_an_overwrite_log_nothing_twice(data, tmp_path):
    log_to = ("tensorboard", tmp_path / "tb")
    run = fit(data, tmp_path / "run", model_config=SMALL, train_config=TC, progress=False, log_to=log_to)
    fit(data, tmp_path / "run", model_config=SMALL, train_config=TC, resume=True, progress=False, log_to=log_to)
    assert_same_as_metrics(tmp_path / "tb", run.history)
    other = TrainConfig(epochs=2, batch_size=4, threads=1, seed=7)
    again = fit(
        data, tmp_path / "run", model_config=SMALL, train_config=other, overwrite=True, progress=False, log_to=log_to
    )
    assert_same_as_metrics(tmp_path / "tb", again.history)  # the replaced run's epochs are superseded


def test_infer_and_the_estimator_log_their_own_metrics(data, tmp_path):
    model = AutoDecoder(SMALL, TC, progress=False, log_to=("tensorboard", tmp_path / "tb" / "fit"))
    assert model.get_params()["log_to"] == ("tensorboard", tmp_path / "tb" / "fit")
    assert clone(model).log_to == model.log_to
    model.fit(data)  # in memory: the event files are the only thing written
    assert_same_as_metrics(tmp_path / "tb" / "fit", model.history_)
    model.transform(data, epochs=2, log_to=("tensorboard", tmp_path / "tb" / "infer"))
    assert [h["epoch"] for h in model.inference_.history] == [0, 1, 2]
    assert_same_as_metrics(tmp_path / "tb" / "infer", model.inference_.history)
    inferred = infer(model.run_, data, epochs=1, progress=False, log_to=("tensorboard", tmp_path / "tb" / "i2"))
    assert_same_as_metrics(tmp_path / "tb" / "i2", inferred.history)


def test_nested_metrics_are_flattened_with_slashes(tmp_path):
    line = {
        "epoch": 4,
        "loss": 0.25,
        "vision": None,
        "note": "x",
        "ok": True,
        "parts": {"motor": 0.5, "deep": {"a": 2}, "label": "y"},
    }
    assert scalars(line) == {"loss": 0.25, "parts/motor": 0.5, "parts/deep/a": 2.0}
    logger = TensorBoardLogger(tmp_path / "tb")
    logger.log(line)
    logger.close()
    assert read_scalars(tmp_path / "tb") == {"loss": [(4, 0.25)], "parts/motor": [(4, 0.5)], "parts/deep/a": [(4, 2.0)]}


@pytest.mark.parametrize("log_to", ["tb", ("wandb", "tb"), ("tensorboard",), ("tensorboard", 3), ("tensorboard", "")])
def test_a_malformed_log_to_is_one_user_error(data, tmp_path, log_to):
    with pytest.raises(UserError, match=r"log_to must be a pair \('tensorboard', DIR\)"):
        fit(data, model_config=SMALL, train_config=TC, progress=False, log_to=log_to)


def test_the_cli_logs_train_and_infer(run_cli, data_file, tmp_path):
    res = run_cli(
        "train",
        data_file,
        "--epochs",
        "2",
        "--out",
        tmp_path / "run",
        "--log-to",
        "tensorboard",
        tmp_path / "tb" / "fit",
        *CLI_ARGS,
    )
    assert res.code == 0, res.err
    lines = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert_same_as_metrics(tmp_path / "tb" / "fit", lines)
    res = run_cli(
        "train",
        data_file,
        "--epochs",
        "3",
        "--out",
        tmp_path / "run",
        "--resume",
        "--log-to",
        "tensorboard",
        tmp_path / "tb" / "fit",
        *CLI_ARGS,
    )
    assert res.code == 0, res.err
    lines = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert [h["epoch"] for h in lines] == [0, 1, 2, 3]
    assert_same_as_metrics(tmp_path / "tb" / "fit", lines)
    res = run_cli(
        "infer",
        tmp_path / "run",
        data_file,
        "--epochs",
        "2",
        "--out",
        tmp_path / "inf",
        "--threads",
        "1",
        "--log-to",
        "tensorboard",
        tmp_path / "inf" / "tb",
    )  # inside its own run folder: fine
    assert res.code == 0, res.err
    lines = [json.loads(line) for line in (tmp_path / "inf" / "metrics.jsonl").read_text().splitlines()]
    assert_same_as_metrics(tmp_path / "inf" / "tb", lines)
    res = run_cli(
        "train", data_file, "--epochs", "1", "--out", tmp_path / "r2", "--log-to", "wandb", tmp_path / "w", *CLI_ARGS
    )
    assert_user_error(res, "--log-to", "wandb")


def test_the_cli_refuses_a_file_or_an_input_as_dir(run_cli, data_file, tmp_path):
    (tmp_path / "notes.txt").write_text("mine\n")
    res = run_cli(
        "train",
        data_file,
        "--epochs",
        "1",
        "--out",
        tmp_path / "run",
        "--log-to",
        "tensorboard",
        tmp_path / "notes.txt",
        *CLI_ARGS,
    )
    assert_user_error(res, "notes.txt", "--log-to tensorboard DIR is a file")
    assert (tmp_path / "notes.txt").read_text() == "mine\n" and not (tmp_path / "run").exists()
    res = run_cli(
        "train", data_file, "--epochs", "1", "--out", tmp_path / "run", "--log-to", "tensorboard", data_file, *CLI_ARGS
    )
    assert_user_error(res, "is a file")
    run = tmp_path / "parent"
    assert run_cli("train", data_file, "--epochs", "1", "--out", run, *CLI_ARGS).code == 0
    res = run_cli("infer", run, data_file, "--epochs", "1", "--out", tmp_path / "inf", "--log-to", "tensorboard", run)
    assert_user_error(res, "--log-to tensorboard DIR is the input")
    res = run_cli(
        "infer", run, data_file, "--epochs", "1", "--out", tmp_path / "inf", "--log-to", "tensorboard", run / "tb"
    )
    assert_user_error(res, "lies inside the input")
    assert not (tmp_path / "inf").exists() and not (run / "tb").exists()


def test_without_the_tensorboard_package_one_line_says_how_to_install(run_cli, data, data_file, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "tensorboard", None)  # `import tensorboard` now fails
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)
    with pytest.raises(UserError, match=r"pip install 'primspace\[tensorboard\]'"):
        fit(
            data,
            tmp_path / "run",
            model_config=SMALL,
            train_config=TC,
            progress=False,
            log_to=("tensorboard", tmp_path / "tb"),
        )
    assert not (tmp_path / "run").exists() and not (tmp_path / "tb").exists()  # refused before anything is written
    res = run_cli(
        "train",
        data_file,
        "--epochs",
        "1",
        "--out",
        tmp_path / "run",
        "--log-to",
        "tensorboard",
        tmp_path / "tb",
        *CLI_ARGS,
    )
    assert_user_error(res, "--log-to tensorboard needs the tensorboard package", "pip install 'primspace[tensorboard]'")
    assert not (tmp_path / "run").exists()
