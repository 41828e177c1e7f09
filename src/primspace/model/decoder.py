"""The generative model: an MTRNN decoder d(θ, z) with a motor head and an image head.

Paper, *Main Results: RNN Architecture*. Layers ``i = 1..L`` (1 = fastest, nearest the
outputs). With ``u`` the state of layer ``i+1`` (and ``u = p(z)`` for the top layer, an
"infinitely slow layer"), every step updates

.. math::

    h_t^{(i)} = (1 - 1/τ_i)\\, d_{t-1}^{(i)}
        + (1/τ_i) \\left(W^{(i)} d_{t-1}^{(i)} + U^{(i)} u + A^{(i)}(d_{t-1}^{(i)}, u) + b^{(i)}\\right),
    \\qquad d_t^{(i)} = \\mathrm{LN}(h_t^{(i)}),

where ``A(d, u)_k = Σ_jl A_kjl d_j u_l`` is the multiplicative (second-order) connection
and ``LN`` is layer normalisation. The initial state is ``d_0 = g(z)`` (eq. 1a). The motor
command ``m_t`` is an MLP of the fastest layer ``d_t^(1)``; the image ``s_t`` is a
deconvolution stack of ``d_t^(1)`` (eq. 1c-1d). All ``T`` steps' outputs are decoded in
one batched call of each head.

**A sequence of codes** (``ModelConfig.code_window = W``; the paper's *Summary and
Discussion*: "To model more complex behaviours composed of many consecutive primitives
... a sequence of such vectors is used"). A sample's codes are ``z_1..z_K``, one per
window of W steps; the top layer's input becomes ``u_t = p(z(t))`` with ``z(t)`` the
linear interpolation of the codes between window centres (constant before the first and
after the last), so the "infinitely slow layer" varies slowly; ``d_0 = g(z_1)``. The
layers below are unchanged. With one code (the default) this is the paper's model.

Choices the paper leaves open (documented in ``docs/model.md``):

* layers update top-down within a step, so ``u`` for layer ``i`` is ``d_t^(i+1)``, the
  higher layer's state at the same step (the paper: "u is equal to vector from higher
  layer d_t^(i+1)");
* ``τ`` defaults to 2 (fast) and 8 (slow);
* ``g`` is a linear map of ``z`` followed by each layer's LayerNorm, so ``d_0`` lives on the
  same scale as every later state; ``p`` is a two-layer tanh MLP;
* the image head ends in a sigmoid: frames are predicted in [0, 1] (targets are
  ``uint8 / 255``); every deconvolution is ``ConvTranspose2d(kernel 4, stride 2,
  padding 1)``, so each doubles the resolution and ``H`` and ``W`` must be multiples of
  ``2 ** len(image_channels)``.

With ``ModelConfig.learned_precision`` the decoder also holds the loss's learned
log-variance of each modality (:class:`~primspace.model.precision.ModalityPrecision`),
trained and saved with θ and returned with every output (``DecoderOutput.log_variances``).

With ``ModelConfig.keypoints = K`` (attention in the image path,
:mod:`primspace.model.keypoints`) a linear head of ``d_t^(1)`` also predicts K keypoints
``(x, y)`` per step (tanh, in [-1, 1]), and the image head draws each frame through them:
their Gaussian heatmaps enter every deconvolution as K more input channels, at its
resolution. The decoder also holds the encoder of real frames to K keypoints; given the
frames being drawn (``seen``), it returns their keypoints (the loss's targets for the
predicted ones) and draws through ``predicted + seen - seen.detach()``: the predicted
values, and the drawing's gradient reaches the encoder too (straight through), so the
encoder's keypoints are trained to carry what the frame needs.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from primspace.model.config import ModelConfig, check_image_size
from primspace.model.keypoints import KeypointEncoder, heatmaps
from primspace.model.precision import KEYPOINT_MODALITIES, MODALITIES, ModalityPrecision

__all__ = ["ModelConfig", "MTRNNDecoder", "MTRNNLayer", "ImageDecoder", "DecoderOutput", "code_interpolation"]


# ----------------------------------------------------------------------------- config


# ----------------------------------------------------------------------------- layers


class MTRNNLayer(nn.Module):
    """One MTRNN layer with a multiplicative connection to its input ``u``.

    Implements the paper's layer update (RNN Architecture)::

        h = (1 - 1/τ) d + (1/τ) (W d + U u + A(d, u) + b),   d' = LN(h)

    Parameters
    ----------
    size : int
        k, units of this layer.
    input_size : int
        l, size of ``u`` (the higher layer, or ``p(z)`` for the top layer).
    tau : float
        Time constant τ ≥ 1.

    Attributes
    ----------
    W : Parameter (k, k)
    U : Parameter (k, l)
    A : Parameter (k, k, l)
        ``A(d, u)_i = Σ_jl A[i, j, l] d_j u_l``.
    b : Parameter (k,)
    norm : LayerNorm(k)
    """

    def __init__(self, size: int, input_size: int, tau: float) -> None:
        super().__init__()
        self.size = int(size)
        self.input_size = int(input_size)
        self.tau = float(tau)
        self.W = nn.Parameter(torch.empty(size, size))
        self.U = nn.Parameter(torch.empty(size, input_size))
        self.A = nn.Parameter(torch.empty(size, size, input_size))
        self.b = nn.Parameter(torch.zeros(size))
        self.norm = nn.LayerNorm(size)
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """Fan-in uniform init: each of ``W d``, ``U u``, ``A(d, u)`` has O(1) variance."""
        k, l_ = self.size, self.input_size
        nn.init.uniform_(self.W, -1 / math.sqrt(k), 1 / math.sqrt(k))
        nn.init.uniform_(self.U, -1 / math.sqrt(l_), 1 / math.sqrt(l_))
        nn.init.uniform_(self.A, -1 / math.sqrt(k * l_), 1 / math.sqrt(k * l_))
        nn.init.zeros_(self.b)
        self.norm.reset_parameters()

    def step(self, d: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """One update ``d_{t-1} -> d_t``, written as the paper's formula (reference path).

        Parameters
        ----------
        d : Tensor (B, k)
            ``d_{t-1}`` of this layer.
        u : Tensor (B, l)
            The input: ``d_t`` of the layer above, or ``p(z)`` for the top layer.
        """
        bilinear = torch.einsum("kjl,bj,bl->bk", self.A, d, u)
        pre = d @ self.W.T + u @ self.U.T + bilinear + self.b
        return self.norm((1 - 1 / self.tau) * d + pre / self.tau)

    def run(self, d0: torch.Tensor, u: torch.Tensor, length: int) -> torch.Tensor:
        """Iterate :meth:`step` ``length`` times from ``d0``; return ``d_1..d_T`` (B, T, k).

        Equal to calling :meth:`step` in a loop, arranged for speed (few, batched
        operations per step; the recurrent loop is latency-bound on CPU and GPU alike).

        Parameters
        ----------
        d0 : Tensor (B, k)
            The initial state ``d_0``.
        u : Tensor (B, l) or (B, T, l)
            A constant input (the top layer's ``p(z)``) or one per step (the layer above's
            ``d_1..d_T``; layers only feed downwards, so it is known before this layer runs).
        length : int
            T.
        """
        if u.dim() == 2:
            return self._run_constant(d0, u, length)
        if u.shape[1] != length:
            raise ValueError(f"input sequence has {u.shape[1]} steps, expected {length}")
        return self._run_sequence(d0, u)

    def _norm(self, h: torch.Tensor) -> torch.Tensor:
        return F.layer_norm(h, (self.size,), self.norm.weight, self.norm.bias, self.norm.eps)

    def _run_constant(self, d0: torch.Tensor, u: torch.Tensor, length: int) -> torch.Tensor:
        # W d + U u + A(d, u) + b = d M + c (d a row vector), M = (W + Σ_l u_l A[:, :, l])ᵀ,
        # c = U u + b: fixed over time, so one batched vector-matrix product per step.
        k = self.size
        a_t = self.A.permute(2, 1, 0).reshape(self.input_size, k * k)  # [l, (j, i)] = A[i, j, l]
        M = (u @ a_t).view(-1, k, k) + self.W.T
        c = F.linear(u, self.U, self.b).unsqueeze(1)
        rate = 1.0 / self.tau
        d = d0.unsqueeze(1)  # (B, 1, k)
        out = []
        for _ in range(length):
            d = self._norm(
                torch.lerp(d, torch.baddbmm(c, d, M).to(d.dtype), rate)
            )  # autocast: bf16 product, fp32 state
            out.append(d)
        return torch.cat(out, dim=1)

    def _run_sequence(self, d0: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        # With u' = [u, 1] and A' = [A | W] (k, k, l+1): W d + A(d, u) = A'(d, u'), one
        # matrix product of the outer product d ⊗ u' per step; U u_t + b for all steps at once.
        b, length, l_ = u.shape
        k = self.size
        c = F.linear(u, self.U, self.b).unbind(1)
        u1 = torch.cat([u, u.new_ones(b, length, 1)], dim=2).unbind(1)
        packed = torch.cat([self.A, self.W.unsqueeze(2)], dim=2).reshape(k, k * (l_ + 1)).T
        rate = 1.0 / self.tau
        d = d0
        out = []
        for u_t, c_t in zip(u1, c):
            outer = (d.unsqueeze(2) * u_t.unsqueeze(1)).view(b, -1)  # d_j u'_l
            d = self._norm(torch.lerp(d, torch.addmm(c_t, outer, packed).to(d.dtype), rate))
            out.append(d)
        return torch.stack(out, dim=1)


class ImageDecoder(nn.Module):
    """The sensory head ``s_t = s(d_t^(1))``: a linear map to a small feature map, then
    deconvolutions (kernel 4, stride 2, padding 1, ReLU between) up to ``H x W x 3``, and a
    sigmoid (pixels in [0, 1]).

    Parameters
    ----------
    in_features : int
        Size of the fastest layer.
    image_size : (H, W)
        Multiples of ``2 ** len(channels)``.
    channels : tuple of int
        Input channels of each deconvolution (the last one outputs 3).
    keypoints : int
        K > 0: :meth:`forward` takes K keypoints per frame and every deconvolution also
        reads their heatmaps (:func:`~primspace.model.keypoints.heatmaps`) at its input's
        resolution, K more channels.
    """

    #: Compute the deconvolutions in NHWC (False under ``torch.func.vmap``, which cannot
    #: query that layout: :mod:`primspace.train.packed`).
    channels_last = True

    def __init__(
        self, in_features: int, image_size: tuple[int, int], channels: tuple[int, ...], keypoints: int = 0
    ) -> None:
        super().__init__()
        check_image_size(image_size, channels)
        self.image_size = tuple(image_size)
        self.channels = tuple(channels)
        self.keypoints = int(keypoints)
        factor = 2 ** len(channels)
        self.base = (image_size[0] // factor, image_size[1] // factor)
        self.fc = nn.Linear(in_features, channels[0] * self.base[0] * self.base[1])
        outs = list(channels[1:]) + [3]
        self.deconvs = nn.ModuleList(
            nn.ConvTranspose2d(c_in + self.keypoints, c_out, kernel_size=4, stride=2, padding=1)
            for c_in, c_out in zip(channels, outs)
        )
        # NHWC is 1.6-2x faster for these layers on the CPU (oneDNN) and suits cuDNN too.
        self.deconvs.to(memory_format=torch.channels_last)

    def forward(self, x: torch.Tensor, points: torch.Tensor | None = None) -> torch.Tensor:
        """``(N, in_features)`` -> ``(N, H, W, 3)`` in [0, 1]; ``points`` (N, K, 2): the
        keypoints each frame is drawn through (needed when the head has keypoints)."""
        y = F.relu(self.fc(x)).view(-1, self.channels[0], *self.base)
        if self.channels_last:
            y = y.contiguous(memory_format=torch.channels_last)
        last = len(self.deconvs) - 1
        for i, deconv in enumerate(self.deconvs):
            if self.keypoints:
                maps = heatmaps(points.float(), y.shape[2], y.shape[3]).to(y.dtype)
                y = torch.cat([y, maps], dim=1)
                if self.channels_last:
                    y = y.contiguous(memory_format=torch.channels_last)
            y = deconv(y)
            if i < last:
                y = F.relu(y)
        return torch.sigmoid(y).permute(0, 2, 3, 1)

    def macs_per_frame(self) -> int:
        """Multiply-accumulates of one frame's forward pass (linear + deconvolutions)."""
        total = self.fc.in_features * self.fc.out_features
        h, w = self.base
        for deconv in self.deconvs:
            h, w = 2 * h, 2 * w
            # each output pixel of a stride-2, kernel-4 deconvolution receives 2x2 taps per input channel
            total += h * w * deconv.out_channels * deconv.in_channels * 4
        return total  # the heatmaps (elementwise) are not counted


class DecoderOutput(NamedTuple):
    """What :class:`MTRNNDecoder` produces for a batch of codes."""

    motor: torch.Tensor  # (B, T, J), scaled joint values
    images: torch.Tensor | None  # (B, T, H, W, 3) in [0, 1], or None
    fast_states: torch.Tensor  # (B, T, k_1), d_1..d_T of the fastest layer
    log_variances: torch.Tensor | None = None  # (M,) s of each modality (ModelConfig.learned_precision)
    keypoints: torch.Tensor | None = None  # (B, T, K, 2) predicted (x, y) in [-1, 1] (ModelConfig.keypoints)
    seen_keypoints: torch.Tensor | None = None  # (B, F, K, 2) the encoder's, of the frames given as ``seen``


# ---------------------------------------------------------------------------- decoder


def code_interpolation(length: int, window: int) -> torch.Tensor:
    """``Φ`` (T, K): ``z(t) = Σ_k Φ[t, k] z_k``, linear between window centres.

    Window ``k`` covers steps ``[kW, (k+1)W)``; its code sits at the centre
    ``kW + (W - 1) / 2``. Steps before the first centre take ``z_1``, after the last
    ``z_K``. Each row sums to 1 and has at most two non-zero entries.
    """
    k = -(-length // window)
    if k == 1:
        return torch.ones(length, 1)
    centres = torch.arange(k, dtype=torch.float64) * window + (window - 1) / 2
    t = torch.arange(length, dtype=torch.float64).clamp(centres[0], centres[-1])
    right = torch.searchsorted(centres, t, right=True).clamp(1, k - 1)
    phi = torch.zeros(length, k, dtype=torch.float64)
    left = right - 1
    w = ((t - centres[left]) / window).clamp(0.0, 1.0)
    rows = torch.arange(length)
    phi[rows, left] = 1.0 - w
    phi[rows, right] += w
    return phi.float()


class MTRNNDecoder(nn.Module):
    """The decoder ``d(θ, z) = (m_{1:T}, s_{1:T})`` of the paper (eq. 1a-1d).

    Parameters
    ----------
    config : ModelConfig
        Validated sizes; ``n_joints`` and ``length`` must be set.

    Examples
    --------
    >>> cfg = ModelConfig(latent_dim=4, n_joints=3, length=10)
    >>> out = MTRNNDecoder(cfg)(torch.zeros(2, 4))
    >>> tuple(out.motor.shape), out.images
    ((2, 10, 3), None)
    """

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        config.validate()
        self.config = config
        sizes = config.layer_sizes
        inputs = list(sizes[1:]) + [config.u_size]
        self.p = nn.Sequential(
            nn.Linear(config.latent_dim, config.p_hidden),
            nn.Tanh(),
            nn.Linear(config.p_hidden, config.u_size),
            nn.Tanh(),
        )
        self.g = nn.Linear(config.latent_dim, sum(sizes))
        self.layers = nn.ModuleList(MTRNNLayer(k, l_, tau) for k, l_, tau in zip(sizes, inputs, config.taus))
        self.motor_head = nn.Sequential(
            nn.Linear(sizes[0], config.motor_hidden), nn.Tanh(), nn.Linear(config.motor_hidden, config.n_joints)
        )
        self.image_head = (
            ImageDecoder(sizes[0], config.image_size, config.image_channels, config.keypoints)
            if config.has_images
            else None
        )
        # last: the other parameters keep their order and their seeded values
        modalities = KEYPOINT_MODALITIES if config.keypoints else MODALITIES
        self.precision = ModalityPrecision(modalities) if config.learned_precision else None
        self.keypoint_head = nn.Linear(sizes[0], 2 * config.keypoints) if config.keypoints else None
        self.keypoint_encoder = KeypointEncoder(config.keypoints) if config.keypoints else None
        if config.code_window is not None:  # derived from the config: not saved with the weights
            self.register_buffer(
                "interpolation", code_interpolation(config.length, config.code_window), persistent=False
            )

    def initial_states(self, z: torch.Tensor) -> list[torch.Tensor]:
        """``d_0 = g(z)``: one state per layer, each layer-normalised."""
        parts = self.g(z).split(list(self.config.layer_sizes), dim=1)
        return [layer.norm(part) for layer, part in zip(self.layers, parts)]

    def dynamics(self, z: torch.Tensor) -> torch.Tensor:
        """Run the layers for T steps; return the fastest layer's states ``(B, T, k_1)``.

        Information flows only downwards (layer ``i`` reads layer ``i+1`` at the same
        step), so the layers run one after the other, top first, each over all T steps
        (:meth:`MTRNNLayer.run`).
        """
        if self.config.code_window is None:
            states0, u = self.initial_states(z), self.p(z)
        else:  # (B, K*q) -> (B, K, q); u_t = p(z(t)), d_0 = g(z_1)
            codes = z.view(z.shape[0], self.config.n_codes, self.config.latent_dim)
            states0 = self.initial_states(codes[:, 0])
            u = self.p(torch.einsum("tk,bkq->btq", self.interpolation.to(codes.dtype), codes))
        for i in range(len(self.layers) - 1, -1, -1):
            u = self.layers[i].run(states0[i], u, self.config.length)
        return u

    def forward(
        self,
        z: torch.Tensor,
        *,
        images: bool = True,
        frame_steps: torch.Tensor | None = None,
        seen: torch.Tensor | None = None,
    ) -> DecoderOutput:
        """Decode codes ``z`` (B, q) into motor (and image) sequences.

        Parameters
        ----------
        z : Tensor (B, q), or (B, K*q) with a code window (K codes per sample, in order)
        images : bool
            Run the image head (if the model has one). False skips it (motor only).
        frame_steps : LongTensor (B, K), optional
            Decode frames only at these steps of each sequence (0-based, in the order
            given): ``images`` is then ``(B, K, H, W, 3)``. The image head dominates the
            cost, so a few steps cost a fraction of all T (the vision loss on K drawn
            frames, :class:`~primspace.train.TrainConfig` ``vision_frames``).
        seen : Tensor (B, T or K, H, W, 3), optional
            With keypoints: the real frames of the steps drawn; their keypoints are
            returned (``seen_keypoints``) and the frames are drawn straight through them
            (module docstring). Ignored without keypoints.
        """
        return self.decode(self.dynamics(z), images=images, frame_steps=frame_steps, seen=seen)

    def decode(
        self,
        fast: torch.Tensor,
        *,
        images: bool = True,
        frame_steps: torch.Tensor | None = None,
        seen: torch.Tensor | None = None,
    ) -> DecoderOutput:
        """The heads on the fastest layer's states ``fast`` (B, T, k_1) (:meth:`dynamics`);
        ``images``, ``frame_steps`` and ``seen`` as in :meth:`forward`."""
        b, t, k = fast.shape
        flat = fast.reshape(b * t, k)
        motor = self.motor_head(flat).view(b, t, -1)
        points = seen_points = None
        if self.keypoint_head is not None:
            points = torch.tanh(self.keypoint_head(flat)).view(b, t, self.config.keypoints, 2)
        frames = None
        if images and self.image_head is not None:
            h, w = self.config.image_size
            rows = None
            if frame_steps is not None:
                rows = (frame_steps + torch.arange(b, device=flat.device).unsqueeze(1) * t).reshape(-1)
                flat = flat.index_select(0, rows)
            draw = None
            if points is not None:
                draw = points.view(b * t, -1, 2)
                draw = draw if rows is None else draw.index_select(0, rows)
                if seen is not None:
                    seen_points = self.keypoint_encoder(seen)
                    flat_seen = seen_points.reshape(draw.shape)
                    draw = draw + (flat_seen - flat_seen.detach())
            n_frames = t if frame_steps is None else frame_steps.shape[1]
            frames = self.image_head(flat, draw).view(b, n_frames, h, w, 3)
        log_variances = None if self.precision is None else self.precision()
        return DecoderOutput(motor, frames, fast, log_variances, points, seen_points)

    # ------------------------------------------------------------------ accounting
    def macs_per_sample(self, *, images: bool = True) -> int:
        """Multiply-accumulates of one sequence's forward pass (matmuls and convolutions).

        Counted analytically as executed: ``p``, ``g``, the top layer's ``M = W + A u``
        and ``c = U u + b`` once; per step ``k²`` for the top layer and ``k² (l + 1) + k l``
        for every other layer (``A'(d, u')`` and ``U u_t``), the motor head and, if
        present, the image head. Elementwise work (LayerNorm, activations, outer
        products, the loss) is not counted.
        """
        cfg = self.config
        q, sizes = cfg.latent_dim, cfg.layer_sizes
        macs = q * cfg.p_hidden + cfg.p_hidden * cfg.u_size + q * sum(sizes)
        k_top = sizes[-1]
        if cfg.code_window is None:
            macs += k_top * k_top * cfg.u_size + k_top * cfg.u_size  # the top layer's M and c
            per_step = k_top * k_top
        else:  # p(z(t)) and the top layer's A'(d, u'_t), U u_t at every step
            per_step = cfg.n_codes * q + q * cfg.p_hidden + cfg.p_hidden * cfg.u_size
            per_step += k_top * k_top * (cfg.u_size + 1) + k_top * cfg.u_size
        for k, l_ in zip(sizes[:-1], sizes[1:]):
            per_step += k * k * (l_ + 1) + k * l_
        per_step += sizes[0] * cfg.motor_hidden + cfg.motor_hidden * cfg.n_joints
        if images and self.image_head is not None:
            per_step += self.image_head.macs_per_frame()
        if self.keypoint_head is not None:
            per_step += sizes[0] * 2 * cfg.keypoints
        return macs + cfg.length * per_step
