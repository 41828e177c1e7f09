"""Inference from what has been seen so far: observation masks and the starts that read them.

One mechanism for every "which entries were observed" (docs/model.md, *Inference from what
has been seen so far*): an :class:`Observation` rule gives, for each sample, a motor mask
and a frame mask (N, T) over its steps, combined with the padding of demonstrations of
different lengths (:func:`primspace.data.steps.valid_steps`). The loss counts only the
observed entries (:class:`primspace.train.loop.DataTensors`), and the starts of
:func:`primspace.train.infer` read the same masks:

* ``zero``, ``random``: as without observation (they read no data);
* ``projection``: ``P (M ⊙ m)``, the run's ``P`` (paper, *Initialization of Latent
  Vectors*) applied to the scaled motor sequence with its unobserved steps set to zero;
  Appendix A then holds for the observed parts (:func:`primspace.latent.appendix_a_observed`);
* ``pca``: ``V_q (M ⊙ (m − mean))``, the principal directions (the run's when it was fitted
  with ``pca``; else fitted here on the zero-filled observed part of the data inferred);
* ``calibrated``: the ridge map towards the identity
  (:class:`primspace.calibration.CodeCalibration`) from the fitted demonstrations' observed
  projections (the same rule applied to them) to their fitted codes; fitted on demand and
  cached in memory on the :class:`~primspace.train.run.TrainedRun`, keyed by the rule;
* ``nearest``: the fitted code of the fitted demonstration whose motor is nearest over the
  new sample's observed steps (Euclidean, scaled units);
* ``calibrated`` with no joints observed (``observe="none"``) and frames observed: a random
  projection of the observed frames minus the run's mean frame, mapped to the fitted codes
  by a calibration fitted the same way (:mod:`primspace.train.frames_start`).

The rule is recorded in an infer run's ``config.json`` (``observe``), so a resume checks it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from primspace.calibration import CodeCalibration
from primspace.data import MotionDataset
from primspace.data.steps import valid_steps
from primspace.errors import UserError
from primspace.latent import CALIBRATABLE, CALIBRATED, NEAREST, LatentInitializer
from primspace.train.rundir import check_run_data

__all__ = ["Observation", "NOTHING", "FIRST", "observation_masks", "observation_record", "observing_args",
           "observed_start", "observed_calibration", "nearest_codes", "fitted_samples"]

#: ``observe`` / ``observe_frames`` value: nothing of that modality is observed.
NOTHING = "none"
#: ``observe_frames`` value: the first frame only.
FIRST = "first"


def _check_amount(value, name: str, words: tuple[str, ...]):
    """``value`` as a fraction in (0, 1], a number of steps >= 1, or one of ``words``."""
    if isinstance(value, str):
        if value in words:
            return value
        raise UserError(f"{name} must be a fraction in (0, 1], a number of steps >= 1 or one of "
                        f"{', '.join(repr(w) for w in words)}; got {value!r}")
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
    def build(cls, observe, observe_frames=None) -> "Observation | None":
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
            raise UserError("observe='none' observes no joints and no frames are observed: nothing to infer from; "
                            "give observe_frames (e.g. 'first' or a fraction) to infer from frames alone")
        return cls(motor, frames, observe_frames is not None and observe_frames != NOTHING)

    def to_dict(self) -> dict:
        """The rule as recorded in ``config.json`` (``observe``)."""
        return {"motor": self.motor, "frames": self.frames}

    @property
    def key(self) -> tuple:
        """What a cached start (``TrainedRun.observed_calibrations``) is keyed by."""
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
            raise UserError(f"observe_frames={self.frames!r}: the run does not use frames (no image head, images off or "
                            "vision_weight 0)")

    def masks(self, lengths, length: int) -> tuple[np.ndarray, np.ndarray]:
        """Motor and frame masks (N, T) bool for samples of valid ``lengths`` (padding included)."""
        return _prefix(self.motor, lengths, length), _prefix(self.frames, lengths, length)


def observation_masks(observation: Observation | None, data: MotionDataset) -> tuple[np.ndarray, np.ndarray]:
    """Motor and frame masks (N, T) bool of ``data``: the observed valid steps (every valid step without a rule)."""
    lengths = data.lengths if data.lengths is not None else np.full(len(data), data.length)
    if observation is None:
        valid = valid_steps(lengths, data.length)
        return valid, valid
    return observation.masks(lengths, data.length)


def observation_record(observation: Observation | None, data: MotionDataset, use_images: bool,
                       has_image_head: bool) -> dict:
    """What an infer run's ``config.json`` records of ``observation`` (``{"observe": rule}``;
    nothing without one), after :meth:`Observation.check`."""
    if observation is None:
        return {}
    observation.check(data, use_images, has_image_head)
    return {"observe": observation.to_dict()}


# ------------------------------------------------------------------------- the starts


def observing_args(init: str, observation: Observation | None, data: MotionDataset,
                   fitted_data: MotionDataset | None) -> dict | None:
    """The arguments of :func:`observed_start` for ``data`` (its motor mask as ``observed``);
    None when the start reads no mask (no observation and not ``nearest``: today's starts)."""
    if observation is None and init != NEAREST:
        return None
    return {"observed": observation_masks(observation, data)[0], "observation": observation, "fitted_data": fitted_data,
            "data": data}


def observed_start(init: str, parent, initializer: LatentInitializer, scaled: np.ndarray, observed: np.ndarray,
                   seed: int, observation: Observation | None, fitted_data: MotionDataset | None,
                   data: MotionDataset | None = None) -> np.ndarray:
    """Starting codes (float64, (n, K·q)) of ``scaled`` motor observed at ``observed`` (n, T).

    ``zero`` / ``random`` / ``projection`` / ``pca``: the initialiser's codes of the observed
    part (:meth:`~primspace.latent.LatentInitializer.transform`); ``calibrated``: those
    mapped by the calibration for this rule (:func:`observed_calibration`), or with no
    joints observed the frames start of ``data`` (:func:`~primspace.train.frames_start.frames_start_codes`);
    ``nearest``: :func:`nearest_codes`. ``parent``: the trained run; ``fitted_data``: the
    data set it was fitted on (default: its data file); ``data``: the samples (their frames).
    """
    if init == NEAREST:
        fitted_set = fitted_samples(parent, fitted_data)
        fitted, valid = parent.scaler.transform(fitted_set.motor), observation_masks(None, fitted_set)[0]
        return nearest_codes(scaled, observed, fitted, valid, parent.latents)
    if observation is not None and observation.motor == NOTHING and init not in ("zero", "random"):
        if init == CALIBRATED and data is not None:
            from primspace.train.frames_start import frames_start_codes  # it reads this module's masks

            return frames_start_codes(parent, data, observation, fitted_data)
        raise UserError(f"init {init!r} starts from the observed joints, and observe='none' observes none: "
                        "start by 'calibrated' (from the frames), 'zero' or 'random'")
    codes = initializer.transform(scaled, random_state=seed, observed=observed)
    if init == CALIBRATED:
        codes = observed_calibration(parent, observation, fitted_data).transform(codes)
    return codes.astype(np.float64)


def observed_calibration(parent, observation: Observation | None, fitted_data: MotionDataset | None) -> CodeCalibration:
    """The ridge map (towards the identity) from the fitted demonstrations' observed codes
    ``P (M_i ⊙ m_i)`` to their fitted codes, for ``observation`` (the run's own map without one).

    Fitted on first use and cached in ``parent.observed_calibrations`` (in memory, not
    saved with the run), keyed by the rule.
    """
    if observation is None:
        return parent.calibration
    cache = parent.observed_calibrations
    if observation.key not in cache:
        if parent.initializer.method not in CALIBRATABLE:
            raise UserError(f"init 'calibrated' needs a run fitted with projection or pca init, not "
                            f"'{parent.initializer.method}'")
        data = fitted_samples(parent, fitted_data)
        scaled = parent.scaler.transform(data.motor)
        motor_mask, _ = observation_masks(observation, data)
        initial = parent.initializer.transform(scaled, observed=motor_mask)
        cache[observation.key] = CodeCalibration(parent.model_config.latent_dim).fit(initial, parent.latents)
    return cache[observation.key]


def nearest_codes(scaled: np.ndarray, observed: np.ndarray, fitted: np.ndarray, fitted_valid: np.ndarray,
                  fitted_codes: np.ndarray) -> np.ndarray:
    """For each sample, the code of the fitted demonstration whose motor is nearest over its observed steps.

    The squared distance is the mean over the entries observed in the sample and valid in
    the fitted demonstration (all of its observed entries, when the fitted demonstrations
    have one length: then the Euclidean distance of the observed parts); a demonstration
    sharing no step is never nearest. Ties go to the first.

    Parameters
    ----------
    scaled : ndarray (n, T, J)
    observed : ndarray (n, T) bool
    fitted : ndarray (m, T, J)
        The fitted demonstrations, scaled.
    fitted_valid : ndarray (m, T) bool
    fitted_codes : ndarray (m, K·q)

    Returns
    -------
    ndarray (n, K·q) float64: rows of ``fitted_codes``.
    """
    j = scaled.shape[2]
    a, m = scaled.reshape(len(scaled), -1), np.repeat(np.asarray(observed, dtype=np.float64), j, axis=1)
    b, v = fitted.reshape(len(fitted), -1), np.repeat(np.asarray(fitted_valid, dtype=np.float64), j, axis=1)
    a, b = a * m, b * v
    sums = (a**2) @ v.T + m @ (b**2).T - 2.0 * a @ b.T  # Σ over shared entries of (a - b)²
    counts = m @ v.T
    dist = np.where(counts > 0, np.maximum(sums, 0.0) / np.maximum(counts, 1.0), np.inf)
    return np.asarray(fitted_codes, dtype=np.float64)[np.argmin(dist, axis=1)]


def fitted_samples(parent, fitted_data: MotionDataset | None) -> MotionDataset:
    """The parent's own samples (checked against its record): from ``fitted_data`` or its data file."""
    if fitted_data is None:
        if parent.data_path is None:
            raise UserError("this start reads the demonstrations the run was fitted on, and the run has no data file: "
                            "give fitted_data= (the data set it was fitted on)")
        fitted_data = MotionDataset.load(parent.data_path)
    if not isinstance(fitted_data, MotionDataset):
        raise UserError(f"fitted_data must be a MotionDataset, got {type(fitted_data).__name__}")
    check_run_data(parent, fitted_data)
    return fitted_data.subset(parent.indices)

