"""What a prediction returns: the codes, the decoded sequences and their errors (:class:`Prediction`).

A :class:`Prediction` becomes a :class:`~primspace.data.MotionDataset` of the same schema
(physical units, labels and lengths kept: :meth:`Prediction.to_dataset`), so ``show``,
``animate``, ``info``, ``cluster`` and the simulator's judge read it unchanged.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from primspace.data import MotionDataset
from primspace.data.steps import valid_steps
from primspace.predict.base import Predictor

__all__ = ["Prediction"]


@dataclass
class Prediction:
    """What :func:`predict` returns: codes, the decoded sequences and their errors.

    Attributes
    ----------
    codes : ndarray (n, K·q) float32
        The inferred codes.
    motor : ndarray (n, T, J) float32
        The predicted joint values, physical units (the observed part reproduced).
    frames : ndarray (n, T, H, W, 3) uint8 or None
        The predicted frames (runs with an image head, when asked for).
    motor_observed, frames_observed : ndarray (n, T) bool
        The observed valid steps of each modality.
    indices : ndarray (n,) int
        The samples of the data set predicted.
    errors : dict of str to ndarray (n,)
        ``motor_mse`` (scaled units, unobserved valid steps; NaN where every valid step
        was observed); with frames ``vision_mse`` ([0, 1] intensity) and ``psnr`` (dB).
    observation : dict
        The rule: ``{"motor": ..., "frames": ...}``.
    init : str
        The start of the inference (``mixture``, ``prior`` or a gradient start).
    epochs : int
    details : dict
        What the predictor adds to ``result.json``: for the prior (:class:`~primspace.predict.prior.PriorPredictor`)
        ``prior`` (its choices and primitives), ``primitive`` (the one asked, or None) and, when
        none was asked, ``posterior`` (n, P) per sample over ``primitives`` (names), ``top_primitive``
        per sample and ``posterior_accuracy`` (the share whose top primitive stands for their
        label; None without labels).
    predictor : Predictor or None
        The fitted predictor (offline predictions), to ask again
        (:func:`~primspace.predict.posterior.posterior_by_fraction`).
    """

    codes: np.ndarray
    motor: np.ndarray
    frames: np.ndarray | None
    motor_observed: np.ndarray
    frames_observed: np.ndarray
    indices: np.ndarray
    errors: dict = field(default_factory=dict)
    observation: dict = field(default_factory=dict)
    init: str = ""
    epochs: int = 0
    continuity: bool = False
    details: dict = field(default_factory=dict)
    predictor: Predictor | None = field(default=None, repr=False, compare=False)

    def summary(self) -> dict:
        """Mean errors over the samples (NaN samples skipped) and the rule, for ``result.json``."""
        means = {}
        for name, values in self.errors.items():
            finite = np.asarray(values, dtype=np.float64)
            finite = finite[np.isfinite(finite)]
            means[name] = float(finite.mean()) if finite.size else None
        return {
            "n": int(len(self.indices)),
            "init": self.init,
            "epochs": int(self.epochs),
            "continuity": bool(self.continuity),
            "observe": self.observation,
            "mean": means,
            **self.details,
        }

    def to_dataset(self, source: MotionDataset) -> MotionDataset:
        """The prediction as a data set of ``source``'s schema: its labels, lengths, names
        and step fields kept, motor (and frames, when predicted) replaced; padded steps
        keep ``source``'s values (they are not part of any sample). Its rows keep the
        source's sample numbers: ``source_ids`` (``"sample i"``, ``i`` the data file's index,
        where the source has none)."""
        taken = source.subset(self.indices)
        lengths = taken.valid_lengths
        valid = valid_steps(lengths, taken.length)
        motor = np.where(valid[..., None], self.motor, taken.motor).astype(np.float32)
        images = self.frames if self.frames is not None else None
        note = f"predicted by primspace (observe {self.observation}, init {self.init})"
        source_text = f"{taken.source}; {note}" if taken.source else note
        ids = taken.source_ids  # row k is sample indices[k] of the source: said in every row
        ids = np.array([f"sample {int(i)}" for i in self.indices]) if ids is None else ids
        return dataclasses.replace(
            taken.without_images(), motor=motor, images=images, source=source_text, path=None, source_ids=ids
        )
