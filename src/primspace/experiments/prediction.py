"""Predicting the rest of a motion (issue 25; docs/predict.md): primspace's starts against
the peers, on the intra split, over seeds.

For each seed, the intra experiment's projection fit at the focus q (its θ frozen) and its
evaluation samples: each sample's first ``f`` of its valid steps is observed, the rest is
predicted, for ``f`` in :data:`PREDICT_FRACTIONS`. primspace's starts (gradient inference
on the observed entries from ``zero``, ``projection``, ``calibrated``, ``nearest``, or no
gradient at all: ``mixture``, the posterior over the fitted codes,
:mod:`primspace.train.mixture`), each with the continuity correction; ``mixture`` also
without it, and as its posterior mean alone (no ensemble conditioning). The peers, on
the same split, scaled the same way (:mod:`primspace.peers`):
ProMP conditioning *given the labels* (one per primitive) and one ProMP for all, each
with its observation noise chosen on the answer (flattering them); the nearest fitted
demonstration on the observed steps; the mean motion of the sample's primitive (given
the label). The error: :func:`primspace.peers.unobserved_mse`, the same for all. For
simulator data every prediction is also replayed and judged (success per fraction,
1.0 included: then nothing is left to predict and the start alone is judged).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.intra import run_intra
from primspace.experiments.runs import focus_runs, phase_dir
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir

__all__ = ["PREDICT_FRACTIONS", "PREDICT_STARTS_GRID", "PEERS", "PREDICT_MAX_SAMPLES", "run_predict", "run_predict_point",
           "predict_table", "predicted_subset"]

#: Observed fractions of the error table (1.0 is added for the judge on simulator data).
PREDICT_FRACTIONS = (0.1, 0.25, 0.5)
#: primspace's starts in the grid (the gradient ones run ``epochs`` of inference).
PREDICT_STARTS_GRID = ("zero", "projection", "calibrated", "nearest", "mixture")
#: The peers' names in the results (labels: the peer is given the test sample's primitive).
PEERS = ("promp (labels)", "promp (one for all)", "nearest neighbour", "mean motion (labels)")
#: The mixture's rows: (name, continuity correction, ensemble conditioning allowed).
POSTERIOR_MEAN = "mixture (posterior mean)"
MIXTURE_VARIANTS = (("mixture", True, True), (POSTERIOR_MEAN, True, False), ("mixture (no continuity)", False, True))
#: Bumped when a grid point's content changes: points of another version are not reused
#: (3: the mixture may condition its ensemble; its posterior mean alone is a row of its own).
PREDICT_VERSION = 3
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


def _given_labels(fit, fitted: MotionDataset, test: MotionDataset, noises: dict):
    """The mixture restricted to each test sample's own primitive (a diagnostic: it is given
    the labels, as the ProMP peer is): candidates built from fitted codes of that label only,
    their posterior mean (no ensemble conditioning)."""
    from primspace.train.mixture import continuity_correction
    from primspace.train.observe import Observation, observation_masks
    from primspace.train.predict import code_mixture

    mixture = code_mixture(fit)  # the one the label-free rows decoded
    source_labels = fitted.labels[mixture.sources]
    other = ~((source_labels[None, :, 0] == test.labels[:, None]) & (source_labels[None, :, 1] == test.labels[:, None]))
    scaled, valid = fit.scaler.transform(test.motor), observation_masks(None, test)[0]
    out = {}
    for key, noise in noises.items():
        observed = observation_masks(Observation.build(float(key)), test)[0]
        w = mixture.weights(scaled, observed, noise, exclude=other)
        out[key] = continuity_correction(np.einsum("nc,ctj->ntj", w, mixture.decoded), scaled, observed, valid)
    return out


def _fitted_peers(fitted_scaled, fitted) -> dict:
    """The peers fitted on the fitted demonstrations once (ProMP's EM is the slow part), by name."""
    from primspace.peers import MeanMotionPeer, NearestPeer, ProMPPeer

    args = (fitted_scaled, fitted.labels, fitted.lengths)
    return {"promp (labels)": ProMPPeer(per_label=True).fit(*args),
            "promp (one for all)": ProMPPeer(per_label=False).fit(*args),
            "nearest neighbour": NearestPeer().fit(*args), "mean motion (labels)": MeanMotionPeer().fit(*args)}


def _peer_predictions(peers: dict, test_scaled, test, observed) -> dict:
    """Scaled predictions of each fitted peer (:func:`_fitted_peers`; the ProMPs' noise chosen on the answer)."""
    from primspace.peers import ProMPPeer, best_noise
    from primspace.train.observe import observation_masks

    lt = test.lengths
    left = (observation_masks(None, test)[0] & ~observed).any()
    out = {}
    for name, peer in peers.items():
        if isinstance(peer, ProMPPeer) and left:
            out[name] = best_noise(peer, test_scaled, observed, test.labels, lt).predicted
        else:  # the others have no noise; at 100 % observed no answer to choose the ProMPs' on: their default
            out[name] = peer.predict(test_scaled, observed, test.labels, lt)
    return out


def run_predict_point(run_dir: Path, data_path: str, fit_dir: str, test_dir: str, fractions: tuple,
                      starts: tuple, epochs: int, judge: bool, max_samples: int | None = None) -> dict:
    """One seed: every start and peer at every fraction; mean unobserved MSE (and success)
    over the run's evaluation samples (at most ``max_samples``: :func:`predicted_subset`)."""
    from primspace.peers import unobserved_mse
    from primspace.train import TrainConfig, configure_process, load_run
    from primspace.train.observe import Observation, observation_masks
    from primspace.train.predict import predict

    configure_process(TrainConfig(device="cpu", threads=1))
    data = MotionDataset.load(data_path).without_images()
    fit, test_idx = load_run(fit_dir), load_run(test_dir).indices
    test_idx = predicted_subset(test_idx, None if data.labels is None else data.labels[test_idx], max_samples,
                                fit.train_config.seed)
    scaler, fitted, test = fit.scaler, data.subset(fit.indices), data.subset(test_idx)
    fitted_scaled, test_scaled = scaler.transform(fitted.motor), scaler.transform(test.motor)
    table: dict = {}
    peers = _fitted_peers(fitted_scaled, fitted)
    for f in tuple(fractions) + ((1.0,) if judge else ()):
        key = f"{f:g}"
        observed = observation_masks(Observation.build(f), test)[0]
        for start in starts:
            for name, continuity, condition in MIXTURE_VARIANTS if start == "mixture" else ((start, True, True),):
                p = predict(fit, data, observe=f, init=start, epochs=epochs, indices=test_idx, fitted_data=data,
                            frames=False, continuity=continuity, condition=condition, progress=False)
                entry = {"mse": _mean(p.errors["motor_mse"])}
                if "mixture" in p.details:
                    entry["noise"] = p.details["mixture"]["noise"]
                    entry["condition"] = p.details["mixture"]["condition"]
                if judge:
                    entry["success"] = _judge(test, p.motor)
                table.setdefault(name, {})[key] = entry
        for name, scaled in _peer_predictions(peers, test_scaled, test, observed).items():
            entry = {"mse": _mean(unobserved_mse(scaled, test_scaled, observed, test.lengths))}
            if judge:
                entry["success"] = _judge(test, scaler.inverse_transform(scaled).astype(np.float32))
            table.setdefault(name, {})[key] = entry
    if POSTERIOR_MEAN in table:  # the same noise as the label-free posterior mean chose
        noises = {k: v["noise"] for k, v in table[POSTERIOR_MEAN].items()}
        for key, scaled in _given_labels(fit, fitted, test, noises).items():
            observed = observation_masks(Observation.build(float(key)), test)[0]
            table.setdefault("mixture (labels; diagnostic)", {})[key] = {
                "mse": _mean(unobserved_mse(scaled, test_scaled, observed, test.lengths))}
    return {"methods": table, "n_fitted": int(len(fit.indices)), "n_test": int(len(test_idx)),
            "n_eval": int(len(load_run(test_dir).indices))}


def _mean(values) -> float | None:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else None


def projection_seeds(intra: dict, q: int) -> list[int]:
    """The seeds of the intra experiment's projection runs at latent size ``q`` (whose fits the
    prediction and scene grids freeze), in order."""
    return sorted({r["seed"] for r in intra["runs"] if r["latent_dim"] == q and r["init"] == "projection"})


def epochs_tail(epochs: int, default: int) -> str:
    """The suffix of a grid point's key for a non-default epoch count (``-e{epochs}``; "" for the
    default): the grid reuses points by key, so other epochs must be other points."""
    return "" if int(epochs) == default else f"-e{int(epochs)}"


def run_predict(exp: ExperimentDir, fractions=PREDICT_FRACTIONS, starts=PREDICT_STARTS_GRID,
                epochs: int = PREDICT_EPOCHS, seeds=None) -> dict:
    """The prediction grid over the intra runs' seeds (runs intra first if needed); ``seeds``:
    only those of them (the results then hold those seeds only)."""
    intra = exp.read_results("intra") or run_intra(exp)
    q, _, _ = focus_runs(exp, intra)
    seeds_run = projection_seeds(intra, q)
    seeds = seeds_run if seeds is None else [s for s in seeds_run if s in set(seeds)]
    tail = epochs_tail(epochs, PREDICT_EPOCHS)
    data = exp.dataset()
    judge = _judgeable(data)
    points = [
        GridPoint(f"predict{PREDICT_VERSION}/projection-q{q}-s{s}{tail}",
                  (str(exp.data_path), str(phase_dir(exp.path, "projection", q, s, "fit")),
                   str(phase_dir(exp.path, "projection", q, s, "infer")), tuple(fractions), tuple(starts), int(epochs),
                   judge, PREDICT_MAX_SAMPLES))
        for s in seeds
    ]
    with exp.stage("predict"):
        grid = exp.grid(run_predict_point, points, "prediction")
    by_seed = {str(s): grid.results[p.key] for s, p in zip(seeds, points) if p.key in grid.results}
    results = {"latent_dim": q, "fractions": [float(f) for f in fractions], "starts": list(starts), "peers": list(PEERS),
               "epochs": int(epochs), "judged": judge, "by_seed": by_seed, "failures": grid.failures,
               "table": predict_table(by_seed)}
    exp.write_results("predict", results)
    _figure(exp, results)
    return results


def _figure(exp: ExperimentDir, results: dict) -> None:
    """figures/predict_errors.png: mean MSE of the rest against the observed fraction, per method."""
    from primspace.plots import plot_prediction_errors, save_figure

    keys = [f"{f:g}" for f in results["fractions"]]
    means, spreads = {}, {}
    for method, cells in results["table"].items():
        if all(cells.get(k, {}).get("mse") for k in keys):
            means[method] = [cells[k]["mse"][0] for k in keys]
            spreads[method] = [cells[k]["mse"][1] for k in keys]
    if means:
        save_figure(plot_prediction_errors(results["fractions"], means, spreads,
                                           title=f"q = {results['latent_dim']}, mean ± std over seeds"),
                    exp.figure("predict_errors"))


def _judgeable(data: MotionDataset) -> bool:
    from primspace.errors import DataError
    from primspace.sim.success import check_judgeable

    try:
        check_judgeable(data)
    except DataError:
        return False
    return True


def predict_table(by_seed: dict) -> dict:
    """{method: {fraction: {"mse": [mean, std, n], "success": [mean, std, n] or absent}}} over seeds."""
    table: dict = {}
    for result in by_seed.values():
        for method, fractions in result["methods"].items():
            for key, entry in fractions.items():
                cell = table.setdefault(method, {}).setdefault(key, {"mse": [], "success": []})
                if entry.get("mse") is not None:
                    cell["mse"].append(entry["mse"])
                if "success" in entry:
                    cell["success"].append(entry["success"]["overall"])
    return {m: {k: {name: _spread(v) for name, v in cell.items() if v} for k, cell in fr.items()} for m, fr in table.items()}


def _spread(values: list) -> list:
    a = np.asarray(values, dtype=np.float64)
    return [float(a.mean()), float(a.std(ddof=1)) if a.size > 1 else 0.0, int(a.size)]
