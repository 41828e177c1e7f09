"""Attention in the image path (ModelConfig.keypoints): the spatial softmax and its inverse,
the decoder drawing frames through predicted keypoints, the loss's keypoint term, and the
keypoints carried by training, checkpoints, inference and the command line."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from primspace.data import JointScaler
from primspace.model.config import ModelConfig
from primspace.model.decoder import MTRNNDecoder
from primspace.model.keypoints import KeypointEncoder, heatmaps, pixel_grid, spatial_softmax
from primspace.model.precision import KEYPOINT_MODALITIES
from primspace.plots import plot_reconstruction
from primspace.train import TrainConfig, decode_keypoints, fit, infer, load_run
from primspace.train.loss import DataTensors, batch_loss
from primspace.train.packed import fit_packed
from primspace.utils.errors import UserError
from test_loss_reduction import IMAGE_MODEL, SMALL_ARGS

pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)

KP_MODEL = replace(IMAGE_MODEL, keypoints=3)
SHORT = TrainConfig(epochs=3, batch_size=4, threads=1, vision_frames=2)


# ------------------------------------------------------------------ the spatial softmax


def _blob_frame(h: int, w: int, row: float, col: float, radius: float = 1.5) -> np.ndarray:
    """A dark (h, w, 3) uint8 frame with one bright disc centred at pixel (row, col)."""
    r, c = np.mgrid[:h, :w]
    disc = (r - row) ** 2 + (c - col) ** 2 <= radius**2
    frame = np.full((h, w, 3), 20, np.uint8)
    frame[disc] = 250
    return frame


@pytest.mark.parametrize("row, col", [(5, 20), (17, 6), (12, 12)])
def test_spatial_softmax_finds_a_bright_blob(row, col):
    frame = _blob_frame(24, 32, row, col)
    brightness = torch.from_numpy(frame).float().mean(dim=2) / 255.0
    (x, y) = spatial_softmax(40.0 * brightness[None, None])[0, 0].tolist()
    xs, ys = pixel_grid(24, 32, dtype=torch.float64)
    assert x == pytest.approx(xs[col].item(), abs=0.02) and y == pytest.approx(ys[row].item(), abs=0.02)


def test_a_uniform_map_points_at_the_centre_and_coordinates_span_the_frame():
    assert spatial_softmax(torch.zeros(2, 3, 6, 8)).abs().max().item() < 1e-6
    peaked = torch.full((1, 2, 6, 8), -1e4)
    peaked[0, 0, 0, 0] = peaked[0, 1, 5, 7] = 0.0  # top left, bottom right
    points = spatial_softmax(peaked)[0]
    assert points[0].tolist() == pytest.approx([-1 + 1 / 8, -1 + 1 / 6])
    assert points[1].tolist() == pytest.approx([1 - 1 / 8, 1 - 1 / 6])


def test_heatmaps_peak_at_the_keypoint():
    xs, ys = pixel_grid(12, 16)
    points = torch.stack([torch.stack([xs[3], ys[9]]), torch.stack([xs[14], ys[1]])])[None]  # (1, 2, 2)
    maps = heatmaps(points, 12, 16)
    assert maps.shape == (1, 2, 12, 16)
    for k, (r, c) in enumerate([(9, 3), (1, 14)]):
        flat = int(maps[0, k].argmax())
        assert divmod(flat, 16) == (r, c) and maps[0, k, r, c].item() == pytest.approx(1.0)
    assert maps[0, 0, 0, 15].item() < 1e-6  # far away: nothing


def test_encoder_shapes_range_and_gradients():
    torch.manual_seed(0)
    enc = KeypointEncoder(4)
    frames = torch.randint(0, 256, (2, 3, 16, 24, 3), dtype=torch.uint8)
    points = enc(frames)
    assert points.shape == (2, 3, 4, 2) and points.abs().max().item() < 1.0
    assert torch.allclose(enc(frames.float() / 255.0), points, atol=1e-6)
    points.sum().backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in enc.parameters())
    assert enc.macs_per_frame((16, 24)) == 8 * 12 * (16 * 3 * 16 + 4 * 16 * 9)


# ------------------------------------------------------------------------ the decoder


def _decoder(data, keypoints: int = 3, **kw):
    torch.manual_seed(0)
    return MTRNNDecoder(replace(KP_MODEL, keypoints=keypoints, **kw).fitted_to(data, images=True))


def test_decoder_predicts_keypoints_and_draws_through_them(loss_image_set):
    model = _decoder(loss_image_set)
    z = torch.randn(2, 5)
    out = model(z)
    assert out.keypoints.shape == (2, 6, 3, 2) and out.keypoints.abs().max() < 1
    assert out.images.shape == (2, 6, 8, 8, 3) and out.seen_keypoints is None
    with torch.no_grad():  # other keypoints, other frames: the head reads them
        moved = model.image_head(out.fast_states[0], -out.keypoints[0])
    assert not torch.allclose(moved, out.images[0], atol=1e-4)
    assert [d.in_channels for d in model.image_head.deconvs] == [8 + 3, 4 + 3]


def test_drawing_reaches_the_encoder_straight_through(loss_image_set):
    model = _decoder(loss_image_set)
    z = torch.randn(2, 5)
    steps = torch.tensor([[0, 4], [2, 5]])
    seen = torch.from_numpy(np.asarray(loss_image_set.images[:2]))[:, [0, 4]]
    out = model(z, frame_steps=steps, seen=seen)
    assert out.seen_keypoints.shape == (2, 2, 3, 2) and out.images.shape == (2, 2, 8, 8, 3)
    plain = model(z, frame_steps=steps)  # the same frames: drawn through the predicted values
    assert torch.allclose(out.images, plain.images, atol=1e-6)
    out.images.sum().backward()
    encoder = model.keypoint_encoder.conv1.weight.grad
    assert encoder is not None and encoder.abs().sum() > 0
    assert model.keypoint_head.weight.grad.abs().sum() > 0


def test_without_keypoints_nothing_is_added(loss_image_set):
    model = MTRNNDecoder(IMAGE_MODEL.fitted_to(loss_image_set, images=True))
    out = model(torch.zeros(1, 5))
    assert out.keypoints is None and model.keypoint_encoder is None
    assert not any("keypoint" in name for name in model.state_dict())
    old = {k: v for k, v in KP_MODEL.fitted_to(loss_image_set).to_dict().items() if k != "keypoints"}
    assert ModelConfig.from_dict(old).keypoints == 0  # a config written before the field loads


def test_keypoints_need_frames():
    with pytest.raises(UserError, match="needs an image head"):
        ModelConfig(n_joints=2, length=4, keypoints=2).validate()
    with pytest.raises(UserError, match="whole number"):
        ModelConfig(n_joints=2, length=4, image_size=(8, 8), image_channels=(4,), keypoints=-1).validate()


# --------------------------------------------------------------------------- the loss


def test_keypoint_term_by_hand(loss_image_set):
    """ "mean": w_m motor + w_v (vision + keypoints); "precision": a third modality; the
    keypoints' target is the encoder's keypoints of the real frame, held fixed."""
    model = _decoder(loss_image_set, learned_precision=True)
    with torch.no_grad():
        model.precision.raw.copy_(torch.tensor([-0.1, 0.2, -0.3]))
    tensors = DataTensors.build(loss_image_set, JointScaler().fit(loss_image_set.motor), True, torch.device("cpu"))
    idx, z = torch.tensor([0, 3, 5]), torch.randn(3, 5)
    with torch.no_grad():
        out = model(z, seen=tensors.images[idx])
        motor = F.mse_loss(out.motor, tensors.motor[idx]).item()
        vision = F.mse_loss(out.images, tensors.images[idx].float() / 255.0).item()
        kp = F.mse_loss(out.keypoints, model.keypoint_encoder(tensors.images[idx])).item()
        tc = TrainConfig(motor_weight=2.0, vision_weight=0.5)
        loss, parts = batch_loss(model, z, idx, tensors, tc, torch.no_grad())
        assert loss.item() == pytest.approx(2.0 * motor + 0.5 * (vision + kp), rel=1e-5)
        assert parts.tolist()[1:] == pytest.approx([motor, vision], rel=1e-5)
        loss, _ = batch_loss(model, z, idx, tensors, replace(tc, loss_reduction="precision"), torch.no_grad())
    s = [r * 10.0 for r in (-0.1, 0.2, -0.3)]
    by_hand = sum(0.5 * (math.exp(-s_) * w * e + s_) for s_, w, e in zip(s, (2.0, 0.5, 0.5), (motor, vision, kp)))
    assert loss.item() == pytest.approx(by_hand, rel=1e-5)
    assert tuple(model.precision.summary()) == KEYPOINT_MODALITIES
    model.zero_grad()
    loss, _ = batch_loss(model, z, idx, tensors, TrainConfig(vision_weight=0.0), torch.no_grad())
    assert loss.item() == pytest.approx(motor, rel=1e-5)  # weight 0: no frames, no keypoints


# ---------------------------------------------------------------------------- training


def test_fit_resume_load_and_frozen_inference(loss_image_set, tmp_path):
    tc = replace(SHORT, epochs=4, final_lr_fraction=1.0)
    whole = fit(loss_image_set, tmp_path / "whole", model_config=KP_MODEL, train_config=tc, progress=False)
    fit(loss_image_set, tmp_path / "part", model_config=KP_MODEL, train_config=replace(tc, epochs=2), progress=False)
    resumed = fit(
        loss_image_set, tmp_path / "part", model_config=KP_MODEL, train_config=tc, resume=True, progress=False
    )
    start = MTRNNDecoder(KP_MODEL.fitted_to(loss_image_set))
    assert json.loads((tmp_path / "whole" / "config.json").read_text())["model"]["keypoints"] == 3
    encoder = whole.model.keypoint_encoder.conv1.weight.detach().clone()
    assert not torch.equal(encoder, start.keypoint_encoder.conv1.weight)  # it trained
    assert torch.allclose(resumed.model.keypoint_encoder.conv1.weight, encoder, atol=1e-6, rtol=0)
    assert np.allclose(resumed.latents, whole.latents, atol=1e-5)
    loaded = load_run(tmp_path / "whole")
    assert torch.equal(loaded.model.keypoint_encoder.conv1.weight, encoder)
    inferred = infer(loaded, loss_image_set, epochs=2, progress=False)
    assert torch.equal(inferred.model.keypoint_encoder.conv1.weight, encoder)  # frozen with θ
    assert torch.equal(inferred.model.keypoint_head.weight, loaded.model.keypoint_head.weight)
    assert not np.allclose(inferred.latents, 0)


def test_packed_and_captured_steps_carry_the_keypoints(loss_image_set):
    jobs = [
        dict(dataset=loss_image_set, model_config=KP_MODEL, train_config=replace(SHORT, seed=s), init="projection")
        for s in (0, 1)
    ]
    alone = [fit(**job, progress=False) for job in jobs]
    captured = fit(**(jobs[0] | {"train_config": replace(SHORT, step="captured")}), progress=False)
    for a, p in zip([alone[0], *alone], [captured, *fit_packed(jobs, progress=False)]):
        assert torch.allclose(a.model.keypoint_head.weight, p.model.keypoint_head.weight, atol=1e-5, rtol=0)
        assert np.abs(a.latents - p.latents).max() < 1e-5


# ----------------------------------------------------------------- the keypoints as data


def test_decoded_keypoints_and_their_dots(loss_image_set):
    run = fit(loss_image_set, model_config=KP_MODEL, train_config=replace(SHORT, epochs=1), progress=False)
    points = decode_keypoints(run, batch_size=4)
    assert points.shape == (6, 6, 3, 2) and points.dtype == np.float32
    with torch.no_grad():
        expected = run.model(torch.from_numpy(run.latents), images=False).keypoints.numpy()
    assert np.allclose(points, expected, atol=1e-6)
    plain = fit(loss_image_set, model_config=IMAGE_MODEL, train_config=replace(SHORT, epochs=1), progress=False)
    assert decode_keypoints(plain) is None
    frames = np.asarray(loss_image_set.images[0])
    motor = np.asarray(loss_image_set.motor[0])
    drawn = plot_reconstruction(motor, motor, images=frames, generated_images=frames, generated_keypoints=points[0])
    dots = [c for ax in drawn.axes for c in ax.collections]
    assert len(dots) == 6 and all(len(c.get_offsets()) == 3 for c in dots)  # 6 frames shown, 3 dots each
    assert not [c for ax in plot_reconstruction(motor, motor, images=frames).axes for c in ax.collections]


def test_cli_keypoints(run_cli, loss_image_set, tmp_path):
    data = tmp_path / "d.h5"
    loss_image_set.save(data)
    res = run_cli("train", data, "--out", tmp_path / "kp", "--keypoints", "2", "--image-channels", "8,4", *SMALL_ARGS)
    assert res.code == 0, res.err
    assert load_run(tmp_path / "kp").model_config.keypoints == 2
    res = run_cli("reconstruct", tmp_path / "kp", "--sample", "0", "--out", tmp_path / "kp.png")
    assert res.code == 0 and (tmp_path / "kp.png").stat().st_size > 0, res.err
    res = run_cli("train", data, "--out", tmp_path / "no", "--keypoints", "2", "--no-images", *SMALL_ARGS)
    assert res.code == 2 and "image head" in res.err and "Traceback" not in res.err
