"""Inference from what has been seen so far: the observation rule (what the loss reads).

One mechanism for every "which entries were observed" (docs/model.md, *Inference from what
has been seen so far*): an :class:`Observation` rule gives, for each sample, a motor mask
and a frame mask (N, T) over its steps, combined with the padding of demonstrations of
different lengths (:func:`primspace.data.steps.valid_steps`). The loss counts only the
observed entries (:class:`primspace.train.loss.DataTensors`); the starts of
:func:`primspace.train.infer` read the same masks (:mod:`primspace.train.starts`).

The rule is recorded in an infer run's ``config.json`` (``observe``), so a resume checks it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from primspace.data import MotionDataset
from primspace.data.steps import valid_steps
from primspace.utils.errors import UserError

__all__ = ["Observation", "NOTHING", "FIRST", "observation_masks", "observation_record"]

#: ``observe`` / ``observe_frames`` value: nothing of that modality is observed.
NOTHING = "none"
#: ``observe_frames`` value: the first frame only.
FIRST = "first"


def _check_amount(value, name: str, words: tuple[str, ...]):
    """``value`` as a fraction in (0, 1], a number of steps >= 1, or one of ``words``."""
    if isinstance(value, str):
        if value in words:
            return value
        raise UserError(
            f"{name} must be a fraction in (0, 1], a number of steps >= 1 or one of "
            f"{', '.join(repr(w) for w in words)}; got {value!r}"
        )
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise UserError(f"{name} must be a fraction in (0, 1] or a number of steps >= 1, got {value!r}")
    if isinstance(value, (int, np.integer)):
        if value < 1:
            raise UserError(f"{name} must observe at least 1 step, got {value} (use {name}={NOTHING!r} for none)")
        return int(value)
    if not (math.isfinite(value) and 0 < value <= 1):
        raise UserError(f"{name} as a fraction of the valid steps must be in (0, 1], got {value}")
    return float(value)


def _prefix(amount, lengths: np.ndarray, length: int) -> np.ndarray:
    """(N, T) bool: the observed prefix of each sample under ``amount``, within its valid steps."""
    lengths = np.asarray(lengths, dtype=np.int64)
    if amount == NOTHING:
        steps = np.zeros_like(lengths)
    elif amount == FIRST:
        steps = np.minimum(lengths, 1)
    elif isinstance(amount, float):
        steps = np.maximum(1, np.ceil(amount * lengths - 1e-9).astype(np.int64))
    else:
        steps = np.minimum(int(amount), lengths)
    return valid_steps(np.minimum(steps, lengths), length)


@dataclass(frozen=True)
class Observation:
    """Which steps of each sample were observed, per modality (a prefix rule).

    Parameters
    ----------
    motor : float, int or "none"
        A fraction in (0, 1] of each sample's valid steps (rounded up, at least 1 step), a
        number of steps (capped at each sample's valid length), or ``"none"``: no joints
        observed (frames only).
    frames : float, int, "first" or "none"
        The same for the frames; ``"first"``: the first frame only.

    Examples
    --------
    >>> obs = Observation.build(0.5, "first")
    >>> obs.masks(np.array([4, 3]), 4)[0].astype(int).tolist()
    [[1, 1, 0, 0], [1, 1, 0, 0]]
    """

    motor: float | int | str
    frames: float | int | str
    frames_given: bool = field(default=False, compare=False)  # observe_frames asked for explicitly

    @classmethod
    def build(cls, observe, observe_frames=None) -> Observation | None:
        """The rule for ``infer(observe=, observe_frames=)``; None when nothing is masked
        (``observe`` and ``observe_frames`` both None: every step observed, today's inference).

        ``observe_frames=None`` follows ``observe``; ``observe=None`` with frames given
        observes every joint value.
        """
        if observe is None and observe_frames is None:
            return None
        motor = 1.0 if observe is None else _check_amount(observe, "observe", (NOTHING,))
        frames = motor if observe_frames is None else _check_amount(observe_frames, "observe_frames", (FIRST, NOTHING))
        if motor == NOTHING and frames == NOTHING:
            raise UserError(
                "observe='none' observes no joints and no frames are observed: nothing to infer from; "
                "give observe_frames (e.g. 'first' or a fraction) to infer from frames alone"
            )
        return cls(motor, frames, observe_frames is not None and observe_frames != NOTHING)

    def to_dict(self) -> dict:
        """The rule as recorded in ``config.json`` (``observe``)."""
        return {"motor": self.motor, "frames": self.frames}

    @property
    def key(self) -> tuple:
        """What a start or a predictor prepared for this rule is keyed by (hashable)."""
        return (self.motor, self.frames)

    def check(self, data: MotionDataset, use_images: bool, has_image_head: bool) -> None:
        """Refuse frames asked of data (or a run) without them, and frames only without an image head."""
        frames_asked = self.frames_given
        if self.motor == NOTHING and not has_image_head:
            raise UserError("observe='none' infers from frames alone, but the run has no image head")
        if frames_asked and not data.has_images:
            where = str(data.path) if data.path is not None else "the data set"
            raise UserError(f"observe_frames={self.frames!r} asks for frames, but {where} has no frames")
        if (frames_asked or self.motor == NOTHING) and not use_images:
            raise UserError(
                f"observe_frames={self.frames!r}: the run does not use frames (no image head, images off or "
                "vision_weight 0)"
            )

    def masks(self, lengths, length: int) -> tuple[np.ndarray, np.ndarray]:
        """Motor and frame masks (N, T) bool for samples of valid ``lengths`` (padding included)."""
        return _prefix(self.motor, lengths, length), _prefix(self.frames, lengths, length)


def observation_masks(observation: Observation | None, data: MotionDataset) -> tuple[np.ndarray, np.ndarray]:
    """Motor and frame masks (N, T) bool of ``data``: the observed valid steps (every valid step without a rule)."""
    lengths = data.valid_lengths
    if observation is None:
        valid = valid_steps(lengths, data.length)
        return valid, valid
    return observation.masks(lengths, data.length)


def observation_record(
    observation: Observation | None, data: MotionDataset, use_images: bool, has_image_head: bool
) -> dict:
    """What an infer run's ``config.json`` records of ``observation`` (``{"observe": rule}``;
    nothing without one), after :meth:`Observation.check`."""
    if observation is None:
        return {}
    observation.check(data, use_images, has_image_head)
    return {"observe": observation.to_dict()}
