"""Gradient inference from a start as a predictor.

The paper's inference, on the observed part only: each new motion's code starts from one
of the starts of :mod:`primspace.train.starts` (``zero``, ``random``, ``projection``, ``pca``,
``calibrated``, ``nearest``) and follows ``epochs`` of :func:`primspace.train.infer` on the
observed entries (θ frozen); the decoder's whole sequence is the prediction. Online
(:meth:`GradientPredictor.predict_online`): the steps arrive one at a time, ``iterations``
Adam steps after each (:class:`~primspace.predict.online.OnlineInference`).

The starts that read the fitted demonstrations (``calibrated``, ``nearest``) read them from
what :meth:`GradientPredictor.fit` was given; their calibrations per observation rule are
kept in the predictor.
"""

from __future__ import annotations

import numpy as np

from primspace.data import MotionDataset
from primspace.model.latent import INFER_STARTS
from primspace.predict.base import Forecast, Predictor, motions_as_dataset, observation_rule
from primspace.predict.candidates import continuity_correction
from primspace.predict.metrics import check_lengths, check_motor, valid_mask
from primspace.predict.online import OnlineInference
from primspace.predict.stream import OnlineResult
from primspace.train.api import infer, reconstruct
from primspace.train.observe import Observation
from primspace.train.starts import STARTS_FROM_FITTED, FittedDemonstrations, fitted_start
from primspace.utils.errors import UserError

__all__ = ["GradientPredictor", "DEFAULT_PREDICT_EPOCHS"]

#: Inference epochs of a gradient predictor when none are given (θ frozen, codes only).
DEFAULT_PREDICT_EPOCHS = 100


class GradientPredictor(Predictor):
    """Inference of each motion's code from its observed part (module docstring).

    Parameters
    ----------
    run : TrainedRun or path-like
        The trained run (θ frozen; not changed).
    start : str, optional
        The start of the inference (default: the run's init).
    epochs : int
        Inference epochs on the observed entries (0: the start decoded as it is).
    continuity : bool
        Apply the continuity correction (:func:`~primspace.predict.candidates.continuity_correction`).
    overrides : dict, optional
        Train-config overrides of the inference (``latent_lr``, ``batch_size``, ``seed``,
        ``device`` ...).
    progress : bool, optional
        A progress bar for the inference (default: when stderr is a terminal).
    iterations : int
        Adam iterations after each arriving step of :meth:`predict_online`.
    """

    def __init__(
        self,
        run,
        start: str | None = None,
        epochs: int = DEFAULT_PREDICT_EPOCHS,
        continuity: bool = True,
        overrides: dict | None = None,
        progress: bool | None = None,
        iterations: int = 1,
    ):
        self.run = run
        self.start = start
        self.epochs = epochs
        self.continuity = continuity
        self.overrides = overrides
        self.progress = progress
        self.iterations = iterations

    #: :meth:`forecast` takes the samples as a data set (``data=``; frames read lazily).
    reads_dataset = True

    @property
    def name(self) -> str:
        """The gradient start (the run's init until fitted without one)."""
        return getattr(self, "start_", None) or self.start or getattr(self.run, "init", "")

    @property
    def epochs_run(self) -> int:
        """The inference epochs of :meth:`forecast`."""
        return int(self.epochs)

    def reads_fitted(self, run) -> bool:
        """Whether :meth:`fit` reads the fitted demonstrations (the starts that read them)."""
        return (self.start or run.init) in STARTS_FROM_FITTED

    def fit(self, motor, labels=None, lengths=None, frames=None) -> GradientPredictor:
        """Keep the fitted demonstrations (scaled, in the run's order) for the starts that read them
        (``motor`` may be None for the others)."""
        self.resolve_run()
        self.start_ = self.start or self.run_.init
        if self.start_ not in INFER_STARTS:
            raise UserError(f"unknown start {self.start_!r}: choose one of {', '.join(INFER_STARTS)}")
        self.cache_: dict = {}  # calibrations per observation rule
        if motor is None and self.start_ not in STARTS_FROM_FITTED:
            self.fitted_ = None
            return self
        motor = check_motor(motor)
        if len(motor) != len(self.run_.latents):
            raise UserError(
                f"a gradient predictor is fitted on the run's {len(self.run_.latents)} fitted "
                f"demonstrations (one per code), got {len(motor)}"
            )
        self.fitted_ = FittedDemonstrations(motor, check_lengths(lengths, *motor.shape[:2]), frames)
        return self

    def _dataset(self, motor: np.ndarray, lengths, frames) -> MotionDataset:
        """The samples as a data set in physical units (what :func:`~primspace.train.infer` reads)."""
        return motions_as_dataset(self.run_.scaler.inverse_transform(motor).astype(np.float32), lengths, frames)

    def start_codes(self, data: MotionDataset, scaled: np.ndarray, rule: Observation) -> np.ndarray | None:
        """The starting codes of the starts that read the fitted demonstrations (None for the others:
        :func:`~primspace.train.infer` computes those)."""
        if self.start_ not in STARTS_FROM_FITTED:
            return None
        observed = rule.masks(check_lengths(data.lengths, len(data), data.length), data.length)[0]
        return fitted_start(self.run_, self.start_, self.fitted_, data, scaled, observed, rule, self.cache_)

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None, *, data: MotionDataset | None = None):
        """The decoded inferred codes. ``data``: the same samples as a data set, when the caller
        has it (its frames are read lazily; default: built from the arrays)."""
        motor = check_motor(motor)
        rule = observation_rule(observed, lengths, motor.shape[:2])
        data = self._dataset(motor, lengths, frames) if data is None else data
        start = self.start_codes(data, motor, rule)
        inferred = infer(
            self.run_,
            data,
            None,
            epochs=self.epochs,
            init=self.start_,
            initial_latents=start,
            observe=rule.motor,
            observe_frames=rule.frames if rule.frames_given else None,
            progress=self.progress,
            **(self.overrides or {}),
        )
        codes = inferred.latents.astype(np.float32)
        scaled = self.run_.scaler.transform(reconstruct(inferred, images=False)[0])
        return Forecast(self._corrected(scaled, motor, rule, data), codes, {})

    def _corrected(self, scaled: np.ndarray, motor: np.ndarray, rule: Observation, data: MotionDataset) -> np.ndarray:
        """``scaled`` with the continuity correction when asked for."""
        if not self.continuity:
            return scaled
        lengths = check_lengths(data.lengths, len(data), data.length)
        observed = rule.masks(lengths, data.length)[0]
        return continuity_correction(scaled, motor, observed, valid_mask(lengths, data.length))

    def stream(self, truth, lengths, labels, frames, steps, keep, data: MotionDataset | None = None):
        """:class:`~primspace.predict.online.OnlineInference` from ``steps[0]``: ``iterations`` Adam steps
        after each arriving step (:mod:`~primspace.predict.online`); the start reads the steps up to
        ``steps[0]``. ``data``: the same motions as a data set (default: built from the arrays). The
        continuity correction is not applied online (:meth:`online_forecast` applies it to the codes kept)."""
        data = self._dataset(truth, lengths, frames) if data is None else data
        start = self.start_codes(data, truth, Observation.build(int(steps[0])))
        overrides = self.overrides or {}
        return OnlineInference(
            self.run_,
            data,
            iterations=self.iterations,
            init=self.start_,
            start_step=int(steps[0]),
            start_codes=start,
            latent_lr=overrides.get("latent_lr"),
            seed=overrides.get("seed"),
        )

    def online_forecast(self, result: OnlineResult, truth, observed, lengths, seen: int) -> Forecast:
        """The codes after step ``seen`` decoded, with the continuity correction at ``observed`` when asked for."""
        codes = result.codes[:, result.column(seen)]
        scaled = self.run_.scaler.transform(reconstruct(self.run_, codes, images=False)[0])
        if self.continuity:
            scaled = continuity_correction(scaled, truth, observed, valid_mask(lengths, truth.shape[1]))
        return Forecast(scaled, codes)
