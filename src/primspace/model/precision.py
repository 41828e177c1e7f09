"""The decoder's learned precision of each modality: :class:`ModalityPrecision`.

Two senses of very different sizes share one loss (a frame holds about a thousand values
for each joint vector): read as a Gaussian likelihood with one variance ``σ_m²`` per
modality ``m`` (motor, vision), the negative log-likelihood per element of each is

.. math::  ½ \\left( e^{-s_m} \\, \\mathrm{MSE}_m + s_m \\right), \\qquad s_m = \\log σ_m^2,

and ``s_m`` is learned with θ (Kendall, Gal & Cipolla 2018, *Multi-task learning using
uncertainty to weigh losses for scene geometry and semantics*). Its minimiser in ``s_m`` is
``log MSE_m``: each modality's error weighs by its precision ``e^{-s_m} ≈ 1 / MSE_m``, so
neither sense drowns the other whatever its size (:mod:`primspace.train.loss`,
``TrainConfig.loss_reduction="precision"``).

The parameter is ``raw`` (2,) and ``s = RATE · raw``: the optimiser of θ moves every
parameter by about its learning rate per step, and ``s_m`` has to travel ``log`` of the
errors' fall during training (about 7 over a fit whose errors fall 1000-fold), so its
steps are ``RATE`` times larger than θ's without an optimiser group of its own (the packed
and captured paths step θ with one rate). ``raw`` starts at 0: both weights 1, the loss
``"mean"``'s balance at the first step.
"""

from __future__ import annotations

import math

import torch
from torch import nn

__all__ = ["ModalityPrecision", "MODALITIES", "KEYPOINT_MODALITIES"]

#: The modalities in the order of ``ModalityPrecision.raw``.
MODALITIES = ("motor", "vision")
#: The same with the keypoints of the frames (``ModelConfig.keypoints > 0``,
#: :mod:`primspace.model.keypoints`): a third modality with its own precision.
KEYPOINT_MODALITIES = MODALITIES + ("keypoints",)


class ModalityPrecision(nn.Module):
    """One learned log-variance ``s_m`` per modality (module docstring).

    Parameters
    ----------
    modalities : tuple of str
        The modalities weighed, :data:`MODALITIES` (default) or :data:`KEYPOINT_MODALITIES`.

    Attributes
    ----------
    raw : Parameter (M,)
        ``s / RATE`` of each modality, in ``modalities``' order.
    """

    #: ``s = RATE · raw`` (module docstring).
    RATE = 10.0

    def __init__(self, modalities: tuple[str, ...] = MODALITIES) -> None:
        super().__init__()
        self.modalities = tuple(modalities)
        self.raw = nn.Parameter(torch.zeros(len(self.modalities)))

    def forward(self) -> torch.Tensor:
        """``s`` (M,): the log-variances of the modalities (float32)."""
        return self.raw.float() * self.RATE

    def summary(self) -> dict:
        """``{modality: {"log_variance": s_m, "weight": e^{-s_m}}}`` as plain floats."""
        with torch.no_grad():
            s = self.forward().double().cpu().tolist()
        return {m: {"log_variance": v, "weight": math.exp(-v)} for m, v in zip(self.modalities, s)}
