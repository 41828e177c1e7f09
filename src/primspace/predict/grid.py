"""The rows of the prediction experiment on one split: ours and the peers, one loop.

:func:`grid_predictors` builds every row as a :class:`~primspace.predict.base.Predictor`
(primspace's gradient starts, the mixture's variants sharing one set of decoded candidates,
the mixture given the labels as a diagnostic, and the peers: ProMP given the labels and one
for all, the nearest neighbour, the mean motion given the labels, and the Gaussian peers of
:mod:`~primspace.predict.gaussian_peers`: the ProMP with its basis count, ridge and noise tuned
and the Gaussian over the raw trajectories, each given the labels and one for all) and fits each
once on the run's fitted demonstrations; :func:`grid_forecasts` runs them all on the same samples
under one observation rule. The first two ProMP rows' observation noise is chosen on the answer
(:func:`~primspace.predict.peers.best_noise`: flattering them), as docs/predict.md says; the
Gaussian peers' settings are chosen by K-fold prediction of the fitted demonstrations, as the
prior's are.
"""

from __future__ import annotations

import numpy as np

from primspace.data import MotionDataset
from primspace.predict.api import predict
from primspace.predict.base import Forecast, Predictor
from primspace.predict.encoder import EncoderPredictor
from primspace.predict.gaussian_peers import RawGaussianPeer, TunedProMPPeer
from primspace.predict.metrics import finite_mean, unobserved_mse
from primspace.predict.mixture import MIXTURE, MixturePredictor, code_mixture
from primspace.predict.peers import MeanMotionPeer, NearestPeer, ProMPPeer, best_noise
from primspace.predict.posterior import top1_accuracy
from primspace.predict.prior import PriorPredictor
from primspace.predict.prior_map import PriorMapPredictor
from primspace.predict.registry import fit_predictor, make_predictor, run_predictor
from primspace.predict.selection import AUTO, SelectedPredictor
from primspace.train.observe import Observation
from primspace.train.run import TrainedRun
from primspace.train.starts import fitted_samples
from primspace.utils.errors import UserError

__all__ = [
    "grid_predictors",
    "grid_forecasts",
    "grid_predictions",
    "PEERS",
    "NOISE_ON_THE_ANSWER",
    "POSTERIOR_MEAN",
    "LABELS_DIAGNOSTIC",
    "MIXTURE_ROWS",
    "PRIOR_ROWS",
    "PRIOR_SETTINGS",
    "GIVEN_ROWS",
    "TUNED_PEERS",
    "PEER_SETTINGS",
    "posterior_accuracy",
    "AUTO_ROWS",
]

#: The Gaussian peers' rows, their settings chosen on the fitted demonstrations: (row, class, given the labels).
TUNED_PEERS = (
    ("promp tuned (labels)", TunedProMPPeer, True),
    ("promp tuned (one for all)", TunedProMPPeer, False),
    ("raw gaussian (labels)", RawGaussianPeer, True),
    ("raw gaussian", RawGaussianPeer, False),
)
#: The peers' rows (labels: the peer is given the test sample's primitive).
PEERS = ("promp (labels)", "promp (one for all)", "nearest neighbour", "mean motion (labels)") + tuple(
    row for row, _, _ in TUNED_PEERS
)
#: The Gaussian peers' kinds whose constructors ``peer_settings`` may set (their registry names).
PEER_SETTINGS = {TunedProMPPeer.name: TunedProMPPeer, RawGaussianPeer.name: RawGaussianPeer}
#: The rows whose observation noise is chosen on the answer (:func:`~primspace.predict.peers.best_noise`).
NOISE_ON_THE_ANSWER = ("promp (labels)", "promp (one for all)")
#: The mixture's posterior mean alone (no ensemble conditioning).
POSTERIOR_MEAN = "mixture (posterior mean)"
#: The mixture given the labels: candidates of the sample's own primitive only (a diagnostic).
LABELS_DIAGNOSTIC = "mixture (labels; diagnostic)"
#: The mixture's rows: (name, continuity correction, ensemble conditioning allowed, given the labels).
MIXTURE_ROWS = (
    (MIXTURE, True, True, False),
    (POSTERIOR_MEAN, True, False, False),
    ("mixture (no continuity)", False, True, False),
    (LABELS_DIAGNOSTIC, True, False, True),
)

#: The priors' rows: given the test motion's primitive (the fitted labels' priors);
#: not given, the posterior over the fitted labels' priors; not given and without any label, the
#: posterior over clusters of the fitted codes (as many as the labels).
PRIOR_ROWS = (
    "prior (labels)",
    "prior (posterior)",
    "prior (clusters)",
    "prior MAP (labels)",
    "encoder (labels)",
    "encoder (posterior)",
)
#: The rows of the start ``auto`` (the default of ``predict``, chosen by held-out evidence): without the
#: primitive, and given the test motion's primitive (with labels only); nothing kept in the run folder.
AUTO_ROWS = (AUTO, "auto (labels)")
#: The rows given the test motion's primitive (the task with the primitive given; the others are label-free
#: at test time).
GIVEN_ROWS = (
    "auto (labels)",
    "prior (labels)",
    "prior MAP (labels)",
    "encoder (labels)",
    "promp (labels)",
    "mean motion (labels)",
    LABELS_DIAGNOSTIC,
    "promp tuned (labels)",
    "raw gaussian (labels)",
)


#: The kinds of the priors' rows whose constructors ``prior_settings`` may set (the predictor classes).
PRIOR_SETTINGS = {"prior": PriorPredictor, "map": PriorMapPredictor, "encoder": EncoderPredictor}


def _check_prior_settings(prior_settings: dict | None) -> dict:
    """``prior_settings`` as ``{kind: {keyword: value}}`` (empty when None); unknown kinds refused."""
    settings = dict(prior_settings or {})
    unknown = sorted(set(settings) - set(PRIOR_SETTINGS))
    if unknown:
        raise UserError(f"prior_settings takes {', '.join(PRIOR_SETTINGS)}, got {', '.join(map(repr, unknown))}")
    return {kind: dict(settings.get(kind) or {}) for kind in PRIOR_SETTINGS}


def _prior_rows(run: TrainedRun, fitted: MotionDataset, prior_settings: dict | None = None) -> dict[str, Predictor]:
    """The priors' rows, fitted (the two over the fitted labels share their draws); ``prior_settings``:
    keywords of their constructors by kind (:data:`PRIOR_SETTINGS`; default: none, the predictors' own)."""
    kw = _check_prior_settings(prior_settings)
    names = fitted.label_names
    scaled, lengths = run.scaler.transform(fitted.motor), fitted.valid_lengths
    by_label = PriorPredictor(run, given=True, label_names=names, **kw["prior"]).fit(scaled, fitted.labels, lengths)
    clusters = PriorPredictor(run, primitives="clusters", label_names=names, **kw["prior"]).fit(
        scaled, fitted.labels, lengths
    )
    refined = PriorMapPredictor(run, prior=by_label, given=True, **kw["map"]).fit(scaled, fitted.labels, lengths)
    encoders = [
        EncoderPredictor(run, prior=by_label.asked(), given=g, **kw["encoder"]).fit(scaled, fitted.labels, lengths)
        for g in (True, False)
    ]
    return dict(zip(PRIOR_ROWS, (by_label, by_label.asked(), clusters, refined, *encoders)))


def posterior_accuracy(forecast: Forecast, labels) -> float | None:
    """Share of motions whose most probable primitive stands for their label (None without a posterior
    over the prior's primitives: the encoder given the primitive records its one-hot, not the prior)."""
    if "posterior" not in forecast.details or "prior" not in forecast.details:
        return None
    return top1_accuracy(forecast.details["posterior"], forecast.details["prior"]["primitives"]["labels"], labels)


def _tuned_peers(run: TrainedRun, has_labels: bool, peer_settings: dict | None) -> dict[str, Predictor]:
    """The Gaussian peers' rows (:data:`TUNED_PEERS`; those given the labels only when the fitted data has
    them), their folds seeded by the run's seed; ``peer_settings``: keywords by kind (:data:`PEER_SETTINGS`)."""
    settings = dict(peer_settings or {})
    unknown = sorted(set(settings) - set(PEER_SETTINGS))
    if unknown:
        raise UserError(f"peer_settings takes {', '.join(PEER_SETTINGS)}, got {', '.join(map(repr, unknown))}")
    seed = int(run.train_config.seed)
    return {
        row: cls(per_label=given, random_state=seed, **dict(settings.get(cls.name) or {}))
        for row, cls, given in TUNED_PEERS
        if has_labels or not given
    }


def grid_predictors(
    run: TrainedRun,
    fitted_data: MotionDataset,
    starts,
    epochs: int,
    *,
    prior_settings: dict | None = None,
    peer_settings: dict | None = None,
) -> dict[str, Predictor]:
    """Every row, fitted once on ``run``'s fitted demonstrations (read from ``fitted_data``, the
    data set it was fitted on): ``starts`` (gradient starts, ``mixture``: all its rows, and ``auto``:
    :data:`AUTO_ROWS`, its draws per primitive ``prior_settings["prior"]["n_samples"]``), then the
    peers, then (with labels) the priors' rows; ``prior_settings``: keywords of the priors' rows'
    constructors by kind, ``{"prior": {...}, "map": {...}, "encoder": {...}}`` (:data:`PRIOR_SETTINGS`;
    default: the predictors' own, as the experiment runs them; tests pass smaller ones); ``peer_settings``
    the same for the Gaussian peers (:data:`PEER_SETTINGS`)."""
    _check_prior_settings(prior_settings)
    fitted = fitted_samples(run, fitted_data)
    rows: dict[str, Predictor] = {}
    candidates = code_mixture(run) if MIXTURE in starts else None
    for start in starts:
        if start == AUTO:
            samples = _check_prior_settings(prior_settings)["prior"].get("n_samples")
            for name, given in zip(AUTO_ROWS, (False, True)):
                if not given or fitted.labels is not None:
                    rows[name] = SelectedPredictor(
                        run, given=given, prior_samples=samples, peer_settings=peer_settings, reuse=False
                    )
            continue
        if start != MIXTURE:
            rows[start] = make_predictor(run, start, epochs=epochs, continuity=True, progress=False)
            continue
        for name, continuity, condition, per_label in MIXTURE_ROWS:
            if per_label and fitted.labels is None:
                continue
            rows[name] = MixturePredictor(
                run, condition=condition, continuity=continuity, candidates=candidates, per_label=per_label
            )
    rows.update(
        {
            "promp (labels)": ProMPPeer(per_label=True),
            "promp (one for all)": ProMPPeer(per_label=False),
            "nearest neighbour": NearestPeer(),
            "mean motion (labels)": MeanMotionPeer(),
            **_tuned_peers(run, fitted.labels is not None, peer_settings),
        }
    )
    for predictor in rows.values():
        fit_predictor(predictor, run, fitted_data)
    if fitted.labels is not None:
        rows.update(_prior_rows(run, fitted, prior_settings))
    return rows


def grid_forecasts(rows: dict[str, Predictor], run: TrainedRun, test: MotionDataset, fraction: float) -> dict:
    """``{row: Forecast}`` of every fitted row on ``test`` with the first ``fraction`` of each
    motion observed (scaled units)."""
    rule = Observation.build(fraction)
    lengths = test.valid_lengths
    observed = rule.masks(lengths, test.length)[0]
    scaled = run.scaler.transform(test.motor)
    left = (np.arange(test.length)[None, :] < lengths[:, None]) & ~observed
    out = {}
    for name, predictor in rows.items():
        if name in NOISE_ON_THE_ANSWER and left.any():
            out[name] = Forecast(best_noise(predictor, scaled, observed, test.labels, lengths).predicted)
        else:  # at 100 % observed there is no answer to choose the ProMPs' noise on: their default
            out[name] = run_predictor(predictor, run, test, rule)
    return out


def grid_predictions(
    run: TrainedRun,
    fitted_data: MotionDataset,
    test: MotionDataset,
    fractions,
    *,
    starts=("zero", "projection", "calibrated", "nearest", MIXTURE),
    epochs: int,
    online_iterations: int | None = None,
    prior_settings: dict | None = None,
    peer_settings: dict | None = None,
) -> dict:
    """``{row: {fraction: mean unobserved MSE}}`` of every row (and, with ``online_iterations``,
    the online gradient start ``projection`` and the online mixture) on ``test``; ``prior_settings`` and
    ``peer_settings`` as :func:`grid_predictors`'s."""
    rows = grid_predictors(run, fitted_data, starts, epochs, prior_settings=prior_settings, peer_settings=peer_settings)
    scaled, lengths = run.scaler.transform(test.motor), test.valid_lengths
    table: dict = {}
    for f in fractions:
        key = f"{f:g}"
        observed = Observation.build(f).masks(lengths, test.length)[0]
        for name, forecast in grid_forecasts(rows, run, test, f).items():
            table.setdefault(name, {})[key] = finite_mean(unobserved_mse(forecast.motor, scaled, observed, lengths))
        if online_iterations is not None:
            for name, init in (("online projection", "projection"), ("online mixture", MIXTURE)):
                p = predict(
                    run,
                    test,
                    observe=f,
                    init=init,
                    online=online_iterations,
                    fitted_data=fitted_data,
                    frames=False,
                    progress=False,
                )
                table.setdefault(name, {})[key] = finite_mean(p.errors["motor_mse"])
    return table
