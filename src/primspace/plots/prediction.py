"""Predicting the rest of a motion (docs/predict.md): observed, predicted and
recorded joints of a few samples, and errors against the observed fraction.

The paper has no such figure: it reconstructs whole demonstrations only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from primspace.plots.base import INIT_COLORS

__all__ = ["plot_predictions", "plot_prediction_errors"]


def plot_predictions(
    truth: np.ndarray,
    predicted: np.ndarray,
    observed: np.ndarray,
    *,
    titles: Sequence[str],
    joint_names: Sequence[str] | None = None,
    dt: float = 1.0,
    max_joints: int = 4,
) -> Figure:
    """One row per sample, one column per joint (the first ``max_joints``): the recorded
    joint (grey), the prediction (blue), the observed steps shaded.

    Parameters
    ----------
    truth, predicted : ndarray (n, T, J)
        Recorded and predicted joints, physical units.
    observed : ndarray (n, T) bool
        The observed steps of each sample.
    titles : sequence of str
        One per sample.
    """
    n, t, j = truth.shape
    cols = min(j, max_joints)
    fig, axes = plt.subplots(n, cols, figsize=(3.2 * cols, 2.2 * n), squeeze=False)
    time = np.arange(t) * dt
    for i in range(n):
        seen = np.flatnonzero(observed[i])
        for c in range(cols):
            ax = axes[i, c]
            if seen.size:
                ax.axvspan(time[0], time[seen[-1]], color="0.9", label="observed")
            ax.plot(time, truth[i, :, c], color="0.4", lw=1.2, label="recorded")
            ax.plot(time, predicted[i, :, c], color="tab:blue", lw=1.2, label="predicted")
            name = joint_names[c] if joint_names is not None else f"joint {c}"
            ax.set_title(f"{titles[i]}: {name}" if c == 0 else name, fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


def plot_prediction_errors(
    fractions: Sequence[float],
    errors: Mapping[str, Sequence[float]],
    spreads: Mapping[str, Sequence[float]] | None = None,
    *,
    ylabel: str = "MSE of the rest",
    title: str = "",
) -> Figure:
    """Error of the unobserved steps against the observed fraction, one line per method
    (mean, with its spread over seeds as error bars when given); log scale."""
    fig, ax = plt.subplots(figsize=(5.2, 3.6))
    for k, (name, values) in enumerate(errors.items()):
        color = INIT_COLORS.get(name, f"C{k % 10}")
        yerr = None if spreads is None else spreads.get(name)
        ax.errorbar(fractions, values, yerr=yerr, marker="o", ms=3, capsize=2, color=color, label=name)
    ax.set_xlabel("observed fraction of the motion")
    ax.set_ylabel(ylabel)
    ax.set_yscale("log")
    if title:
        ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig
