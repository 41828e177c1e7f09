"""Long demonstrations: the timeline of a demonstration's code sequence with its true and
found primitive boundaries and labels (docs/sequences.md)."""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure

from primspace.plots.base import label_colors

__all__ = ["plot_code_timeline"]


def plot_code_timeline(
    codes: np.ndarray,
    window: int,
    lengths: Sequence[int],
    true_labels: np.ndarray,
    found_labels: np.ndarray,
    true_boundaries: Sequence[Sequence[int]],
    found_boundaries: Sequence[Sequence[int]],
    *,
    label_names: Sequence[str] = (),
    title: str = "",
) -> Figure:
    """One row per demonstration: its window codes as a heat map over time (q rows,
    each window W steps wide), the true labels and the found labels as colour strips,
    true boundaries as solid lines and found ones dashed.

    Parameters
    ----------
    codes : ndarray (n, K, q)
    window : int
        W, steps per code.
    lengths : sequence of int
        Valid steps per demonstration (later steps are not drawn).
    true_labels, found_labels : ndarray (n, T)
        Primitive per step (-1: padding); found labels are cluster ids (colours do not
        correspond to the true ones).
    true_boundaries, found_boundaries : sequences of step indices per demonstration
    label_names : names of the true labels (legend)
    """
    n = codes.shape[0]
    fig = plt.figure(figsize=(9, 1.9 * n + 0.6))
    grid = fig.add_gridspec(3 * n, 1, height_ratios=[6, 1, 1] * n, hspace=0.15)
    n_colors = int(max(np.max(true_labels), np.max(found_labels), 0)) + 1
    cmap = ListedColormap(label_colors(max(n_colors, 2)))
    longest = max(int(v) for v in lengths[:n])  # one time axis for every row (a shorter demonstration ends early)
    for i in range(n):
        length = int(lengths[i])
        ax = fig.add_subplot(grid[3 * i])
        _draw_codes(ax, codes[i], window, length, longest, true_boundaries[i], found_boundaries[i])
        ax.set_ylabel(f"#{i}\ncode", fontsize=8)
        for row, labels, name in ((1, true_labels, "true"), (2, found_labels, "found")):
            strip = fig.add_subplot(grid[3 * i + row])
            _draw_label_strip(strip, labels[i][:length], cmap, length, longest, name)
            if not (i == n - 1 and row == 2):
                strip.set_xticks([])
    fig.axes[-1].set_xlabel("step")
    _legend(fig, cmap, label_names)
    if title:
        fig.suptitle(title, y=0.97)
    return fig


def _draw_codes(ax, codes: np.ndarray, window: int, length: int, longest: int, true_bounds, found_bounds) -> None:
    """One demonstration's window codes (K, q) as a heat map over its ``length`` steps, with
    its true boundaries as solid lines and the found ones dashed."""
    q = codes.shape[1]
    steps = np.repeat(codes, window, axis=0)[:length].T  # (q, L)
    limit = float(np.abs(steps).max()) or 1.0
    ax.imshow(
        steps,
        aspect="auto",
        cmap="RdBu_r",
        vmin=-limit,
        vmax=limit,
        interpolation="nearest",
        extent=(0, length, q, 0),
    )
    ax.set_xlim(0, longest)
    ax.set_xticks([])
    for b in true_bounds:
        ax.axvline(b, color="k", lw=1.5)
    for b in found_bounds:
        ax.axvline(b, color="gold", lw=1.5, ls="--")


def _draw_label_strip(strip, labels: np.ndarray, cmap, length: int, longest: int, name: str) -> None:
    """One demonstration's labels per step as a colour strip (-1, padding: blank)."""
    shown = np.ma.masked_less(np.asarray(labels, float)[None], 0)
    strip.imshow(
        shown,
        aspect="auto",
        cmap=cmap,
        vmin=0,
        vmax=cmap.N - 1,
        interpolation="nearest",
        extent=(0, length, 1, 0),
    )
    strip.set_xlim(0, longest)
    strip.set_yticks([])
    strip.set_ylabel(name, fontsize=7, rotation=0, ha="right", va="center")


def _legend(fig: Figure, cmap, label_names: Sequence[str]) -> None:
    """The boundaries' line styles and the true labels' colours, above the rows."""
    handles = [
        plt.Line2D([], [], color="k", lw=1.5, label="true boundary"),
        plt.Line2D([], [], color="gold", lw=1.5, ls="--", label="found boundary"),
    ]
    handles += [plt.Rectangle((0, 0), 1, 1, color=cmap(k), label=name) for k, name in enumerate(label_names)]
    fig.legend(
        handles=handles,
        loc="lower center",
        bbox_to_anchor=(0.5, 0.9),
        ncol=min(len(handles), 5),
        fontsize=7,
        frameon=False,
    )
