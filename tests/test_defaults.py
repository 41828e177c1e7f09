"""The defaults that give the best result, the same from the command line and from Python
(issue 37, section 2): the learning-rate decay, the segmentation method, the threads."""

from __future__ import annotations

import numpy as np
import pytest
import typer.main


def _params(command: str) -> dict:
    from primspace.cli import app

    found = typer.main.get_command(app)
    for name in command.split():
        found = found.commands[name]
    return {p.name: p for p in found.params}


def _default(command: str, name: str):
    value = _params(command)[name].default
    return getattr(value, "value", value)


def test_learning_rate_decay_is_the_same_from_the_cli_python_and_the_presets():
    from primspace.experiments.presets import PRESETS, default_train
    from primspace.train import TrainConfig

    python = TrainConfig().final_lr_fraction
    assert python == 0.1 < 1.0  # decays (a constant rate ended 10x worse on the paper preset)
    assert _default("train", "final_lr_fraction") == python
    assert default_train().final_lr_fraction == python
    assert {name: p.train.final_lr_fraction for name, p in PRESETS.items()} == {name: python for name in PRESETS}


def test_segment_defaults_to_synthesis_as_the_segmentation_package_says():
    """F1 0.76 against 0.18 for the window codes (issue 37); a run trained with a code window
    can only be segmented by its windows, so that is its default."""
    from types import SimpleNamespace

    from primspace import segmentation
    from primspace.cli.segment import SegmentMethod, segment_method

    def run(window):
        return SimpleNamespace(model_config=SimpleNamespace(code_window=window))

    assert segmentation.DEFAULT_METHOD == "synthesis"
    assert _default("segment", "method") is None  # chosen by the run:
    assert segment_method(None, run(None)).value == segmentation.DEFAULT_METHOD
    assert segment_method(None, run(8)) is SegmentMethod.windows
    assert segment_method(SegmentMethod.surprise, run(None)) is SegmentMethod.surprise
    assert {m.value for m in _params("segment")["method"].type_descriptor.annotation} == set(segmentation.METHODS)


@pytest.mark.parametrize("command", ["train", "infer", "reconstruct", "animate", "segment"])
def test_threads_default_is_the_train_configs_on_every_command_where_torch_runs(command):
    from primspace.train import TrainConfig

    assert TrainConfig().threads == 1
    assert _default(command, "threads") == TrainConfig().threads


#: The experiments run torch in their runs: --threads and --device go to the preset's TrainConfig.
_GRIDS = ["demo"] + [
    f"experiment {name}" for name in ("intra", "clustering", "success", "inter", "composite", "tune", "predict", "all")
]


@pytest.mark.parametrize("command", ["train", "infer", "reconstruct", "animate", *_GRIDS])
def test_device_is_an_option_where_a_model_runs(command):
    assert "device" in _params(command)


@pytest.mark.parametrize("command", _GRIDS)
def test_threads_of_an_experiment_default_to_the_presets_one_per_run(command):
    from primspace.experiments.presets import PRESETS

    assert _default(command, "threads") is None and _default(command, "device") is None  # the preset's:
    assert {p.train.threads for p in PRESETS.values()} == {1}
    changed = PRESETS["demo"].with_overrides(threads=2, device="cpu").train
    assert (changed.threads, changed.device) == (2, "cpu")


def _blas_threads() -> int:
    from threadpoolctl import threadpool_info

    return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")


@pytest.mark.parametrize("kind", ["fit", "infer"])
def test_threads_from_python_limit_torch_and_blas_while_training_and_are_put_back(monkeypatch, kind):
    """TrainConfig(threads=1) from Python: torch and BLAS run one thread inside fit/infer,
    and the process's settings are as they were afterwards (no process-wide change)."""
    import torch
    from threadpoolctl import threadpool_limits

    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, fit, infer
    from primspace.train.loop import Session

    rng = np.random.default_rng(0)
    ds = MotionDataset(motor=rng.standard_normal((6, 12, 3)).astype(np.float32))
    seen = []
    original = Session._train_epoch

    def spy(self):
        seen.append((torch.get_num_threads(), _blas_threads()))
        return original(self)

    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        with threadpool_limits(limits=2, user_api="blas"):
            outside = (torch.get_num_threads(), _blas_threads())
            tc = TrainConfig(epochs=2, batch_size=3, threads=1)
            run = fit(ds, model_config=ModelConfig(latent_dim=2, layer_sizes=(4, 3)), train_config=tc, progress=False)
            monkeypatch.setattr(Session, "_train_epoch", spy)
            if kind == "fit":
                fit(ds, model_config=ModelConfig(latent_dim=2, layer_sizes=(4, 3)), train_config=tc, progress=False)
            else:
                infer(run, ds, epochs=2, threads=1, progress=False)
            after = (torch.get_num_threads(), _blas_threads())
    finally:
        torch.set_num_threads(before)
    assert seen and set(seen) == {(1, 1)}
    assert outside == after == (2, 2)
