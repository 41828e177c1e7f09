"""Predicting the rest of a motion: predictors with one surface, ours and the peers'.

Every predictor is fitted once on the fitted demonstrations and then predicts whole
sequences from their observed steps (:mod:`primspace.predict.base`):

* :class:`SelectedPredictor`: the default (``auto``), the candidate below with the lowest K-fold
  error on the fitted demonstrations for the task asked (:mod:`primspace.predict.selection`);
* :class:`MixturePredictor`: the posterior over the run's fitted codes, offline and online
  (no gradient);
* :class:`GradientPredictor`: gradient inference of the code from a start, offline and online;
* :class:`PriorPredictor`: a prior in code space per primitive (a label or a cluster of the fitted
  codes), drawn, decoded and conditioned on the observed steps, given the primitive or weighted by
  the posterior over primitives (:mod:`primspace.predict.prior`), offline and online;
* :class:`PriorMapPredictor` and :class:`EncoderPredictor`: the code under that prior by MAP through
  the frozen decoder, or by an encoder trained on the decoder's own samples (measured: neither
  beats the prior's conditioning on the simulated presets; docs/predict.md); ``predict(...,
  primitive="push")`` asks it for every motion as that primitive (:mod:`primspace.predict.posterior`);
* the peers (:mod:`primspace.predict.peers`): ProMP conditioning, nearest neighbour, mean motion.

:data:`REGISTRY` names them all (:mod:`primspace.predict.registry`); :func:`predict` runs one on a data set and scores it (:func:`~primspace.predict.metrics.unobserved_mse`,
the one error); :func:`grid_predictions` runs the experiment's rows on one split.
"""

from primspace.predict.api import (
    AUTO,
    DEFAULT_PREDICTOR,
    MIXTURE,
    PREDICT_STARTS,
    Prediction,
    PredictRequest,
    fit_predictor,
    make_predictor,
    predict,
    run_predictor,
)
from primspace.predict.base import Forecast, MotionPredictor, Predictor, observation_rule, observed_mask
from primspace.predict.candidates import CodeMixture, continuity_correction
from primspace.predict.encoder import EncoderPredictor
from primspace.predict.gradient import DEFAULT_PREDICT_EPOCHS, GradientPredictor
from primspace.predict.grid import grid_predictions
from primspace.predict.metrics import finite_mean, frame_errors, observed_prefix, unobserved_mse
from primspace.predict.mixture import MixturePredictor, code_mixture
from primspace.predict.peers import MeanMotionPeer, NearestPeer, ProMPPeer, best_noise
from primspace.predict.posterior import POSTERIOR_FRACTIONS, posterior_by_fraction
from primspace.predict.prior import PRIOR, PriorPredictor
from primspace.predict.prior_map import PriorMapPredictor
from primspace.predict.registry import REGISTRY, PredictorSpec
from primspace.predict.selection import SelectedPredictor
from primspace.predict.stream import OnlineResult

__all__ = [
    "Predictor",
    "MotionPredictor",
    "PredictRequest",
    "REGISTRY",
    "PredictorSpec",
    "OnlineResult",
    "Forecast",
    "observed_mask",
    "observation_rule",
    "Prediction",
    "predict",
    "make_predictor",
    "fit_predictor",
    "run_predictor",
    "grid_predictions",
    "MixturePredictor",
    "SelectedPredictor",
    "AUTO",
    "GradientPredictor",
    "CodeMixture",
    "code_mixture",
    "continuity_correction",
    "PriorPredictor",
    "PRIOR",
    "posterior_by_fraction",
    "PriorMapPredictor",
    "EncoderPredictor",
    "POSTERIOR_FRACTIONS",
    "ProMPPeer",
    "NearestPeer",
    "MeanMotionPeer",
    "best_noise",
    "unobserved_mse",
    "frame_errors",
    "finite_mean",
    "observed_prefix",
    "MIXTURE",
    "PREDICT_STARTS",
    "DEFAULT_PREDICTOR",
    "DEFAULT_PREDICT_EPOCHS",
]
