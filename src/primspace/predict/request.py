"""What a prediction is asked to do, in one value (:class:`PredictRequest`).

:func:`~primspace.predict.predict` takes its settings as keywords or as a request; the
registry builds the predictor a request names (:func:`~primspace.predict.registry.make_predictor`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from primspace.data import MotionDataset
from primspace.predict.gradient import DEFAULT_PREDICT_EPOCHS
from primspace.predict.selection import AUTO
from primspace.utils.errors import UserError

__all__ = ["PredictRequest"]


@dataclass(frozen=True)
class PredictRequest:
    """The settings of a prediction.

    Attributes
    ----------
    observe, observe_frames
        What is observed, as in :func:`primspace.train.infer`: a fraction in (0, 1] of
        each sample's valid steps, a number of steps, ``"none"``; for frames also
        ``"first"``. ``observe_frames=None`` follows ``observe``.
    init : str or None
        The predictor (:func:`~primspace.predict.registry.make_predictor`): ``auto`` (default: the
        candidate with the lowest K-fold error on the fitted demonstrations for the task asked,
        :class:`~primspace.predict.selection.SelectedPredictor`), ``mixture`` (no gradient steps, the
        posterior over the fitted codes' mixture or its ensemble conditioned on the observed entries,
        whichever the leave-one-out prediction of the fitted demonstrations prefers; given a
        ``primitive``, restricted to that label), or a start of gradient inference (``zero``, ``random``,
        ``projection``, ``pca``, ``calibrated``, ``nearest``) followed by ``epochs`` of inference on
        the observed entries, or ``prior`` (:class:`~primspace.predict.prior.PriorPredictor`: a prior
        in code space per primitive, conditioned on the observed entries; without ``primitive``,
        weighted by the posterior over primitives). None: the run's init.
    epochs : int
        Inference epochs of a gradient start (0: the start decoded as it is).
    indices : array-like of int, optional
        Samples of the data set to predict (default: all).
    fitted_data : MotionDataset, optional
        The data set the run was fitted on (default: the run's data file), read by the
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
        id (``Prediction.details["prior"]["primitives"]`` lists them), read by ``auto`` (its candidates
        given the primitive), the prior and the mixture (restricted to that label); another ``init``
        is one UserError. None: no primitive given.
    primitives : {"labels", "clusters"}
        The prior's primitives: the fitted data's labels, or clusters of the fitted codes (asks for
        the prior as ``primitive`` does).
    n_clusters : int, optional
        The number of clusters with ``primitives="clusters"`` (default: the number of labels).
    prior_samples : int, optional
        Codes the prior draws and decodes per primitive (default 2000).
    reuse : bool
        ``auto``: keep its choice in the run folder and read it from there on a later call with the
        same fitted data, task and settings (:mod:`~primspace.predict.selection_cache`).
    overrides : dict
        Train-config overrides of a gradient inference (``latent_lr``, ``batch_size``, ``seed`` ...);
        the prior reads ``seed``.
    """

    observe: object = 0.25
    observe_frames: object = None
    init: str | None = AUTO
    epochs: int = DEFAULT_PREDICT_EPOCHS
    indices: object = None
    fitted_data: MotionDataset | None = None
    frames: bool = True
    continuity: bool = True
    condition: bool = True
    online: int | None = None
    progress: bool | None = None
    primitive: object = None
    primitives: str = "labels"
    n_clusters: int | None = None
    prior_samples: int | None = None
    reuse: bool = True
    overrides: dict = field(default_factory=dict)

    @classmethod
    def of(cls, **settings) -> PredictRequest:
        """A request of keyword ``settings``: the fields by name, the rest train-config overrides."""
        names = {f.name for f in dataclasses.fields(cls)} - {"overrides"}
        overrides = {k: v for k, v in settings.items() if k not in names}
        if "overrides" in settings:
            raise UserError("pass train-config overrides as keywords, not as overrides=")
        return cls(**{k: v for k, v in settings.items() if k in names}, overrides=overrides)

    def replace(self, **changes) -> PredictRequest:
        """This request with ``changes``."""
        return dataclasses.replace(self, **changes)
