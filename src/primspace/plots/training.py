"""Training and latent figures: loss curves (the paper's convergence and inter-primitive
figures) and the first principal components of the codes (its latent-encoding figure)."""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from primspace.plots.base import init_color
from primspace.utils.stats import sample_std

__all__ = ["plot_loss_curves", "plot_intra_losses", "plot_latent_pca"]


def plot_loss_curves(
    histories,
    *,
    key: str = "loss",
    colors=None,
    title: str = "",
    log_scale: bool = True,
    ax=None,
) -> Figure:
    """Loss per epoch of several runs (paper Figs. ``loss_train``, ``loss_test``).

    Parameters
    ----------
    histories : mapping of label -> list of dict, or of label -> list of lists
        Each run's ``metrics.jsonl`` (:attr:`primspace.train.TrainedRun.history`). A list
        of histories under one label (seeds, folds) is drawn as their mean ± sample std
        (ddof 1, :func:`primspace.utils.stats.sample_std`, the convention of every table; the
        legend says so) per epoch (paper Fig. ``loss_inter``); on a log axis the band's
        lower edge stops at the lowest run.
    key : {"loss", "motor", "vision"}
    colors : mapping of label -> colour, optional
        Default: :data:`INIT_COLORS` when a label starts with an init name.
    title : str
    log_scale : bool
    ax : matplotlib Axes, optional
    """
    if ax is None:
        fig, ax = plt.subplots(figsize=(5.5, 3.6))
    else:
        fig = ax.figure
    banded = False
    for label, runs in histories.items():
        runs = [runs] if runs and isinstance(runs[0], dict) else list(runs)
        curves = [
            (np.array([h["epoch"] for h in r]), np.array([np.nan if h.get(key) is None else h[key] for h in r], float))
            for r in runs
        ]
        if not curves:
            continue
        color = init_color(label, colors)
        n = min(len(e) for e, _ in curves)
        epochs = curves[0][0][:n]
        values = np.stack([v[:n] for _, v in curves])
        mean = values.mean(axis=0)
        ax.plot(epochs, mean, color=color, lw=1.5, label=str(label))
        if len(curves) > 1:
            std = np.apply_along_axis(sample_std, 0, values)  # over the runs, per epoch
            banded = True
            lower = mean - std
            if log_scale:  # a band below zero has no place on a log axis: stop it at the lowest run
                lower = np.maximum(lower, values.min(axis=0))
            ax.fill_between(epochs, lower, mean + std, color=color, alpha=0.2, lw=0)
    if log_scale:
        ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.set_ylabel(f"{key} (mean squared error)" if key != "loss" else "loss")
    ax.grid(True, alpha=0.3)
    legend = ax.legend(fontsize=8)
    if banded:
        legend.set_title("mean ± sample std (ddof 1)", prop={"size": 7})
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_intra_losses(runs: Sequence[dict], *, phase: str = "fit", key: str = "loss", title: str = "") -> Figure:
    """The paper's convergence figures: loss per epoch, one panel per latent size q.

    Parameters
    ----------
    runs : list of dict
        Intra-primitive run results (``init``, ``latent_dim``, ``seed``, and the per-epoch
        histories ``fit`` / ``infer``); several seeds of one (init, q) are drawn as mean ± sample
        std (ddof 1) over the seeds.
    phase : {"fit", "infer"}
        Fitting θ and Z (paper Fig. ``loss_train``) or inferring Z (Fig. ``loss_test``).
    """
    dims = sorted({r["latent_dim"] for r in runs})
    fig, axes = plt.subplots(1, len(dims), figsize=(4.6 * len(dims), 3.6), squeeze=False, sharey=True)
    for ax, q in zip(axes[0], dims):
        histories: dict[str, list] = {}
        for r in sorted(runs, key=lambda r: r["init"]):
            if r["latent_dim"] == q:
                histories.setdefault(r["init"], []).append(r[phase])
        plot_loss_curves(histories, key=key, title=f"q = {q}", ax=ax)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def _position_colors(xy: np.ndarray) -> np.ndarray:
    """A 2-D colour map of block positions: x runs red-ward, y blue-ward."""
    lo, hi = xy.min(0), xy.max(0)
    u = (xy - lo) / np.where(hi > lo, hi - lo, 1.0)
    return np.column_stack([0.15 + 0.8 * u[:, 0], 0.35 * np.ones(len(u)), 0.15 + 0.8 * u[:, 1]])


def plot_latent_pca(
    codes: dict,
    labels: np.ndarray,
    params: np.ndarray,
    *,
    primitive: int = 0,
    primitive_name: str = "",
    n_components: int = 2,
) -> Figure:
    """First principal components of one primitive's codes, coloured by block position.

    The paper's latent-encoding figure: (a) the block positions on the table, then per
    initialisation the codes of every sample of one primitive projected on their first two
    (or three) principal components, each point coloured by its block's position
    (x red-ward, y blue-ward) and sized by block size.

    Parameters
    ----------
    codes : dict of init name -> ndarray (N, q)
    labels : ndarray (N,)
    params : ndarray (N, P)
        Columns 0, 1, 2 = block x, y, size.
    """
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers the 3-D projection)

    mask = labels == primitive
    xy = params[mask, :2]
    colors = _position_colors(xy)
    sizes = params[mask, 2] if params.shape[1] > 2 else np.ones(mask.sum())
    sizes = 12 + 40 * (sizes - sizes.min()) / (np.ptp(sizes) or 1.0)
    n = len(codes) + 1
    fig = plt.figure(figsize=(3.8 * n, 3.8))
    ax = fig.add_subplot(1, n, 1)
    ax.scatter(xy[:, 0], xy[:, 1], c=colors, s=sizes, edgecolors="none")
    ax.set_xlabel("block x [m]")
    ax.set_ylabel("block y [m]")
    ax.set_title("(a) block positions", fontsize=9)
    ax.set_aspect("equal", adjustable="datalim")
    for k, (init, z) in enumerate(codes.items(), start=2):
        zz = np.asarray(z)[mask]
        zz = zz - zz.mean(0)
        _, _, vt = np.linalg.svd(zz, full_matrices=False)
        pcs = zz @ vt[:n_components].T
        pcs = np.pad(pcs, ((0, 0), (0, n_components - pcs.shape[1])))  # fewer samples than components
        if n_components == 3:
            ax = fig.add_subplot(1, n, k, projection="3d")
            ax.scatter(pcs[:, 0], pcs[:, 1], pcs[:, 2], c=colors, s=sizes, edgecolors="none", depthshade=False)
            ax.set_zlabel("PC 3", fontsize=8)
        else:
            ax = fig.add_subplot(1, n, k)
            ax.scatter(pcs[:, 0], pcs[:, 1], c=colors, s=sizes, edgecolors="none")
        ax.set_xlabel("PC 1", fontsize=8)
        ax.set_ylabel("PC 2", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_title(f"({chr(ord('a') + k - 1)}) {init} init", fontsize=9)
    fig.suptitle(
        f"Codes of primitive '{primitive_name}' (train and eval), first {n_components} principal components",
        fontsize=10,
    )
    fig.tight_layout()
    return fig
