"""The primitive as an input (issue 39): what a prediction by the prior says of its primitives.

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
from primspace.utils.errors import UserError
from primspace.predict.prior import PriorPredictor
from primspace.train.observe import Observation

__all__ = ["prior_details", "posterior_by_fraction", "top1_accuracy", "POSTERIOR_FRACTIONS"]

#: The observed fractions of ``posterior.png`` (:func:`posterior_by_fraction`).
POSTERIOR_FRACTIONS = tuple(round(0.1 * k, 1) for k in range(1, 11))


def top1_accuracy(posterior, stands_for, labels) -> float | None:
    """Share of the labelled samples (``labels`` >= 0) whose most probable primitive (``posterior``
    (n, P)) stands for their label (``stands_for``: the label of each primitive, None for none);
    None without labels."""
    if labels is None:
        return None
    labels = np.asarray(labels)
    scored = labels >= 0
    if not scored.any():
        return None
    table = np.array([-2 if v is None else int(v) for v in stands_for])
    top = np.asarray(posterior).argmax(axis=1)
    return float(np.mean(table[top[scored]] == labels[scored]))


def prior_details(predictor: PriorPredictor, details: dict, labels=None) -> dict:
    """``Prediction.details`` of the prior's forecast (``details``): its ``prior`` summary and the
    ``primitive`` asked (None: none); with none asked (nor each motion's label), the ``posterior``
    (n, P) over ``primitives`` (their names), each sample's ``top_primitive`` and
    ``posterior_accuracy`` (:func:`top1_accuracy` against ``labels``)."""
    summary = details["prior"]
    out = {"prior": summary, "primitive": summary["primitive"]}
    if summary["primitive"] is not None or predictor.given:
        return out
    names = list(summary["primitives"]["names"])
    posterior = np.asarray(details["posterior"], dtype=np.float64)
    return {
        **out,
        "primitives": names,
        "posterior": posterior.tolist(),
        "top_primitive": [names[k] for k in posterior.argmax(axis=1)],
        "posterior_accuracy": top1_accuracy(posterior, summary["primitives"]["labels"], labels),
    }


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
