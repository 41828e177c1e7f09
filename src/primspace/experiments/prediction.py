"""Predicting the rest of a motion (issue 25; docs/predict.md): primspace's starts against
the peers, on the intra split, over seeds.

For each seed, the intra experiment's projection fit at the focus q (its θ frozen) and its
evaluation samples: each sample's first ``f`` of its valid steps is observed, the rest is
predicted, for ``f`` in :data:`PREDICT_FRACTIONS`. primspace's starts (gradient inference
on the observed entries from ``zero``, ``projection``, ``calibrated``, ``nearest``, or no
gradient at all: ``mixture``, the posterior over the fitted codes,
:mod:`primspace.predict.mixture`), each with the continuity correction; ``mixture`` also
without it, and as its posterior mean alone (no ensemble conditioning). The peers, on
the same split, scaled the same way (:mod:`primspace.predict.peers`):
ProMP conditioning *given the labels* (one per primitive) and one ProMP for all, each
with its observation noise chosen on the answer (flattering them); the nearest fitted
demonstration on the observed steps; the mean motion of the sample's primitive (given
the label). Every row is a predictor of :mod:`primspace.predict` (one loop over ``{name: predictor}``,
:func:`primspace.predict.grid.grid_predictors`). The error: :func:`primspace.predict.metrics.unobserved_mse`, the same for all. For
simulator data every prediction is also replayed and judged (success per fraction,
1.0 included: then nothing is left to predict and the start alone is judged).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.intra import run_intra
from primspace.experiments.prediction_table import predict_figure, predict_table
from primspace.experiments.runs import focus_runs
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir
from primspace.predict.grid import GIVEN_ROWS, LABELS_DIAGNOSTIC, PEERS
from primspace.results.layout import phase_dir

__all__ = [
    "PREDICT_FRACTIONS",
    "PREDICT_STARTS_GRID",
    "PEERS",
    "PREDICT_MAX_SAMPLES",
    "run_predict",
    "run_predict_point",
    "predicted_subset",
    "projection_seeds",
    "epochs_tail",
    "judgeable",
]

#: Observed fractions of the error table (1.0 is added for the judge on simulator data).
PREDICT_FRACTIONS = (0.1, 0.25, 0.5)
#: primspace's starts in the grid (the gradient ones run ``epochs`` of inference).
PREDICT_STARTS_GRID = ("zero", "projection", "calibrated", "nearest", "mixture")
#: Bumped when a grid point's content changes: points of another version are not reused
#: (3: the mixture may condition its ensemble; its posterior mean alone is a row of its own;
#: 4: the priors in code space per primitive, and the posterior's top-1 accuracy;
#: 5: the Gaussian peers tuned on the fitted demonstrations, and each row's model share).
PREDICT_VERSION = 5
#: Inference epochs of the gradient starts.
PREDICT_EPOCHS = 200
#: Evaluation samples predicted per seed at most: a subset stratified by label, drawn with
#: the seed (all of them on LASA, 130, and the demo, 98; 280 of the paper preset's 1372,
#: whose gradient starts and simulator replays would otherwise take hours per seed).
PREDICT_MAX_SAMPLES = 280


def predicted_subset(indices: np.ndarray, labels: np.ndarray | None, max_samples: int | None, seed: int) -> np.ndarray:
    """``indices`` when there are at most ``max_samples``; else a subset of that size, each
    label's share kept (rounded down, the remainder from the largest labels), drawn with
    ``seed`` and returned in the original order."""
    indices = np.asarray(indices)
    if max_samples is None or len(indices) <= max_samples:
        return indices
    rng = np.random.default_rng(seed)
    labels = np.zeros(len(indices), int) if labels is None else np.asarray(labels)
    names, counts = np.unique(labels, return_counts=True)
    take = np.floor(counts * max_samples / len(indices)).astype(int)
    for i in np.argsort(-counts, kind="stable")[: max_samples - take.sum()]:
        take[i] += 1
    chosen = np.concatenate([rng.permutation(np.flatnonzero(labels == n))[:k] for n, k in zip(names, take)])
    return indices[np.sort(chosen)]


def _judge(test: MotionDataset, motor: np.ndarray) -> dict:
    from primspace.sim.success import evaluate_dataset, success_rates

    results = evaluate_dataset(test, motor)
    return {"rates": success_rates(results), "overall": float(np.mean([r.success for r in results]))}


def run_predict_point(
    run_dir: Path,
    data_path: str,
    fit_dir: str,
    test_dir: str,
    fractions: tuple,
    starts: tuple,
    epochs: int,
    judge: bool,
    max_samples: int | None = None,
    prior_settings: dict | None = None,
    peer_settings: dict | None = None,
) -> dict:
    """One seed: every row (:func:`~primspace.predict.grid.grid_predictors`, ``prior_settings`` its
    keywords of the priors' rows, ``peer_settings`` those of the tuned peers; None: their defaults)
    at every fraction; mean unobserved MSE (and
    success) over the run's evaluation samples (at most ``max_samples``: :func:`predicted_subset`)."""
    from primspace.predict.grid import grid_forecasts, grid_predictors, posterior_accuracy
    from primspace.predict.metrics import finite_mean, unobserved_mse
    from primspace.predict.registry import built_on_run, model_share
    from primspace.train import TrainConfig, configure_process, load_run
    from primspace.train.observe import Observation

    configure_process(TrainConfig(device="cpu", threads=1))
    data = MotionDataset.load(data_path).without_images()
    fit, test_idx = load_run(fit_dir), load_run(test_dir).indices
    test_idx = predicted_subset(
        test_idx, None if data.labels is None else data.labels[test_idx], max_samples, fit.train_config.seed
    )
    test = data.subset(test_idx)
    truth = fit.scaler.transform(test.motor)
    rows = grid_predictors(fit, data, tuple(starts), epochs, prior_settings=prior_settings, peer_settings=peer_settings)
    table: dict = {}
    for f in tuple(fractions) + ((1.0,) if judge else ()):
        key = f"{f:g}"
        observed = Observation.build(f).masks(test.valid_lengths, test.length)[0]
        for name, forecast in grid_forecasts(rows, fit, test, f).items():
            entry = {"mse": finite_mean(unobserved_mse(forecast.motor, truth, observed, test.lengths))}
            accuracy = posterior_accuracy(forecast, test.labels)
            if accuracy is not None and name not in GIVEN_ROWS:
                entry["accuracy"] = accuracy
            entry["model_share"] = model_share(forecast.details, built_on_run(rows[name]))
            if "mixture" in forecast.details:
                entry["noise"] = forecast.details["mixture"]["noise"]
                entry["condition"] = forecast.details["mixture"]["condition"]
            if judge and name != LABELS_DIAGNOSTIC:
                entry["success"] = _judge(test, fit.scaler.inverse_transform(forecast.motor).astype(np.float32))
            table.setdefault(name, {})[key] = entry
    if LABELS_DIAGNOSTIC in table:  # a diagnostic: its error only
        table[LABELS_DIAGNOSTIC] = {k: {"mse": v["mse"]} for k, v in table[LABELS_DIAGNOSTIC].items()}
    return {
        "methods": table,
        "n_fitted": int(len(fit.indices)),
        "n_test": int(len(test_idx)),
        "n_eval": int(len(load_run(test_dir).indices)),
    }


def projection_seeds(intra: dict, q: int) -> list[int]:
    """The seeds of the intra experiment's projection runs at latent size ``q`` (whose fits the
    prediction and scene grids freeze), in order."""
    return sorted({r["seed"] for r in intra["runs"] if r["latent_dim"] == q and r["init"] == "projection"})


def epochs_tail(epochs: int, default: int) -> str:
    """The suffix of a grid point's key for a non-default epoch count (``-e{epochs}``; "" for the
    default): the grid reuses points by key, so other epochs must be other points."""
    return "" if int(epochs) == default else f"-e{int(epochs)}"


def run_predict(
    exp: ExperimentDir,
    fractions=PREDICT_FRACTIONS,
    starts=PREDICT_STARTS_GRID,
    epochs: int = PREDICT_EPOCHS,
    seeds=None,
    prior_settings: dict | None = None,
    peer_settings: dict | None = None,
) -> dict:
    """The prediction grid over the intra runs' seeds (runs intra first if needed); ``seeds``:
    only those of them (the results then hold those seeds only); ``prior_settings``,
    ``peer_settings``: keywords of the priors' and the tuned peers' rows
    (:func:`~primspace.predict.grid.grid_predictors`; None, as the command runs it: their defaults). The points' keys do not say them: points computed with other settings
    are reused as they are."""
    intra = exp.read_results("intra") or run_intra(exp)
    q, _, _ = focus_runs(exp, intra)
    seeds_run = projection_seeds(intra, q)
    seeds = seeds_run if seeds is None else [s for s in seeds_run if s in set(seeds)]
    tail = epochs_tail(epochs, PREDICT_EPOCHS)
    data = exp.dataset()
    judge = judgeable(data)
    points = [
        GridPoint(
            f"predict{PREDICT_VERSION}/projection-q{q}-s{s}{tail}",
            (
                str(exp.data_path),
                str(phase_dir(exp.path, "projection", q, s, "fit")),
                str(phase_dir(exp.path, "projection", q, s, "infer")),
                tuple(fractions),
                tuple(starts),
                int(epochs),
                judge,
                PREDICT_MAX_SAMPLES,
                *(() if prior_settings is None and peer_settings is None else (prior_settings, peer_settings)),
            ),
        )
        for s in seeds
    ]
    with exp.stage("predict"):
        grid = exp.grid(run_predict_point, points, "prediction")
    by_seed = {str(s): grid.results[p.key] for s, p in zip(seeds, points) if p.key in grid.results}
    results = {
        "version": PREDICT_VERSION,
        "latent_dim": q,
        "fractions": [float(f) for f in fractions],
        "starts": list(starts),
        "peers": list(PEERS),
        "given_rows": list(GIVEN_ROWS),
        "epochs": int(epochs),
        "judged": judge,
        "by_seed": by_seed,
        "failures": grid.failures,
        "table": predict_table(by_seed),
    }
    exp.write_results("predict", results)
    predict_figure(exp, results)
    return results


def judgeable(data: MotionDataset) -> bool:
    """Whether the simulator's judge can replay ``data`` (simulated data with its scene)."""
    from primspace.sim.success import check_judgeable
    from primspace.utils.errors import DataError

    try:
        check_judgeable(data)
    except DataError:
        return False
    return True
