"""The one surface of every predictor: fit once, then predict the rest of each motion.

Every predictor of :mod:`primspace.predict`, primspace's own and the peers alike, is an
object with the same two methods, as the maintained peers are (ProMP in
``movement-primitives``, scikit-learn's estimators):

``fit(motor, labels=None, lengths=None, frames=None)``
    once, on the fitted demonstrations: ``motor`` ``(m, T, J)`` in the run's scaled units,
    their integer ``labels`` (primitives; read by the predictors given the primitive),
    valid ``lengths`` and camera ``frames`` ``(m, T, H, W, 3)`` uint8. primspace's own
    predictors are built on a trained run (``Predictor(run, ...)``); their ``motor`` rows are
    the run's fitted samples in its order, the rows of its codes.

``predict(motor, observed, labels=None, lengths=None, frames=None)``
    the whole sequence ``(n, T, J)`` (scaled units; the observed part reproduced or
    corrected towards what was seen) of each new motion from its observed steps.
    ``observed`` is either a boolean mask ``(n, T)`` (a prefix of each sample's valid
    steps) or an :class:`~primspace.train.observe.Observation` rule (a fraction or a number
    of steps; with frames, a rule for them too). A predictor reads only the observed steps
    of ``motor`` (and ``frames``); ``labels`` are the primitive asked for, read only by the
    predictors given it.

``forecast(...)`` (same arguments) returns a :class:`Forecast`: the motion, and for
primspace's predictors the codes that decode to it (from which frames are decoded) and
what the predictor chose (``details``). ``predict`` is ``forecast(...).motor``. ``forecast`` is
abstract: a subclass that implements neither cannot be built (TypeError); the predictors of
the motion alone (the peers) implement ``predict`` and inherit ``forecast``
(:class:`MotionPredictor`).

``predict_online(motor, lengths=None, labels=None, frames=None, *, start_step=1, prediction_after=None)``
    the steps arrive one at a time, the prediction after each (an
    :class:`~primspace.predict.stream.OnlineResult`): one loop for every predictor
    (:func:`~primspace.predict.stream.follow`), each supplying only the update of an arriving
    step (:meth:`Predictor.stream`); the others refuse it in one line.

The predictors that prepare something per observation rule from the fitted
demonstrations (the mixture's noise, a calibration) need the rule: a mask that observes
the same number of steps in every sample is that number of steps; for prefixes of
different lengths pass the rule itself (``Observation.build(0.25)``).
"""

from __future__ import annotations

from abc import ABCMeta, abstractmethod
from dataclasses import dataclass, field

import numpy as np
from sklearn.base import BaseEstimator

from primspace.predict.metrics import check_lengths, check_motor, check_observed, valid_mask
from primspace.predict.stream import OnlineResult, follow, online_steps
from primspace.train.observe import Observation
from primspace.utils.errors import UserError

__all__ = [
    "Predictor",
    "MotionPredictor",
    "Forecast",
    "observed_mask",
    "observation_rule",
    "motions_as_dataset",
]


@dataclass
class Forecast:
    """What :meth:`Predictor.forecast` returns.

    Attributes
    ----------
    motor : ndarray (n, T, J) float64
        The predicted sequences, scaled units.
    codes : ndarray (n, K·q) float32 or None
        The codes that decode to them (primspace's predictors; None for the peers).
    details : dict
        What the predictor chose (e.g. the mixture's noise), for ``result.json``.
    """

    motor: np.ndarray
    codes: np.ndarray | None = None
    details: dict = field(default_factory=dict)


class Predictor(BaseEstimator, metaclass=ABCMeta):
    """The interface (module docstring). A subclass implements :meth:`fit` and :meth:`forecast`;
    one that predicts online implements :meth:`stream` (the update of one arriving step) and
    inherits :meth:`predict_online`, the one loop."""

    #: True when :meth:`predict` needs the labels of the samples (it is given the primitive).
    needs_labels = False
    #: True when :meth:`forecast` takes the samples as a data set too (``data=``, read lazily).
    reads_dataset = False
    #: The name ``Prediction.init`` records (the registry's name of the predictor).
    name = ""
    #: Gradient epochs a forecast runs (0: none).
    epochs_run = 0

    @abstractmethod
    def fit(self, motor, labels=None, lengths=None, frames=None) -> Predictor:
        """Fit once on the fitted demonstrations; returns self."""

    @abstractmethod
    def forecast(self, motor, observed, labels=None, lengths=None, frames=None, **options) -> Forecast:
        """The whole sequences ``(n, T, J)`` (scaled units) from the observed steps, with the codes
        and choices behind them (:class:`Forecast`)."""

    def predict(self, motor, observed, labels=None, lengths=None, frames=None, **options) -> np.ndarray:
        """The whole sequences ``(n, T, J)`` (scaled units) from the observed steps: ``forecast(...).motor``."""
        return self.forecast(motor, observed, labels, lengths, frames, **options).motor

    def resolve_run(self):
        """``run_``: the run this predictor is built on (``self.run``), read once from its directory when
        given as a path (:func:`~primspace.train.as_run`); :meth:`fit` of a predictor built on a run calls it."""
        from primspace.train.sessions import as_run

        self.run_ = as_run(self.run)
        return self.run_

    def check_query(self, motor) -> np.ndarray:
        """``motor`` as float64 ``(n, T, J)`` with the run's T and J (a predictor built on a run), or one UserError."""
        motor = check_motor(motor)
        config = self.run_.model_config
        expected = (int(config.length), int(config.n_joints))
        if tuple(motor.shape[1:]) != expected:
            raise UserError(f"motor must have the run's (T, J) = {expected}, got {tuple(motor.shape[1:])}")
        return motor

    def reads_fitted(self, run) -> bool:
        """Whether :meth:`fit` reads ``run``'s fitted demonstrations (otherwise it is given None)."""
        return True

    def stream(self, truth: np.ndarray, lengths: np.ndarray, labels, frames, steps: np.ndarray, keep: int, data=None):
        """The :class:`~primspace.predict.stream.Stream` that follows ``truth`` (scaled, checked) from
        ``steps[0]``, prepared for a prediction kept after step ``keep``; a predictor without one
        refuses online prediction (one UserError)."""
        raise UserError(f"{type(self).__name__} does not predict online")

    def predict_online(
        self,
        motor,
        lengths=None,
        labels=None,
        frames=None,
        *,
        start_step: int = 1,
        prediction_after: int | None = None,
        progress: bool | None = None,
        data=None,
    ) -> OnlineResult:
        """The prediction after each arriving step ``start_step..T`` (scaled ``motor`` (n, T, J), each
        motion within its valid ``lengths``; ``labels`` for the predictors given the primitive;
        ``frames`` or ``data``, the same motions as a data set, for those that read frames). What the
        predictor prepares before the first step arrives is not counted in the latency.

        Returns
        -------
        OnlineResult
            ``prediction`` after step ``prediction_after`` (default T), physical units.
        """
        truth = check_motor(motor)
        n, length = truth.shape[:2]
        steps, keep = online_steps(start_step, prediction_after, length)
        lengths = check_lengths(lengths, n, length)
        stream = self.stream(truth, lengths, labels, frames, steps, keep, data=data)
        return follow(
            stream, truth, lengths, steps, keep, label=f"online {self.name or type(self).__name__}", progress=progress
        )

    def online_forecast(self, result: OnlineResult, truth, observed, lengths, seen: int) -> Forecast:
        """The :class:`Forecast` (scaled) after step ``seen`` of an online ``result`` on ``truth`` (scaled;
        ``observed`` its observed steps, ``lengths`` its valid ones): the prediction kept and the codes
        after that step."""
        return Forecast(self.run_.scaler.transform(result.prediction), result.codes[:, result.column(seen)])

    def describe(self, details: dict, labels=None) -> dict:
        """What ``result.json`` records of a forecast's ``details`` (``labels``: the samples')."""
        return details


class MotionPredictor(Predictor):
    """A predictor of the motion alone (no codes, e.g. the peers): a subclass implements
    :meth:`fit` and :meth:`predict`; :meth:`forecast` wraps the motion."""

    @abstractmethod
    def predict(self, motor, observed, labels=None, lengths=None, frames=None, **options) -> np.ndarray:
        """The whole sequences ``(n, T, J)`` (scaled units) from the observed steps."""

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None, **options) -> Forecast:
        """:meth:`predict` as a :class:`Forecast` (float64, no codes)."""
        return Forecast(np.asarray(self.predict(motor, observed, labels, lengths, frames, **options), dtype=np.float64))


def observed_mask(observed, lengths, shape: tuple[int, int], frames: bool = False) -> np.ndarray:
    """The boolean mask ``(n, T)`` of ``observed`` (a mask, or an Observation rule applied to
    ``lengths``); ``frames``: the frames' mask of a rule (a mask stands for both)."""
    n, steps = shape
    lengths = check_lengths(lengths, n, steps)
    if isinstance(observed, Observation):
        return observed.masks(lengths, steps)[1 if frames else 0]
    return check_observed(observed, shape, valid_mask(lengths, steps))


def observation_rule(observed, lengths, shape: tuple[int, int]) -> Observation:
    """The rule behind ``observed``: itself when it is one; for a mask, the number of steps
    it observes in every sample (a prefix of the same length in each; one UserError otherwise)."""
    if isinstance(observed, Observation):
        return observed
    mask = observed_mask(observed, lengths, shape)
    counts = mask.sum(axis=1)
    prefix = np.arange(shape[1])[None, :] < counts[:, None]
    if not np.array_equal(mask, prefix):
        raise UserError("observed must be a prefix of each sample's steps")
    if counts.size == 0 or counts.min() != counts.max():
        raise UserError(
            "observed holds prefixes of different lengths: pass the rule instead of the mask "
            "(e.g. Observation.build(0.25) for a quarter of each motion)"
        )
    if counts[0] < 1:
        raise UserError("observed marks no step: nothing to predict from")
    return Observation.build(int(counts[0]))


def motions_as_dataset(motor: np.ndarray, lengths=None, frames=None):
    """Arrays of motions (physical units) as a :class:`~primspace.data.MotionDataset` for the
    predictors that infer through :func:`~primspace.train.infer`: motions of different valid
    ``lengths`` carry the step fields the data set asks of padded samples (one segment each)."""
    from primspace.data import MotionDataset

    n, steps = motor.shape[:2]
    lengths = check_lengths(lengths, n, steps)
    if (lengths == steps).all():
        return MotionDataset(motor=motor, images=frames)
    valid = valid_mask(lengths, steps)
    step = np.where(valid, 0, -1).astype(np.int32)
    return MotionDataset(motor=motor, lengths=lengths, step_labels=step, step_segments=step.copy(), images=frames)
