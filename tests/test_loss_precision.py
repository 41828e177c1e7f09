"""TrainConfig.loss_reduction="precision": each modality's per-element mean squared error
weighed by a learned precision (one log-variance per modality, part of the decoder's
parameters), and the reductions that stay as they were."""

from dataclasses import replace

import pytest
import torch

from primspace.train import TrainConfig, fit
from test_loss_reduction import IMAGE_MODEL
from test_train import SMALL, primitives

pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)

SHORT = TrainConfig(epochs=6, batch_size=4, threads=1)


@pytest.fixture(scope="module")
def motor_set():
    return primitives(3, seed=0, T=10, J=4)  # 9 sequences of 10 steps, 4 joints


@pytest.fixture(scope="module")
def image_set():
    return primitives(2, seed=1, T=6, J=3, images=True)  # 6 sequences of 6 steps, 8x8 frames


# ------------------------------------------------------------ the other reductions, pinned


def test_motor_only_mean_is_pinned(motor_set):
    """Same seed, same numbers: the default loss on motor data, as before the precision loss."""
    run = fit(motor_set, model_config=SMALL, train_config=SHORT, progress=False)
    last = run.history[-1]
    assert (last["loss"], last["motor"]) == pytest.approx((0.10001925296253628, 0.10001925296253628), rel=1e-6)
    assert float(abs(run.latents).sum()) == pytest.approx(73.30300903320312, rel=1e-6)


def test_mean_with_frames_is_pinned(image_set):
    run = fit(image_set, model_config=IMAGE_MODEL, train_config=replace(SHORT, vision_frames=2), progress=False)
    last = run.history[-1]
    assert (last["loss"], last["motor"], last["vision"]) == pytest.approx(
        (0.3601820071538289, 0.1170315792163213, 0.24315041800340018), rel=1e-6
    )
    assert float(abs(run.latents).sum()) == pytest.approx(28.082548141479492, rel=1e-6)
    assert not any("precision" in name for name in run.model.state_dict())
