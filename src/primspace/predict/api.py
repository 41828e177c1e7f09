"""Predict the rest of a motion from what has been seen so far (issue 25; docs/predict.md).

The paper frames its model as predictive coding: "Predicted information is compared with
the real one and internal state is corrected based on the error" (paper, *Background*).
:func:`predict` does this offline: the code of each new sample is inferred with θ frozen
from its *observed* entries only (:func:`primspace.train.infer` with ``observe`` /
``observe_frames``, :mod:`primspace.train.observe`), and the decoder's whole sequence
``d(θ, z)`` is the prediction: the observed part reproduced, the rest predicted. Each way
of finding that code is a predictor (:mod:`primspace.predict.base`): :func:`predict` builds
the one named by ``init`` (:func:`make_predictor`), fits it on the run's fitted
demonstrations and runs it on a data set. The default is the best we have measured, the
mixture over the fitted codes (:mod:`primspace.predict.mixture`; docs/predict.md).

The measure of a prediction is its error on the steps that were **not** observed:

* motor: the mean squared error over the unobserved valid steps and all joints, in the
  scaled units of the run (joints scaled to [-1, 1] over the fitted data), the one
  definition :func:`primspace.predict.metrics.unobserved_mse` shared with the peers (ProMP, nearest
  neighbour, mean motion), so the table of docs/predict.md compares like with like;
* frames: the mean squared error of the unobserved valid frames in [0, 1] intensity and
  the PSNR ``10 log10(1 / MSE)`` (dB).

A :class:`Prediction` becomes a :class:`~primspace.data.MotionDataset` of the same schema
(physical units, labels and lengths kept: :meth:`Prediction.to_dataset`), so ``show``,
``animate``, ``info``, ``cluster`` and the simulator's judge read it unchanged.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field

import numpy as np

from primspace.data import MotionDataset
from primspace.data.steps import valid_steps
from primspace.utils.errors import UserError
from primspace.model.latent import INFER_STARTS
from primspace.predict.base import Predictor
from primspace.predict.candidates import continuity_correction
from primspace.predict.gradient import DEFAULT_PREDICT_EPOCHS, GradientPredictor
from primspace.predict.metrics import frame_errors, unobserved_mse
from primspace.predict.mixture import MIXTURE, MixturePredictor
from primspace.predict.posterior import prior_details
from primspace.predict.primitives import PRIMITIVE_SOURCES
from primspace.predict.prior import PRIOR, PriorPredictor
from primspace.train.api import as_run, reconstruct
from primspace.train.checks import select
from primspace.train.observe import Observation
from primspace.train.run import TrainedRun
from primspace.train.starts import STARTS_FROM_FITTED, fitted_samples

__all__ = [
    "Prediction",
    "predict",
    "make_predictor",
    "fit_predictor",
    "predictor_for",
    "DEFAULT_PREDICT_EPOCHS",
    "MIXTURE",
    "PRIOR",
    "PREDICT_STARTS",
    "DEFAULT_PREDICTOR",
]

#: What :func:`predict` accepts as ``init``: the gradient starts, the mixture and the prior.
PREDICT_STARTS = INFER_STARTS + (MIXTURE, PRIOR)
#: The predictor of :func:`predict` and ``primspace predict`` when none is named: the best we
#: have measured (docs/predict.md: below every gradient start on the demo, LASA and real recordings).
DEFAULT_PREDICTOR = MIXTURE


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


def make_predictor(
    run,
    init: str = DEFAULT_PREDICTOR,
    *,
    epochs: int = DEFAULT_PREDICT_EPOCHS,
    continuity: bool = True,
    condition: bool = True,
    progress: bool | None = None,
    primitive=None,
    primitives: str = "labels",
    n_clusters: int | None = None,
    prior_samples: int | None = None,
    **overrides,
) -> Predictor:
    """The predictor named ``init``: ``mixture`` (:class:`~primspace.predict.mixture.MixturePredictor`,
    ``condition``), ``prior`` (:class:`~primspace.predict.prior.PriorPredictor`: ``primitive``,
    ``primitives``, ``n_clusters``, ``prior_samples`` draws per primitive, ``seed`` of ``overrides``)
    or a gradient start (:class:`~primspace.predict.gradient.GradientPredictor`, ``epochs`` and
    train-config ``overrides``); each with the continuity correction when ``continuity``. A
    primitive (or ``primitives``, ``n_clusters``) asks for the prior (:func:`predictor_for`)."""
    init = predictor_for(init, primitive=primitive, primitives=primitives, n_clusters=n_clusters)
    if init not in PREDICT_STARTS:
        raise UserError(f"unknown start {init!r}: choose one of {', '.join(PREDICT_STARTS)}")
    if init == MIXTURE:
        return MixturePredictor(run, condition=condition, continuity=continuity, progress=progress)
    if init == PRIOR:
        extra = {} if prior_samples is None else {"n_samples": prior_samples}
        return PriorPredictor(
            run,
            primitive=primitive,
            primitives=primitives,
            n_clusters=n_clusters,
            continuity=continuity,
            random_state=overrides.get("seed"),
            progress=progress,
            **extra,
        )
    return GradientPredictor(
        run, init, epochs=epochs, continuity=continuity, overrides=overrides or None, progress=progress
    )


def predictor_for(init, *, primitive=None, primitives: str = "labels", n_clusters: int | None = None):
    """The predictor to build: ``init``, or ``prior`` when a primitive is asked for (``primitive``, or
    ``primitives`` other than ``labels``, or ``n_clusters``) and ``init`` is left at its default
    (None or :data:`DEFAULT_PREDICTOR`); one UserError when ``init`` names another predictor:
    only the prior takes a primitive."""
    if primitives not in PRIMITIVE_SOURCES:
        raise UserError(f"primitives must be one of {', '.join(PRIMITIVE_SOURCES)}, got {primitives!r}")
    asked = [name for name, value in (("primitive", primitive), ("n_clusters", n_clusters)) if value is not None]
    asked += ["primitives"] if primitives != "labels" else []
    if not asked:
        return init
    if init in (None, DEFAULT_PREDICTOR, PRIOR):
        return PRIOR
    raise UserError(
        f"only the prior predictor (init='prior') takes a primitive: init={init!r} does not (given {', '.join(asked)})"
    )


def fit_predictor(predictor: Predictor, run: TrainedRun, fitted_data: MotionDataset | None = None) -> Predictor:
    """``predictor`` fitted on ``run``'s fitted demonstrations (scaled, in its order), read from
    ``fitted_data`` (the data set it was fitted on) or the run's data file; a gradient start that
    does not read them is fitted without."""
    if isinstance(predictor, GradientPredictor) and (predictor.start or run.init) not in STARTS_FROM_FITTED:
        return predictor.fit(None)
    fitted = fitted_samples(run, fitted_data)
    lengths = fitted.valid_lengths
    if "label_names" in predictor.get_params() and predictor.label_names is None:
        predictor.set_params(label_names=fitted.label_names)  # a primitive may be asked for by name
    return predictor.fit(
        run.scaler.transform(fitted.motor), fitted.labels, lengths, fitted.images if fitted.has_images else None
    )


def predict(
    run: TrainedRun | str | os.PathLike,
    dataset: MotionDataset,
    *,
    observe=0.25,
    observe_frames=None,
    init: str = DEFAULT_PREDICTOR,
    epochs: int = DEFAULT_PREDICT_EPOCHS,
    indices=None,
    fitted_data: MotionDataset | None = None,
    frames: bool = True,
    continuity: bool = True,
    condition: bool = True,
    online: int | None = None,
    progress: bool | None = None,
    primitive=None,
    primitives: str = "labels",
    n_clusters: int | None = None,
    prior_samples: int | None = None,
    **overrides,
) -> Prediction:
    """Predict the rest of each motion of ``dataset`` from its observed part, and score it.

    Parameters
    ----------
    run : TrainedRun or path-like
        A fitted run (θ is frozen; the run is not changed).
    dataset : MotionDataset
        The samples to predict: their observed part is read, the rest is the answer the
        errors are measured against.
    observe, observe_frames
        What is observed, as in :func:`primspace.train.infer`: a fraction in (0, 1] of
        each sample's valid steps, a number of steps, ``"none"``; for frames also
        ``"first"``. ``observe_frames=None`` follows ``observe``.
    init : str
        The predictor (:func:`make_predictor`): ``mixture`` (default, the best we have: no
        gradient steps, the posterior over the fitted codes' mixture or its ensemble
        conditioned on the observed entries, whichever the leave-one-out prediction of the
        fitted demonstrations prefers), or a start of gradient inference (``zero``,
        ``random``, ``projection``, ``pca``, ``calibrated``, ``nearest``) followed by
        ``epochs`` of inference on the observed entries, or ``prior``
        (:class:`~primspace.predict.prior.PriorPredictor`: a prior in code space per primitive,
        conditioned on the observed entries; without ``primitive``, weighted by the posterior
        over primitives).
    epochs : int
        Inference epochs of a gradient start (0: the start decoded as it is).
    indices : array-like of int, optional
        Samples of ``dataset`` to predict (default: all).
    fitted_data : MotionDataset, optional
        The data set ``run`` was fitted on (default: the run's data file), read by the
        mixture, ``nearest`` and ``calibrated``.
    frames : bool
        Decode the frames too (runs with an image head).
    continuity : bool
        Remove the jump at the last observed step
        (:func:`~primspace.predict.candidates.continuity_correction`; default on).
    condition : bool
        ``mixture`` only: let the leave-one-out choice take the ensemble conditioning.
    online : int, optional
        Predictive coding a step at a time: the steps arrive one by one (``online``
        gradient iterations after each, warm-started; the mixture's posterior needs none
        and updates in closed form, without the ensemble conditioning); the prediction is
        the one after the last observed step (the same number of steps for every sample:
        the largest observed prefix). ``details`` then holds the latency per step and the
        error of the remaining steps after each.
    progress : bool, optional
    primitive : str or int, optional
        The primitive of every motion, a name (a label name of the fitted data, ``"push"``) or an
        id (``Prediction.details["prior"]["primitives"]`` lists them): the prior predictor, whatever
        ``init`` unless it names another predictor (then one UserError: only the prior takes a
        primitive). None: the prior weighs its primitives by their posterior.
    primitives : {"labels", "clusters"}
        The prior's primitives: the fitted data's labels, or clusters of the fitted codes (asks for
        the prior as ``primitive`` does).
    n_clusters : int, optional
        The number of clusters with ``primitives="clusters"`` (default: the number of labels).
    prior_samples : int, optional
        Codes the prior draws and decodes per primitive (default 2000).
    **overrides
        Train-config overrides of a gradient inference (``latent_lr``, ``batch_size``, ``seed`` ...);
        the prior reads ``seed``.

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
    parent = as_run(run)
    if observe is None and observe_frames is None:
        raise UserError(
            "predict needs observe= (a fraction in (0, 1], a number of steps or 'none'): "
            "with everything observed there is nothing to predict"
        )
    observation = Observation.build(observe, observe_frames)
    asked = dict(primitive=primitive, primitives=primitives, n_clusters=n_clusters)
    predictor = make_predictor(
        parent,
        predictor_for(init, **asked) or parent.init,
        epochs=epochs,
        continuity=continuity,
        condition=condition,
        progress=progress,
        prior_samples=prior_samples,
        **asked,
        **overrides,
    )
    data, idx = select(dataset, indices)
    head = parent.model_config.has_images
    observation.check(data, use_images=head and data.has_images, has_image_head=head)  # before any fitting
    motor_observed, frames_observed = observation.masks(data.valid_lengths, data.length)
    fitted = None
    if online is not None:
        codes, scaled, details = _online(predictor, parent, data, observation, online, fitted_data, progress)
    else:
        fitted = fit_predictor(predictor, parent, fitted_data)
        forecast = run_predictor(fitted, parent, data, observation)
        codes, scaled, details = forecast.codes, forecast.motor, forecast.details
        if isinstance(fitted, PriorPredictor):
            details = prior_details(fitted, forecast.details, data.labels)
    scaled = np.clip(scaled, -1.0, 1.0)  # within each joint's recorded range (the scaler maps it onto [-1, 1])
    predicted_frames = None
    if frames and parent.model_config.has_images:
        predicted_frames = reconstruct(parent, codes, images=True)[1]
    lengths = data.valid_lengths
    errors = {"motor_mse": unobserved_mse(scaled, parent.scaler.transform(data.motor), motor_observed, lengths)}
    if predicted_frames is not None and data.has_images:
        errors["vision_mse"], errors["psnr"] = frame_errors(
            predicted_frames, data.load_images().images, frames_observed, valid_steps(lengths, data.length)
        )
    epochs_run = epochs if isinstance(predictor, GradientPredictor) and online is None else 0
    return Prediction(
        codes=codes,
        motor=parent.scaler.inverse_transform(scaled).astype(np.float32),
        frames=predicted_frames,
        motor_observed=motor_observed,
        frames_observed=frames_observed,
        indices=idx,
        errors=errors,
        observation=observation.to_dict(),
        init=_predictor_name(predictor, parent),
        epochs=int(epochs_run),
        continuity=continuity,
        details=details,
        predictor=fitted,
    )


def _predictor_name(predictor: Predictor, run: TrainedRun) -> str:
    """The name ``Prediction.init`` records: the gradient start, ``prior`` or ``mixture``."""
    if isinstance(predictor, GradientPredictor):
        return getattr(predictor, "start_", None) or predictor.start or run.init
    return PRIOR if isinstance(predictor, PriorPredictor) else MIXTURE


def run_predictor(predictor: Predictor, run: TrainedRun, data: MotionDataset, observation: Observation):
    """A fitted predictor's :class:`~primspace.predict.base.Forecast` of ``data`` under ``observation``
    (scaled units; a gradient predictor reads ``data`` itself, its frames lazily)."""
    scaled = run.scaler.transform(data.motor)
    extra = {"data": data} if isinstance(predictor, GradientPredictor) else {}
    frames = data.images if data.has_images and not extra else None
    return predictor.forecast(scaled, observation, data.labels, data.valid_lengths, frames, **extra)


def _online(
    predictor: Predictor,
    parent: TrainedRun,
    data: MotionDataset,
    observation: Observation,
    iterations: int,
    fitted_data,
    progress,
) -> tuple:
    """Codes, scaled motor and details after the observed steps arrived one at a time."""
    if observation.motor == "none" or observation.frames != observation.motor:
        raise UserError(
            "online prediction observes joints and frames together, a step at a time: give --observe "
            "only (not --observe-frames, not 'none')"
        )
    seen = int(observation.masks(data.valid_lengths, data.length)[0].sum(axis=1).max())
    predictor = fit_predictor(predictor, parent, fitted_data)
    scaled_truth = parent.scaler.transform(data.motor)
    if isinstance(predictor, (MixturePredictor, PriorPredictor)):  # no gradient: updated a step at a time
        result = predictor.predict_online(scaled_truth, data.valid_lengths, prediction_after=seen, progress=progress)
        codes = result.codes[:, result.column(seen)]
        scaled = parent.scaler.transform(result.prediction)
    else:
        result = predictor.predict_online(
            scaled_truth, data.lengths, iterations=iterations, data=data, progress=progress
        )
        codes = result.codes[:, result.column(seen)]
        scaled = parent.scaler.transform(reconstruct(parent, codes, images=False)[0])
        if predictor.continuity:
            observed = observation.masks(data.valid_lengths, data.length)[0]
            scaled = continuity_correction(scaled, scaled_truth, observed, valid_steps(data.valid_lengths, data.length))
    details = {
        "online": {
            "iterations": int(getattr(result, "iterations", 0)),
            "steps_observed": seen,
            "latency_ms_mean": 1e3 * result.latency_mean,
            "latency_ms_p95": 1e3 * result.latency_p95,
            "remaining_error": [None if not np.isfinite(e) else float(e) for e in result.mean_error],
        }
    }
    if isinstance(predictor, PriorPredictor):
        details["prior"] = predictor.summary()
        details["primitive"] = details["prior"]["primitive"]
    return codes.astype(np.float32), scaled, details
