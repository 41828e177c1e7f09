"""The primitive as an input: what a prediction by the prior says of its primitives.

:func:`~primspace.predict.predict` with the prior (:class:`~primspace.predict.prior.PriorPredictor`)
either is told the primitive of every motion (``primitive="push"``) or weighs its primitives by
their posterior given the observed steps. :func:`prior_details` turns the prior's forecast into
what ``Prediction.details`` and ``result.json`` hold (the posterior per sample with the
primitives' names, each sample's top primitive and its top-1 accuracy against the labels);
:func:`posterior_by_fraction` asks the fitted prior again after each observed fraction, for
``posterior.png`` (:func:`primspace.plots.plot_posterior`).
"""

from __future__ import annotations

import numpy as np

from primspace.data import MotionDataset
from primspace.predict.primitives import top1_accuracy
from primspace.predict.prior import PriorPredictor
from primspace.train.observe import Observation
from primspace.utils.errors import UserError

__all__ = ["prior_details", "posterior_by_fraction", "top1_accuracy", "POSTERIOR_FRACTIONS"]

#: The observed fractions of ``posterior.png`` (:func:`posterior_by_fraction`).
POSTERIOR_FRACTIONS = tuple(round(0.1 * k, 1) for k in range(1, 11))


def prior_details(predictor: PriorPredictor, details: dict, labels=None) -> dict:
    """``Prediction.details`` of the prior's forecast (``details``):
    :meth:`~primspace.predict.prior.PriorPredictor.describe`."""
    return predictor.describe(details, labels)


def posterior_by_fraction(predictor, data: MotionDataset, fractions=POSTERIOR_FRACTIONS) -> np.ndarray:
    """The posterior over primitives (F, n, P) of the motions of ``data`` after each observed
    fraction of ``fractions`` of their valid steps: the fitted prior ``predictor`` (``Prediction.predictor``)
    asked again without a primitive, not fitted again (its noise and temperature are chosen
    once per fraction, as for any prediction)."""
    if not isinstance(predictor, PriorPredictor) or not hasattr(predictor, "primitives_"):
        raise UserError("the posterior over primitives is the fitted prior predictor's (init='prior')")
    asked = predictor.asked()
    scaled = predictor.run_.scaler.transform(data.motor)
    return np.stack(
        [
            np.asarray(asked.forecast(scaled, Observation.build(f), None, data.valid_lengths).details["posterior"])
            for f in fractions
        ]
    )
