"""The loss of a batch: the training targets on the device (:class:`DataTensors`), the
loss and its logged parts (:func:`batch_loss`), a step of the codes alone
(:func:`code_step`) and the precision the loss is computed in (:func:`autocast_for`).

The loss (paper, *Main Results*: ``L(θ, z_1..z_n) = Σ_i ‖d(θ, z_i) − o_i‖²``) is taken here
as ``w_m · mean((m̂ − m)²) + w_v · mean((ŝ − s)²)`` (see :mod:`primspace.train`), with
``TrainConfig.loss_reduction="sum"`` as the paper's sums over each sample's entries, or with
``"precision"`` as each modality's Gaussian negative log-likelihood per element,
``Σ_m ½ (e^{-s_m} · w_m · MSE_m + s_m)``, the log-variances ``s_m`` learned with θ
(:mod:`primspace.model.precision`; Kendall, Gal & Cipolla 2018). The paper, on vision
(*Summary and Discussion*): "The problem here is only a small portion of each perceived
image is relevant to motion, the rest is a background noise which will clutter random
projection." Weighed by its precision, a sense counts by
how well it is predicted, not by how many values it holds. For
data of different lengths (``MotionDataset.lengths``) each sample's loss is its mean (or
sum) over its own valid steps and the batch loss the mean over samples, so padding never
counts and a code's gradient does not depend on the other samples of its batch. The
training loop (:mod:`primspace.train.loop`) and inference from a part of each motion
(:mod:`primspace.predict`) step on it.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from primspace.data import JointScaler, MotionDataset
from primspace.data.steps import valid_steps
from primspace.model.latent import LatentTable
from primspace.train.config import TrainConfig
from primspace.train.observe import observation_masks
from primspace.utils.errors import UserError

__all__ = [
    "DataTensors",
    "batch_loss",
    "batch_frames",
    "precision_loss",
    "code_step",
    "code_variation",
    "autocast_for",
]


@dataclass
class DataTensors:
    """Training targets on the device: scaled motor (float32) and frames (uint8, converted per batch).

    ``mask`` marks the valid steps (padding); ``motor_mask`` and ``frame_mask``, when set,
    the observed ones of each modality (inference from a part of each motion,
    :mod:`primspace.train.observe`), padding included. The loss counts the entries of
    :meth:`motor_steps` / :meth:`frame_steps` only.
    """

    motor: torch.Tensor  # (N, T, J) float32, scaled to [-1, 1]
    images: torch.Tensor | None  # (N, T, H, W, 3) uint8
    mask: torch.Tensor | None = None  # (N, T) float32, 1 at valid steps; None: every step
    motor_mask: torch.Tensor | None = None  # (N, T) float32, 1 at observed valid steps; None: ``mask``
    frame_mask: torch.Tensor | None = None  # the same for the frames
    streamed: bool = False  # the frames are trained on but not held: each batch brings its own

    @classmethod
    def build(
        cls, data: MotionDataset, scaler: JointScaler, use_images: bool, device, observation=None, stream: bool = False
    ) -> DataTensors:
        """The tensors of ``data``; ``observation`` (:class:`~primspace.train.observe.Observation`)
        sets the observed masks (a modality observed at every valid step keeps ``mask``);
        ``stream``: the frames are left in the file (:mod:`primspace.train.streaming`)."""
        motor = torch.from_numpy(np.ascontiguousarray(scaler.transform(data.motor), dtype=np.float32)).to(device)
        images = None
        if use_images and not stream:
            loaded = data.load_images().images
            images = torch.from_numpy(np.ascontiguousarray(loaded)).to(device)
        mask = None
        if data.lengths is not None:
            mask = torch.from_numpy(valid_steps(data.lengths, data.length).astype(np.float32)).to(device)
        tensors = cls(motor, images, mask, streamed=use_images and stream)
        if observation is not None:
            valid = observation_masks(None, data)[0]
            motor_mask, frame_mask = (
                None if np.array_equal(m, valid) else torch.from_numpy(m.astype(np.float32)).to(device)
                for m in observation_masks(observation, data)
            )
            tensors.motor_mask, tensors.frame_mask = motor_mask, frame_mask
        return tensors

    @property
    def use_images(self) -> bool:
        """Whether the vision loss is trained (frames held here, or streamed per batch)."""
        return self.images is not None or self.streamed

    def motor_steps(self) -> torch.Tensor | None:
        """The motor entries the loss counts (N, T) (None: every one)."""
        return self.mask if self.motor_mask is None else self.motor_mask

    def frame_steps(self) -> torch.Tensor | None:
        """The frames the loss counts (N, T) (None: every one)."""
        return self.mask if self.frame_mask is None else self.frame_mask


def _rows(mask: torch.Tensor | None, idx: torch.Tensor) -> torch.Tensor | None:
    return None if mask is None else mask.index_select(0, idx)


def _sample_mean(per_sample: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    """The mean over samples, or with ``weights`` (B,) their weighted mean (a padded row weighs 0)."""
    if weights is None:
        return per_sample.mean()
    return (per_sample * weights).sum() / weights.sum()


def _mse(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Mean squared error; with ``mask`` (B, K) over the first two axes, each sample's mean
    over its valid entries, then the mean over samples (weighted by ``weights``)."""
    if mask is None and weights is None:
        return F.mse_loss(pred, target)
    per_step = (pred - target).pow(2).flatten(2).mean(dim=2)
    if mask is None:
        return _sample_mean(per_step.mean(dim=1), weights)
    return _sample_mean((per_step * mask).sum(dim=1) / mask.sum(dim=1).clamp_min(1.0), weights)


def _sse(
    pred: torch.Tensor,
    target: torch.Tensor,
    mask: torch.Tensor | None,
    scale: float = 1.0,
    weights: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The paper's summed squared error (*Main Results*, ``Σ_i ‖d(θ, z_i) − o_i‖²``) and,
    detached, the per-element mean squared error that :func:`_mse` computes.

    The first is the mean over samples of each sample's sum over its valid entries
    (``mask`` (B, K) over the first two axes), times ``scale``; the second is for logging,
    so that ``motor`` / ``vision`` read the same under both reductions.
    """
    per_step = (pred - target).pow(2).flatten(2).sum(dim=2)  # (B, K): one sum per step
    valid = per_step if mask is None else per_step * mask
    summed = _sample_mean(valid.sum(dim=1), weights)
    if scale != 1.0:
        summed = summed * scale
    with torch.no_grad():
        size = per_step.new_tensor(float(pred[0, 0].numel()))  # entries per step
        if mask is None and weights is None:
            mse = per_step.mean() / size
        elif mask is None:
            mse = _sample_mean(per_step.mean(dim=1), weights) / size
        else:
            mse = _sample_mean(valid.sum(dim=1) / size / mask.sum(dim=1).clamp_min(1.0), weights)
    return summed, mse


def batch_frames(images: torch.Tensor, idx: torch.Tensor, steps: torch.Tensor | None) -> torch.Tensor:
    """The stored frames of samples ``idx`` (B, T, H, W, 3) uint8, or at ``steps`` (B, K) only (B, K, H, W, 3)."""
    if steps is None:
        return images.index_select(0, idx)
    n, t = images.shape[:2]
    rows = (idx.unsqueeze(1) * t + steps).reshape(-1)
    return images.view(n * t, *images.shape[2:]).index_select(0, rows).view(*steps.shape, *images.shape[2:])


def batch_loss(
    model,
    z,
    idx,
    tensors: DataTensors,
    tc: TrainConfig,
    autocast,
    steps: torch.Tensor | None = None,
    frames: torch.Tensor | None = None,
    weights: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The loss of one batch and the detached ``[loss, motor, vision]`` means.

    ``loss`` is the objective of ``tc.loss_reduction`` (``"mean"``: ``w_m · motor + w_v ·
    vision``; ``"sum"``: the same weights on each sample's summed squared errors, then the
    mean over samples; ``"precision"``: :func:`precision_loss` of the per-element means,
    weighed by the decoder's learned precisions); ``motor`` and ``vision`` are per-element
    mean squared errors under each. ``steps`` (B, K): the vision loss on those frames of each sequence only
    (every frame when None); a sum over them is scaled by ``T / K``, an unbiased estimate
    of the sum over all frames (each step is drawn with probability ``K / T``). ``frames``:
    the batch's stored frames (:func:`batch_frames`), given when they are streamed;
    None: taken from ``tensors``. ``model`` may be wrapped (DDP). ``weights`` (B,): the
    means over samples become weighted means (a batch padded to a static size gives its
    padded rows weight 0, :mod:`primspace.train.captured`); None: every sample weighs 1.
    """
    summed = tc.loss_reduction == "sum"
    weighed = tc.loss_reduction == "precision"
    use_images = tensors.use_images
    config = getattr(model, "module", model).config  # DDP holds the decoder as .module
    mask, motor_mask = _rows(tensors.mask, idx), _rows(tensors.motor_steps(), idx)
    seen = None
    if use_images:
        seen = batch_frames(tensors.images, idx, steps) if frames is None else frames
    # with keypoints the decoder reads the real frames it draws (their keypoints: the targets)
    extra = {"seen": seen} if use_images and config.keypoints else {}
    with autocast:
        out = model(z, images=use_images, frame_steps=steps if use_images else None, **extra)
    if summed:
        motor_term, motor = _sse(out.motor.float(), tensors.motor.index_select(0, idx), motor_mask, weights=weights)
    else:
        motor = motor_term = _mse(out.motor.float(), tensors.motor.index_select(0, idx), motor_mask, weights)
    keypoint_term = None
    if use_images:
        frame_mask = _rows(tensors.frame_steps(), idx)
        if steps is not None and frame_mask is not None:
            frame_mask = frame_mask.gather(1, steps)
        target = seen.to(torch.float32).div_(255.0)
        scale = 1.0 if steps is None else tensors.motor.shape[1] / steps.shape[1]
        if summed:
            vision_term, vision = _sse(out.images.float(), target, frame_mask, scale, weights)
        else:
            vision = vision_term = _mse(out.images.float(), target, frame_mask, weights)
        if extra:
            keypoint_term = _keypoint_term(out, steps, frame_mask, weights, scale if summed else None)
    else:
        vision_term = None
        vision = torch.zeros((), device=motor.device)
    if weighed:
        loss = precision_loss(out.log_variances, motor_term, vision_term, tc, keypoint_term)
    else:
        loss = tc.motor_weight * motor_term
        if vision_term is not None:
            loss = loss + tc.vision_weight * vision_term
        if keypoint_term is not None:
            loss = loss + tc.vision_weight * keypoint_term
    if tc.code_smoothness > 0 and config.code_window is not None:
        loss = loss + tc.code_smoothness * code_variation(z, config, mask, weights)
    return loss, torch.stack([loss.detach(), motor.detach(), vision.detach()])


def _keypoint_term(out, steps, frame_mask, weights, scale: float | None) -> torch.Tensor:
    """The error of the predicted keypoints at the drawn steps against the encoder's keypoints
    of the real frames (a fixed target: the encoder learns from the drawing alone,
    :mod:`primspace.model.decoder`); its mean per coordinate, or with ``scale`` the sum of
    each sample's squared errors times ``scale`` (as the frames' under ``"sum"``)."""
    pred = out.keypoints.float()
    if steps is not None:
        pred = pred.gather(1, steps[:, :, None, None].expand(-1, -1, *pred.shape[2:]))
    target = out.seen_keypoints.detach().float()
    if scale is None:
        return _mse(pred, target, frame_mask, weights)
    return _sse(pred, target, frame_mask, scale, weights)[0]


def precision_loss(
    log_variances: torch.Tensor | None,
    motor: torch.Tensor,
    vision: torch.Tensor | None,
    tc: TrainConfig,
    keypoints: torch.Tensor | None = None,
) -> torch.Tensor:
    """``Σ_m ½ (e^{-s_m} · w_m · MSE_m + s_m)`` over the modalities trained (vision: when
    ``vision`` is given; the keypoints, weighed by ``w_v``: when ``keypoints`` is given)
    whose weight ``w_m`` is not 0 (a term at weight 0 would only drive its ``s_m`` down
    without end); ``log_variances``: ``s`` of motor, vision (and keypoints), the
    decoder's (:class:`~primspace.model.precision.ModalityPrecision`)."""
    if log_variances is None:
        raise UserError(
            "loss_reduction 'precision' needs a decoder with learned log-variances "
            "(a run fitted with loss_reduction 'precision')"
        )
    s = log_variances.float()
    terms = [(0, tc.motor_weight, motor), (1, tc.vision_weight, vision), (2, tc.vision_weight, keypoints)]
    parts = [0.5 * (torch.exp(-s[m]) * (w * mse) + s[m]) for m, w, mse in terms if mse is not None and w != 0]
    return torch.stack(parts).sum()


def code_step(
    model, table: LatentTable, idx: torch.Tensor, tensors: DataTensors, tc: TrainConfig, autocast, to_code=None
) -> torch.Tensor:
    """One Adam step of the rows ``idx`` of ``table`` with θ frozen, each row on the gradient of
    its own sample's loss (:func:`batch_loss` of the batch ``idx``; its mean over the batch
    scaled each row's gradient by 1/B, undone here). ``to_code``: maps the table's rows to
    the decoder's codes (e.g. coordinates in a subspace, ``mean + a @ basis``); None: the rows
    are the codes. Returns the detached ``[loss, motor, vision]`` means.
    """
    rows = table.batch(idx)
    loss, values = batch_loss(model, rows if to_code is None else to_code(rows), idx, tensors, tc, autocast)
    loss.backward()
    table.step(idx, rows.grad.mul_(idx.numel()))
    return values


def code_variation(
    z: torch.Tensor, config, mask: torch.Tensor | None, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Mean over samples of ``Σ_k ‖z_{k+1} − z_k‖₂`` over each sample's valid windows
    (a window is valid when its first step is; :class:`~primspace.train.TrainConfig`
    ``code_smoothness``)."""
    codes = z.view(z.shape[0], config.n_codes, config.latent_dim)
    steps = torch.sqrt(codes.diff(dim=1).pow(2).sum(dim=2) + 1e-12)  # (B, K-1); smooth at 0
    if mask is not None:
        steps = steps * mask[:, :: config.code_window][:, 1:]
    return _sample_mean(steps.sum(dim=1), weights)


def autocast_for(tc: TrainConfig, device: torch.device):
    if tc.amp and device.type == "cuda":
        return torch.autocast(device_type="cuda", dtype=torch.bfloat16)
    return contextlib.nullcontext()
