"""The prediction grid's numbers over seeds and its figure (issue 25): aggregation and drawing,
apart from the computation (:mod:`primspace.experiments.prediction`)."""

from __future__ import annotations

import numpy as np

__all__ = ["predict_table", "predict_figure", "mean_std_count"]


def predict_table(by_seed: dict) -> dict:
    """{method: {fraction: {"mse": [mean, std, n], "success": [mean, std, n], "accuracy": [mean, std, n],
    "model_share": [mean, std, n]}}} over seeds ("success" where judged, "accuracy" (the posterior's top-1)
    where the row has one, "model_share" (the share of the prediction through the decoder) where recorded;
    absent otherwise)."""
    table: dict = {}
    for result in by_seed.values():
        for method, fractions in result["methods"].items():
            for key, entry in fractions.items():
                cell = table.setdefault(method, {}).setdefault(
                    key, {"mse": [], "success": [], "accuracy": [], "model_share": []}
                )
                if entry.get("mse") is not None:
                    cell["mse"].append(entry["mse"])
                if "success" in entry:
                    cell["success"].append(entry["success"]["overall"])
                if entry.get("accuracy") is not None:
                    cell["accuracy"].append(entry["accuracy"])
                if entry.get("model_share") is not None:
                    cell["model_share"].append(entry["model_share"])
    return {
        m: {k: {name: mean_std_count(v) for name, v in cell.items() if v} for k, cell in fr.items()}
        for m, fr in table.items()
    }


def mean_std_count(values: list) -> list:
    """``[mean, std (ddof 1; 0 for one value), count]`` of ``values``."""
    a = np.asarray(values, dtype=np.float64)
    return [float(a.mean()), float(a.std(ddof=1)) if a.size > 1 else 0.0, int(a.size)]


def predict_figure(exp, results: dict) -> None:
    """figures/predict_errors.png: mean MSE of the rest against the observed fraction, per method."""
    from primspace.plots import plot_prediction_errors, save_figure

    keys = [f"{f:g}" for f in results["fractions"]]
    means, spreads = {}, {}
    for method, cells in results["table"].items():
        if all(cells.get(k, {}).get("mse") for k in keys):
            means[method] = [cells[k]["mse"][0] for k in keys]
            spreads[method] = [cells[k]["mse"][1] for k in keys]
    if means:
        save_figure(
            plot_prediction_errors(
                results["fractions"], means, spreads, title=f"q = {results['latent_dim']}, mean ± std over seeds"
            ),
            exp.figure("predict_errors"),
        )
