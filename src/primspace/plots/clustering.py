"""Clustering figures: the affinity and the predicted label of every sample (the paper's
clustering figures), τ sweeps, and accuracy against the R² target that picks τ."""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from primspace.plots.base import init_color, label_colors

__all__ = ["plot_clustering", "plot_tau_sweep", "plot_accuracy_vs_r2"]


def plot_clustering(
    affinity,
    labels_pred,
    labels_true=None,
    *,
    label_names: Sequence[str] | None = None,
    title: str = "",
    gamma: float = 0.5,
) -> Figure:
    """The paper's clustering figure (Figs. "Clustering results for robotic trajectory data"
    and "... latent encodings"): the affinity ordered by true label, and the predicted label
    of every sample.

    Samples are ordered by true label (stable; by predicted label without true labels).
    Left: the affinity ``W`` in that order (power-law colour scale, true-cluster boundaries
    drawn). Right: each sample's predicted cluster, the cluster ids matched to the true labels
    by the Hungarian assignment so that a perfect clustering is a staircase; points whose
    predicted cluster disagrees with their true label are drawn as crosses. Samples with true
    label -1 (unknown) come last, in grey.

    Parameters
    ----------
    affinity : ndarray of shape (m, m)
        ``W`` for the samples shown (e.g. :func:`primspace.cluster.affinity_from_factor` on a
        subset).
    labels_pred : array-like of int, shape (m,)
    labels_true : array-like of int, shape (m,), optional
    label_names : list of str, optional
        Names of the true labels (tick labels of the right panel).
    title : str
    gamma : float
        Exponent of the colour scale (affinities span orders of magnitude).
    """
    w = np.asarray(affinity, dtype=np.float64)
    pred = np.asarray(labels_pred)
    true = None if labels_true is None else np.asarray(labels_true)
    key = pred if true is None else np.where(true < 0, np.iinfo(np.int64).max, true)
    order = np.argsort(key, kind="stable")
    w = w[np.ix_(order, order)]
    pred = pred[order]
    true = None if true is None else true[order]
    shown = _matched_to_true(pred, true)

    fig, (ax_w, ax_l) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1, 1.3]})
    _draw_affinity(fig, ax_w, w, gamma, ordered_by_true=true is not None)
    _draw_labels(ax_w, ax_l, shown, true, label_names)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _matched_to_true(pred: np.ndarray, true: np.ndarray | None) -> np.ndarray:
    """Predicted cluster ids renamed to the true labels they match best (Hungarian);
    unmatched clusters get ids above the true ones. Unchanged without true labels."""
    from scipy.optimize import linear_sum_assignment

    shown = pred.copy()
    if true is None or not np.any(true >= 0):
        return shown
    pred_ids = np.unique(pred)
    true_ids = np.unique(true[true >= 0])
    table = np.array([[np.sum((pred == p) & (true == t)) for t in true_ids] for p in pred_ids])
    rows, cols = linear_sum_assignment(table, maximize=True)
    mapping = {pred_ids[r]: true_ids[c] for r, c in zip(rows, cols)}
    next_id = int(true_ids.max()) + 1  # unmatched predicted clusters go above the true ids
    for p in pred_ids:
        if p not in mapping:
            mapping[p], next_id = next_id, next_id + 1
    return np.array([mapping[p] for p in pred])


def _draw_affinity(fig: Figure, ax_w, w: np.ndarray, gamma: float, *, ordered_by_true: bool) -> None:
    """The affinity on a power-law colour scale, with its colour bar."""
    from matplotlib.colors import PowerNorm
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    m = w.shape[0]
    # the colour scale ends at a high quantile of the off-diagonal entries: the diagonal
    # (a point's affinity with itself) and a few outliers would otherwise leave all dark
    off = w[~np.eye(m, dtype=bool)] if m > 1 else w.ravel()
    vmax = float(np.quantile(off, 0.995)) if off.size else 0.0
    if vmax <= 0:
        vmax = float(w.max()) if w.size and w.max() > 0 else 1.0
    image = ax_w.imshow(w, cmap="magma", norm=PowerNorm(gamma, vmin=0.0, vmax=vmax, clip=True), interpolation="nearest")
    colorbar = fig.colorbar(
        image, ax=ax_w, fraction=0.046, pad=0.04, label="affinity (clipped at the 99.5th percentile)"
    )
    colorbar.locator = MaxNLocator(4)
    colorbar.formatter = ScalarFormatter(useMathText=True)
    colorbar.formatter.set_powerlimits((-2, 3))
    colorbar.update_ticks()
    ax_w.set_title(
        "affinity W (ordered by true label)" if ordered_by_true else "affinity W (ordered by cluster)", fontsize=9
    )
    ax_w.set_xlabel("sample")
    ax_w.set_ylabel("sample")


def _draw_labels(ax_w, ax_l, shown: np.ndarray, true: np.ndarray | None, label_names) -> None:
    """Each sample's (matched) predicted cluster; with true labels, wrong ones as crosses,
    unknown ones in grey, and the true-cluster boundaries on both panels."""
    m = shown.size
    n_colors = int(max(shown.max(initial=0), (true.max(initial=0) if true is not None else 0))) + 1
    colors = label_colors(n_colors)
    x = np.arange(m)
    point_colors = [colors[int(s)] for s in shown]
    if true is not None:
        wrong = (true >= 0) & (shown != true)
        unknown = true < 0
        from matplotlib.lines import Line2D

        handles = []
        for name, mask, marker in (("correct", ~wrong & ~unknown, "o"), ("wrong", wrong, "x")):
            if mask.any():
                ax_l.scatter(
                    x[mask], shown[mask], c=[point_colors[i] for i in np.flatnonzero(mask)], s=10, marker=marker
                )
                handles.append(Line2D([], [], marker=marker, ls="", color="0.3", label=name))
        if unknown.any():
            ax_l.scatter(x[unknown], shown[unknown], c="0.6", s=10, marker="o")
            handles.append(Line2D([], [], marker="o", ls="", color="0.6", label="true label unknown"))
        bounds = np.flatnonzero(np.diff(true)) + 0.5
        for b in bounds:
            ax_w.axhline(b, color="white", lw=0.4, alpha=0.7)
            ax_w.axvline(b, color="white", lw=0.4, alpha=0.7)
            ax_l.axvline(b, color="0.85", lw=0.6, zorder=0)
        ax_l.legend(handles=handles, fontsize=7, loc="upper left")
        if label_names is not None and n_colors <= 30:
            names = [str(s) for s in label_names][:n_colors]
            names += [f"extra {i - len(names) + 1}" for i in range(len(names), n_colors)]
            ax_l.set_yticks(np.arange(n_colors))
            ax_l.set_yticklabels(names, fontsize=6 if n_colors > 10 else 8)
    else:
        ax_l.scatter(x, shown, c=point_colors, s=10)
    ax_l.set_xlabel("sample (ordered as left)")
    ax_l.set_ylabel("predicted cluster" + (" (matched to true labels)" if true is not None else ""))
    ax_l.set_xlim(-0.5, m - 0.5)
    ax_l.set_title("predicted label per sample", fontsize=9)


def plot_tau_sweep(rows: Sequence[dict], *, title: str = "") -> Figure:
    """Tau against R^2 (left axis) and the clustering scores (right axis), rank annotated:
    how the paper chose tau (Motion Capture Data: R^2 between 0.85 and 0.95).

    Parameters
    ----------
    rows : list of dict
        :func:`primspace.cluster.sweep` rows (``tau``, ``r2``, ``rank``, optionally
        ``accuracy``, ``nmi``, ``ari``); rows without a tau are skipped.
    title : str
    """
    rows = sorted((r for r in rows if r.get("tau") is not None), key=lambda r: r["tau"])
    fig, ax = plt.subplots(figsize=(7, 4))
    if not rows:
        ax.text(0.5, 0.5, "no tau kept a component", ha="center", va="center", transform=ax.transAxes)
        return fig
    tau = np.array([r["tau"] for r in rows])
    r2 = np.array([r["r2"] for r in rows], dtype=float)
    ax.semilogx(tau, r2, "o-", color="black", label="$R^2$")
    for t, v, r in zip(tau, r2, rows):
        ax.annotate(f"r={r['rank']}", (t, v), textcoords="offset points", xytext=(0, 6), ha="center", fontsize=7)
    ax.set_xlabel(r"$\tau$")
    ax.set_ylabel(r"$R^2$ of $Z \approx Z Q^*$")
    lines, names = ax.get_legend_handles_labels()
    score_keys = [k for k in ("accuracy", "nmi", "ari") if any(r.get(k) is not None for r in rows)]
    if score_keys:
        ax2 = ax.twinx()
        for key, color in zip(score_keys, ("tab:blue", "tab:green", "tab:orange")):
            values = np.array([np.nan if r.get(key) is None else r[key] for r in rows], dtype=float)
            ax2.semilogx(tau, values, "s--", color=color, ms=4, label=key)
        ax2.set_ylabel("score")
        ax2.set_ylim(-0.05, 1.05)
        more_lines, more_names = ax2.get_legend_handles_labels()
        lines, names = lines + more_lines, names + more_names
    ax.legend(lines, names, fontsize=8, loc="lower right")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_accuracy_vs_r2(sweeps: dict, *, title: str = "", colors: dict | None = None) -> Figure:
    """Clustering accuracy against the R² target that picks τ, one line per set of codes.

    Shows how the paper's single setting (R² = 0.9999 for latents) sits among the others.

    Parameters
    ----------
    sweeps : dict of name -> list of dict
        :func:`primspace.cluster.sweep` rows over ``r2_targets`` (``value``, ``accuracy``, ``rank``).
    """
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for name, rows in sweeps.items():
        rows = [r for r in rows if r.get("accuracy") is not None]
        xs = np.arange(len(rows))
        color = init_color(name, colors)
        ls = "--" if "initial" in str(name) else "-"
        ax.plot(xs, [r["accuracy"] for r in rows], marker="o", ms=3, lw=1.4, ls=ls, color=color, label=str(name))
        ax.set_xticks(xs, [f"{r['value']:g}" for r in rows], fontsize=7)
    ax.set_xlabel("R² target (chooses τ)")
    ax.set_ylabel("accuracy")
    ax.set_ylim(0, 1.02)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig
