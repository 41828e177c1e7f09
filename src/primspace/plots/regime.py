"""The regime of few demonstrations (docs/predict.md): the error against the number of fitted
demonstrations per primitive, one line per predictor, log-log."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib.pyplot as plt
from matplotlib.figure import Figure
from matplotlib.ticker import NullLocator

__all__ = ["plot_error_against_n"]


def plot_error_against_n(
    panels: Mapping[str, Mapping[str, tuple[Sequence[float], Sequence[float], Sequence[float]]]],
    *,
    ylabel: str = "MSE of the rest",
    title: str = "",
) -> Figure:
    """One panel per task (its title), one line per row: ``(ns, means, stds)``, the mean with its
    spread over seeds as error bars, both axes logarithmic; rows whose name starts with a peer's
    (``promp``, ``raw gaussian``, ``nearest``) dashed."""
    shown = {name: rows for name, rows in panels.items() if rows}
    fig, axes = plt.subplots(1, max(1, len(shown)), figsize=(5.0 * max(1, len(shown)), 3.8), squeeze=False)
    for ax, (name, rows) in zip(axes[0], shown.items()):
        for k, (row, (ns, means, stds)) in enumerate(rows.items()):
            dashed = row.startswith(("promp", "raw gaussian", "nearest"))
            ax.errorbar(
                ns,
                means,
                yerr=stds,
                marker="o",
                ms=3,
                capsize=2,
                ls="--" if dashed else "-",
                color=f"C{k % 10}",
                label=row,
            )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ticks = sorted({float(n) for ns, _, _ in rows.values() for n in ns})
        ax.set_xticks(ticks, [f"{n:g}" for n in ticks])  # the n run, plainly, not 2x10^0
        ax.xaxis.set_minor_locator(NullLocator())
        ax.set_xlabel("fitted demonstrations per primitive (n)")
        ax.set_ylabel(ylabel)
        ax.set_title(name, fontsize=9)
        ax.legend(fontsize=6)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig
