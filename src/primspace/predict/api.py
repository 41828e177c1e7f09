"""Predict the rest of a motion from what has been seen so far (docs/predict.md).

The paper frames its model as predictive coding: "Predicted information is compared with
the real one and internal state is corrected based on the error" (paper, *Background*).
:func:`predict` does this offline: the code of each new sample is inferred with θ frozen
from its *observed* entries only (:func:`primspace.train.infer` with ``observe`` /
``observe_frames``, :mod:`primspace.train.observe`), and the decoder's whole sequence
``d(θ, z)`` is the prediction: the observed part reproduced, the rest predicted. Each way
of finding that code is a predictor (:mod:`primspace.predict.base`): :func:`predict` builds
the one a :class:`~primspace.predict.request.PredictRequest` names
(:func:`~primspace.predict.registry.make_predictor`), fits it on the run's fitted
demonstrations and runs it on a data set. The default, ``auto``, chooses among the mixture over
the fitted codes and the prior per primitive (given the primitive: the prior given it and the
mixture restricted to it) by their K-fold error on the fitted demonstrations for the task asked
(:mod:`primspace.predict.selection`; docs/predict.md, *How the predictor is chosen*).

The measure of a prediction is its error on the steps that were **not** observed:

* motor: the mean squared error over the unobserved valid steps and all joints, in the
  scaled units of the run (joints scaled to [-1, 1] over the fitted data), the one
  definition :func:`primspace.predict.metrics.unobserved_mse` shared with the peers (ProMP, nearest
  neighbour, mean motion), so the table of docs/predict.md compares like with like;
* frames: the mean squared error of the unobserved valid frames in [0, 1] intensity and
  the PSNR ``10 log10(1 / MSE)`` (dB).

The run is resolved here, once (:func:`~primspace.train.as_run`); what :func:`predict` calls
takes the :class:`~primspace.train.run.TrainedRun`.
"""

from __future__ import annotations

import os

import numpy as np

from primspace.data import MotionDataset
from primspace.data.steps import valid_steps
from primspace.predict.base import Predictor
from primspace.predict.gradient import DEFAULT_PREDICT_EPOCHS
from primspace.predict.metrics import frame_errors, unobserved_mse
from primspace.predict.mixture import MIXTURE
from primspace.predict.prior import PRIOR
from primspace.predict.registry import (
    DEFAULT_PREDICTOR,
    PREDICT_STARTS,
    fit_predictor,
    make_predictor,
    predictor_for,
    run_predictor,
)
from primspace.predict.request import PredictRequest
from primspace.predict.result import Prediction
from primspace.predict.selection import AUTO
from primspace.train.api import as_run, reconstruct
from primspace.train.checks import select
from primspace.train.observe import Observation
from primspace.train.run import TrainedRun
from primspace.utils.errors import UserError

__all__ = [
    "Prediction",
    "PredictRequest",
    "predict",
    "predict_request",
    "make_predictor",
    "fit_predictor",
    "predictor_for",
    "run_predictor",
    "DEFAULT_PREDICT_EPOCHS",
    "AUTO",
    "MIXTURE",
    "PRIOR",
    "PREDICT_STARTS",
    "DEFAULT_PREDICTOR",
]


def predict(
    run: TrainedRun | str | os.PathLike, dataset: MotionDataset, request: PredictRequest | None = None, **settings
) -> Prediction:
    """Predict the rest of each motion of ``dataset`` from its observed part, and score it.

    Parameters
    ----------
    run : TrainedRun or path-like
        A fitted run (θ is frozen; the run is not changed); resolved here, once.
    dataset : MotionDataset
        The samples to predict: their observed part is read, the rest is the answer the
        errors are measured against.
    request : PredictRequest, optional
        The settings (:class:`~primspace.predict.request.PredictRequest` lists them: ``observe``,
        ``observe_frames``, ``init``, ``epochs``, ``indices``, ``fitted_data``, ``frames``,
        ``continuity``, ``condition``, ``online``, ``progress``, ``primitive``, ``primitives``,
        ``n_clusters``, ``prior_samples``, ``reuse`` and train-config overrides). ``init`` defaults to
        ``auto``: the predictor chosen by held-out evidence, recorded in ``details["selection"]``.
    **settings
        The same settings as keywords (without ``request``).

    Returns
    -------
    Prediction
        Its motion stays within each joint's recorded range (the minimum and maximum of
        the fitted demonstrations, which the run's scaler maps onto [-1, 1]): a gripper
        predicted beyond fully open or closed is set to that bound, and the errors are
        those of the motion returned.

    Raises
    ------
    UserError
        ``observe`` of 0 or above 1, frames asked of data without frames, an unknown
        start, a primitive the run does not have (the line lists those it has), and what
        :func:`~primspace.train.infer` refuses.
    """
    if request is not None and settings:
        raise UserError("predict takes a request or keywords, not both")
    return predict_request(as_run(run), dataset, PredictRequest.of(**settings) if request is None else request)


def predict_request(run: TrainedRun, dataset: MotionDataset, request: PredictRequest) -> Prediction:
    """:func:`predict` of a resolved run and a request."""
    if request.observe is None and request.observe_frames is None:
        raise UserError(
            "predict needs observe= (a fraction in (0, 1], a number of steps or 'none'): "
            "with everything observed there is nothing to predict"
        )
    observation = Observation.build(request.observe, request.observe_frames)
    init = predictor_for(
        request.init, primitive=request.primitive, primitives=request.primitives, n_clusters=request.n_clusters
    )
    predictor = make_predictor(run, request=request.replace(init=init or run.init))
    data, idx = select(dataset, request.indices)
    head = run.model_config.has_images
    observation.check(data, use_images=head and data.has_images, has_image_head=head)  # before any fitting
    motor_observed, frames_observed = observation.masks(data.valid_lengths, data.length)
    if request.online is not None:
        _check_online(observation)
    predictor = fit_predictor(predictor, run, request.fitted_data)
    if request.online is not None:
        forecast = _online(predictor, run, data, observation, request.progress)
    else:
        forecast = run_predictor(predictor, run, data, observation)
    details = predictor.describe(forecast.details, data.labels)
    scaled = np.clip(forecast.motor, -1.0, 1.0)  # within each joint's recorded range (the scaler maps it onto [-1, 1])
    codes = forecast.codes.astype(np.float32) if request.online is not None else forecast.codes
    predicted_frames = None
    if request.frames and run.model_config.has_images:
        predicted_frames = reconstruct(run, codes, images=True)[1]
    lengths = data.valid_lengths
    errors = {"motor_mse": unobserved_mse(scaled, run.scaler.transform(data.motor), motor_observed, lengths)}
    if predicted_frames is not None and data.has_images:
        errors["vision_mse"], errors["psnr"] = frame_errors(
            predicted_frames, data.load_images().images, frames_observed, valid_steps(lengths, data.length)
        )
    return Prediction(
        codes=codes,
        motor=run.scaler.inverse_transform(scaled).astype(np.float32),
        frames=predicted_frames,
        motor_observed=motor_observed,
        frames_observed=frames_observed,
        indices=idx,
        errors=errors,
        observation=observation.to_dict(),
        init=predictor.name,
        epochs=0 if request.online is not None else predictor.epochs_run,
        continuity=request.continuity,
        details=details,
        predictor=None if request.online is not None else predictor,
    )


def _online(predictor: Predictor, run: TrainedRun, data: MotionDataset, observation: Observation, progress):
    """The :class:`~primspace.predict.base.Forecast` after the observed steps arrived one at a time
    (``details["online"]``: the latency per step and the error of the remaining steps after each)."""
    observed = observation.masks(data.valid_lengths, data.length)[0]
    seen = int(observed.sum(axis=1).max())
    truth = run.scaler.transform(data.motor)
    extra = {"data": data} if predictor.reads_dataset else {}
    result = predictor.predict_online(
        truth, data.valid_lengths, data.labels, prediction_after=seen, progress=progress, **extra
    )
    forecast = predictor.online_forecast(result, truth, observed, data.valid_lengths, seen)
    forecast.details = {
        "online": {
            "iterations": int(getattr(result, "iterations", 0)),
            "steps_observed": seen,
            "latency_ms_mean": 1e3 * result.latency_mean,
            "latency_ms_p95": 1e3 * result.latency_p95,
            "remaining_error": [None if not np.isfinite(e) else float(e) for e in result.mean_error],
        }
    }
    return forecast


def _check_online(observation: Observation) -> None:
    """One UserError unless the rule observes joints and frames together (online prediction)."""
    if observation.motor == "none" or observation.frames != observation.motor:
        raise UserError(
            "online prediction observes joints and frames together, a step at a time: give --observe "
            "only (not --observe-frames, not 'none')"
        )
