"""Attention in the image path: frames to K keypoints and keypoints back to heatmaps.

The paper (*Summary and Discussion*): "only a small portion of each perceived image is
relevant to motion, the rest is a background noise ... Some attention mechanism will
potentially alleviate the problem." With ``ModelConfig.keypoints = K > 0``:

* :class:`KeypointEncoder` reads a frame into K points through a *spatial softmax*
  (Levine et al. 2016; Finn et al. 2016): a small CNN makes K feature maps, each map's
  softmax over its pixels is a distribution, and its expected position ``(x, y)`` is the
  keypoint. Nothing but the pixels is given (no colour, label or block position).
* :func:`heatmaps` is the inverse: a Gaussian bump at each keypoint, at any resolution;
  the decoder's image head draws its frames through the heatmaps of the keypoints it
  predicts (:class:`~primspace.model.decoder.ImageDecoder`).

Coordinates are normalised to ``[-1, 1]``: ``x`` from the left edge to the right, ``y``
from the top row to the bottom, each pixel at its centre.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["KeypointEncoder", "spatial_softmax", "heatmaps", "pixel_grid", "HEATMAP_WIDTH"]

#: σ of the Gaussian heatmaps in normalised units (the image is 2 wide): 0.1 is 5 % of the
#: width, 3 pixels of a 64-pixel-wide frame, about half the demo's block.
HEATMAP_WIDTH = 0.1


def pixel_grid(height: int, width: int, device=None, dtype=torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
    """The normalised ``x`` (W,) and ``y`` (H,) of the pixel centres, each in ``(-1, 1)``."""
    xs = (torch.arange(width, device=device, dtype=dtype) + 0.5) / width * 2 - 1
    ys = (torch.arange(height, device=device, dtype=dtype) + 0.5) / height * 2 - 1
    return xs, ys


def spatial_softmax(features: torch.Tensor) -> torch.Tensor:
    """``(N, K, H, W)`` feature maps -> ``(N, K, 2)`` expected ``(x, y)`` of each map's softmax."""
    n, k, h, w = features.shape
    prob = torch.softmax(features.float().reshape(n, k, h * w), dim=2).view(n, k, h, w)
    xs, ys = pixel_grid(h, w, features.device)
    x = (prob.sum(dim=2) * xs).sum(dim=2)
    y = (prob.sum(dim=3) * ys).sum(dim=2)
    return torch.stack([x, y], dim=2)


def heatmaps(points: torch.Tensor, height: int, width: int, sigma: float = HEATMAP_WIDTH) -> torch.Tensor:
    """``(N, K, 2)`` keypoints -> ``(N, K, H, W)`` Gaussian bumps, 1 at each keypoint's centre.

    The Gaussian is separable, ``exp(-(x - x_k)² / 2σ²) · exp(-(y - y_k)² / 2σ²)``: two
    small vectors per keypoint and one outer product.
    """
    xs, ys = pixel_grid(height, width, points.device, points.dtype)
    gx = torch.exp(-((xs - points[..., :1]) ** 2) / (2 * sigma**2))  # (N, K, W)
    gy = torch.exp(-((ys - points[..., 1:]) ** 2) / (2 * sigma**2))  # (N, K, H)
    return gy.unsqueeze(3) * gx.unsqueeze(2)


class KeypointEncoder(nn.Module):
    """Frames to K keypoints: two convolutions and a spatial softmax.

    ``Conv(3 -> hidden, kernel 4, stride 2) -> ReLU -> Conv(hidden -> K, kernel 3)`` at half
    the frame's resolution, then :func:`spatial_softmax`. Small on purpose: it runs on every
    frame the vision loss draws, and the keypoint path may cost at most 1.5x the frames
    path per epoch (benchmarks/bench_keypoints_epoch.py).

    Parameters
    ----------
    keypoints : int
        K.
    hidden : int
        Channels of the first convolution.
    """

    def __init__(self, keypoints: int, hidden: int = 16) -> None:
        super().__init__()
        self.keypoints = int(keypoints)
        self.conv1 = nn.Conv2d(3, hidden, kernel_size=4, stride=2, padding=1)
        self.conv2 = nn.Conv2d(hidden, self.keypoints, kernel_size=3, padding=1)

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        """``(..., H, W, 3)`` frames (uint8, or floats in [0, 1]) -> ``(..., K, 2)`` keypoints."""
        lead = frames.shape[:-3]
        x = frames.reshape(-1, *frames.shape[-3:])
        x = x.float().div(255.0) if x.dtype == torch.uint8 else x.float()
        x = x.permute(0, 3, 1, 2)
        points = spatial_softmax(self.conv2(F.relu(self.conv1(x))))
        return points.view(*lead, self.keypoints, 2)

    def macs_per_frame(self, image_size: tuple[int, int]) -> int:
        """Multiply-accumulates of one frame's forward pass."""
        h, w = image_size[0] // 2, image_size[1] // 2
        c1, c2 = self.conv1, self.conv2
        return h * w * (c1.out_channels * c1.in_channels * 16 + c2.out_channels * c2.in_channels * 9)
