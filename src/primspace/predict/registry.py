"""Every predictor by name, with what it needs: the one place that dispatches on the kind of predictor.

:data:`REGISTRY` maps a name to a :class:`PredictorSpec`: the class, whether it is built on a
trained run (primspace's own) or not (the peers), whether it predicts online, whether
``primspace predict`` offers it, and how a :class:`~primspace.predict.request.PredictRequest`
builds it. :func:`make_predictor` builds the predictor a request names (a gradient start names
the gradient predictor), :func:`fit_predictor` fits any predictor on a run's fitted
demonstrations and :func:`run_predictor` runs it on a data set: what differs between
predictors is asked of the predictor itself (:class:`~primspace.predict.base.Predictor`'s
``reads_fitted``, ``reads_dataset``, ``name``, ``describe``), never of its type.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from primspace.data import MotionDataset
from primspace.model.latent import INFER_STARTS
from primspace.predict.base import Forecast, Predictor
from primspace.predict.encoder import ENCODER, EncoderPredictor
from primspace.predict.gaussian_peers import RawGaussianPeer, TunedProMPPeer
from primspace.predict.gradient import GradientPredictor
from primspace.predict.mixture import MIXTURE, MixturePredictor
from primspace.predict.peers import MeanMotionPeer, NearestPeer, ProMPPeer
from primspace.predict.primitives import PRIMITIVE_SOURCES
from primspace.predict.prior import PRIOR, PriorPredictor
from primspace.predict.prior_map import PriorMapPredictor
from primspace.predict.request import PredictRequest
from primspace.predict.selection import AUTO, SelectedPredictor
from primspace.train.observe import Observation
from primspace.train.run import TrainedRun
from primspace.train.starts import fitted_samples
from primspace.utils.errors import UserError

__all__ = [
    "PredictorSpec",
    "REGISTRY",
    "GRADIENT",
    "PRIOR_MAP",
    "PREDICT_STARTS",
    "DEFAULT_PREDICTOR",
    "make_predictor",
    "fit_predictor",
    "run_predictor",
    "predictor_for",
    "model_share",
    "built_on_run",
]

#: The registry's name of gradient inference from a start (the starts name it in a request).
GRADIENT = "gradient"
#: The registry's name of the MAP code under the prior.
PRIOR_MAP = "prior_map"
#: The predictor of :func:`~primspace.predict.predict` and ``primspace predict`` when none is named: the
#: candidate with the lowest K-fold error on the fitted demonstrations for the task asked
#: (:class:`~primspace.predict.selection.SelectedPredictor`; docs/predict.md, *How the predictor is chosen*).
DEFAULT_PREDICTOR = AUTO


@dataclass(frozen=True)
class PredictorSpec:
    """What the registry knows of a predictor.

    Attributes
    ----------
    name : str
    cls : type
        The :class:`~primspace.predict.base.Predictor` subclass.
    needs_run : bool
        Built on a trained run (``cls(run, ...)``; primspace's own) or not (the peers, ``cls(...)``).
    online : bool
        It predicts online (:meth:`~primspace.predict.base.Predictor.predict_online`).
    command : bool
        ``primspace predict`` and :func:`~primspace.predict.predict` offer it.
    build : callable
        ``build(run, request)``: the predictor a :class:`~primspace.predict.request.PredictRequest` asks for.
    """

    name: str
    cls: type
    needs_run: bool
    online: bool
    command: bool
    build: Callable[[TrainedRun | None, PredictRequest], Predictor]


def _mixture(run, request: PredictRequest) -> Predictor:
    if request.primitive is not None:  # restricted to the primitive's label: no ensemble conditioning
        return MixturePredictor(
            run, condition=False, continuity=request.continuity, primitive=request.primitive, progress=request.progress
        )
    return MixturePredictor(run, condition=request.condition, continuity=request.continuity, progress=request.progress)


def _auto(run, request: PredictRequest) -> Predictor:
    return SelectedPredictor(
        run,
        primitive=request.primitive,
        primitives=request.primitives,
        n_clusters=request.n_clusters,
        prior_samples=request.prior_samples,
        condition=request.condition,
        continuity=request.continuity,
        random_state=request.overrides.get("seed"),
        reuse=request.reuse,
        progress=request.progress,
    )


def _prior(run, request: PredictRequest) -> Predictor:
    extra = {} if request.prior_samples is None else {"n_samples": request.prior_samples}
    return PriorPredictor(
        run,
        primitive=request.primitive,
        primitives=request.primitives,
        n_clusters=request.n_clusters,
        continuity=request.continuity,
        random_state=request.overrides.get("seed"),
        progress=request.progress,
        **extra,
    )


def _gradient(run, request: PredictRequest) -> Predictor:
    start = None if request.init == GRADIENT else request.init
    return GradientPredictor(
        run,
        start,
        epochs=request.epochs,
        continuity=request.continuity,
        overrides=dict(request.overrides) or None,
        progress=request.progress,
        iterations=1 if request.online is None else request.online,
    )


def _with_run(cls):
    def build(run, request: PredictRequest) -> Predictor:
        return cls(run, continuity=request.continuity)

    return build


def _peer(cls):
    def build(run, request: PredictRequest) -> Predictor:
        return cls()

    return build


REGISTRY: dict[str, PredictorSpec] = {
    spec.name: spec
    for spec in (
        PredictorSpec(AUTO, SelectedPredictor, True, True, True, _auto),
        PredictorSpec(MIXTURE, MixturePredictor, True, True, True, _mixture),
        PredictorSpec(GRADIENT, GradientPredictor, True, True, True, _gradient),
        PredictorSpec(PRIOR, PriorPredictor, True, True, True, _prior),
        PredictorSpec(PRIOR_MAP, PriorMapPredictor, True, False, False, _with_run(PriorMapPredictor)),
        PredictorSpec(ENCODER, EncoderPredictor, True, True, False, _with_run(EncoderPredictor)),
        PredictorSpec(ProMPPeer.name, ProMPPeer, False, False, False, _peer(ProMPPeer)),
        PredictorSpec(NearestPeer.name, NearestPeer, False, False, False, _peer(NearestPeer)),
        PredictorSpec(MeanMotionPeer.name, MeanMotionPeer, False, False, False, _peer(MeanMotionPeer)),
        PredictorSpec(RawGaussianPeer.name, RawGaussianPeer, False, False, False, _peer(RawGaussianPeer)),
        PredictorSpec(TunedProMPPeer.name, TunedProMPPeer, False, False, False, _peer(TunedProMPPeer)),
    )
}


#: What :func:`~primspace.predict.predict` accepts as ``init``: the gradient starts, then the registered
#: predictors the command offers (auto, the mixture and the prior).
PREDICT_STARTS = INFER_STARTS + tuple(name for name, spec in REGISTRY.items() if spec.command and name != GRADIENT)


def spec_for(init: str) -> PredictorSpec:
    """The spec of ``init``: a registered name, or a gradient start (the gradient predictor)."""
    if init in INFER_STARTS:
        return REGISTRY[GRADIENT]
    if init not in REGISTRY:
        raise UserError(f"unknown predictor {init!r}: choose one of {', '.join(tuple(REGISTRY) + INFER_STARTS)}")
    return REGISTRY[init]


def make_predictor(
    run, init: str = DEFAULT_PREDICTOR, *, request: PredictRequest | None = None, **settings
) -> Predictor:
    """The predictor named ``init`` (a name of ``primspace predict``: :data:`PREDICT_STARTS`), built as
    ``request`` asks (default: a :class:`~primspace.predict.request.PredictRequest` of ``settings``:
    ``epochs``, ``continuity``, ``condition``, ``progress``, ``primitive``, ``primitives``, ``n_clusters``,
    ``prior_samples`` and train-config overrides). A primitive (or ``primitives``, ``n_clusters``) asks
    for the prior (:func:`predictor_for`)."""
    request = PredictRequest.of(init=init, **settings) if request is None else request
    init = predictor_for(
        request.init, primitive=request.primitive, primitives=request.primitives, n_clusters=request.n_clusters
    )
    if init not in PREDICT_STARTS:
        raise UserError(f"unknown start {init!r}: choose one of {', '.join(PREDICT_STARTS)}")
    return spec_for(init).build(run, request.replace(init=init))


def predictor_for(init, *, primitive=None, primitives: str = "labels", n_clusters: int | None = None):
    """The predictor to build: ``init``, or ``auto`` when a primitive is asked for (``primitive``, or
    ``primitives`` other than ``labels``, or ``n_clusters``) and ``init`` is None; one UserError when
    ``init`` names a predictor that takes no primitive: auto and the prior take one, the mixture
    ``primitive`` alone (restricted to that label of the fitted data)."""
    if primitives not in PRIMITIVE_SOURCES:
        raise UserError(f"primitives must be one of {', '.join(PRIMITIVE_SOURCES)}, got {primitives!r}")
    asked = [name for name, value in (("primitive", primitive), ("n_clusters", n_clusters)) if value is not None]
    asked += ["primitives"] if primitives != "labels" else []
    if not asked:
        return init
    if init in (None, AUTO):
        return AUTO
    if init == PRIOR or (init == MIXTURE and asked == ["primitive"]):
        return init
    raise UserError(
        f"only auto, the prior (init='prior') and, given a primitive of the labels alone, the mixture take a "
        f"primitive: init={init!r} does not (given {', '.join(asked)})"
    )


def fit_predictor(predictor: Predictor, run: TrainedRun, fitted_data: MotionDataset | None = None) -> Predictor:
    """``predictor`` fitted on ``run``'s fitted demonstrations (scaled, in its order), read from
    ``fitted_data`` (the data set it was fitted on) or the run's data file; a predictor that does
    not read them (``reads_fitted``: a gradient start that does not) is fitted without."""
    if not predictor.reads_fitted(run):
        return predictor.fit(None)
    fitted = fitted_samples(run, fitted_data)
    lengths = fitted.valid_lengths
    if "label_names" in predictor.get_params() and predictor.label_names is None:
        predictor.set_params(label_names=fitted.label_names)  # a primitive may be asked for by name
    return predictor.fit(
        run.scaler.transform(fitted.motor), fitted.labels, lengths, fitted.images if fitted.has_images else None
    )


def run_predictor(predictor: Predictor, run: TrainedRun, data: MotionDataset, observation: Observation) -> Forecast:
    """A fitted predictor's :class:`~primspace.predict.base.Forecast` of ``data`` under ``observation``
    (scaled units; a predictor that ``reads_dataset`` reads ``data`` itself, its frames lazily)."""
    scaled = run.scaler.transform(data.motor)
    extra = {"data": data} if predictor.reads_dataset else {}
    frames = data.images if data.has_images and not extra else None
    return predictor.forecast(scaled, observation, data.labels, data.valid_lengths, frames, **extra)


def model_share(details: dict, built_on_run: bool) -> float:
    """The share of a prediction that comes through the run's decoder, for ``result.json`` and the tables:
    ``details["model_share"]`` where the predictor reports one (the prior: the weight of its decoded draws,
    ``1 - blend``); else 1.0 for a predictor ``built_on_run`` (it decodes codes: :func:`built_on_run`) and 0.0
    for a peer (it never reads the run)."""
    share = details.get("model_share")
    if share is not None:
        return float(share)
    return 1.0 if built_on_run else 0.0


def built_on_run(predictor: Predictor) -> bool:
    """Whether ``predictor`` is built on a trained run (primspace's own; the peers are not)."""
    return "run" in predictor.get_params()
