"""Every figure primspace draws (matplotlib, Agg backend, written atomically as PNG).

Functions return a :class:`matplotlib.figure.Figure`; :func:`save_figure` writes it and
closes it. Figures name the paper's figure they reproduce in their docstring.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")  # headless: never needs a display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from primspace.files import atomic_path  # noqa: E402

__all__ = [
    "save_figure",
    "plot_motion_sample",
    "plot_sim_sample",
    "plot_clustering",
    "plot_tau_sweep",
    "plot_intra_losses",
    "plot_latent_pca",
    "plot_accuracy_vs_r2",
]

# One palette for the latent initialisations, so every figure colours them alike.
INIT_COLORS = {"zero": "tab:blue", "random": "tab:red", "projection": "tab:green", "pca": "tab:purple"}


def save_figure(fig: Figure, path: str | os.PathLike, dpi: int = 120) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically (creating the folder) and close it."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png", bbox_inches="tight")
    finally:
        plt.close(fig)
    return path


# ============================================================== samples (data, model)


def plot_motion_sample(
    motor: np.ndarray,
    images: np.ndarray | None = None,
    *,
    joint_names: Sequence[str] | None = None,
    generated_motor: np.ndarray | None = None,
    generated_images: np.ndarray | None = None,
    n_frames: int = 8,
    dt: float | None = None,
    title: str = "",
) -> Figure:
    """One demonstration: a strip of camera frames above its joint curves.

    With ``generated_motor`` / ``generated_images`` it becomes the paper's Appendix B
    comparison: generated (dashed) against ground truth (solid), and a second frame
    strip of generated images under the recorded one.

    Parameters
    ----------
    motor : ndarray, shape (T, J)
        Ground-truth (or the only) joint values.
    images : ndarray, shape (T, H, W, 3), uint8, optional
        Ground-truth frames.
    joint_names : list of str, optional
    generated_motor : ndarray, shape (T, J), optional
    generated_images : ndarray, shape (T, H, W, 3), optional
    n_frames : int
        Frames shown per strip, evenly spaced in time.
    dt : float, optional
        Seconds per step (the time axis is in steps otherwise).
    title : str
    """
    motor = np.asarray(motor)
    t_len, n_joints = motor.shape
    names = list(joint_names) if joint_names is not None else [f"j{i}" for i in range(n_joints)]
    strips = [s for s in (images, generated_images) if s is not None]
    n_frames = min(n_frames, t_len)
    n_cols = 3 if n_joints > 4 else min(n_joints, 2)
    n_rows_j = int(np.ceil(n_joints / n_cols))
    fig = plt.figure(figsize=(2.0 * max(n_frames, 2 * n_cols), 1.4 * len(strips) + 1.9 * n_rows_j + 0.4))
    grid = fig.add_gridspec(len(strips) + n_rows_j, max(n_frames, 1), height_ratios=[1.2] * len(strips) + [1.6] * n_rows_j)
    frame_idx = np.linspace(0, t_len - 1, n_frames).round().astype(int)
    strip_labels = ["recorded", "generated"] if len(strips) == 2 else [None]
    for row, (strip, label) in enumerate(zip(strips, strip_labels)):
        for col, t in enumerate(frame_idx):
            ax = fig.add_subplot(grid[row, col])
            ax.imshow(np.asarray(strip[t]))
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(f"t={t}", fontsize=8)
            if col == 0 and label:
                ax.set_ylabel(label, fontsize=8)
    time = np.arange(t_len) * (dt if dt else 1.0)
    sub = grid[len(strips):, :].subgridspec(n_rows_j, n_cols, hspace=0.6, wspace=0.25)
    for j in range(n_joints):
        ax = fig.add_subplot(sub[j // n_cols, j % n_cols])
        ax.plot(time, motor[:, j], color="black", lw=1.4, label="ground truth" if generated_motor is not None else None)
        if generated_motor is not None:
            ax.plot(time, np.asarray(generated_motor)[:, j], color="tab:orange", lw=1.4, ls="--", label="generated")
        ax.set_title(names[j], fontsize=8)
        ax.tick_params(labelsize=7)
        if j == 0 and generated_motor is not None:
            ax.legend(fontsize=7, loc="best")
        if j // n_cols == n_rows_j - 1:
            ax.set_xlabel("time [s]" if dt else "step", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


# ================================================================= simulated data (sim)


def plot_sim_sample(dataset, index: int, n_frames: int = 8) -> Figure:
    """One sample of a data set (simulated or not): frame strip and joint curves.

    The title names the sample, its primitive and, for simulated data, the block
    (``block_x``, ``block_y``, ``block_size`` in cm). What ``primspace show`` draws.

    Parameters
    ----------
    dataset : MotionDataset
    index : int
        Sample index.
    n_frames : int
        Frames in the strip, evenly spaced in time.
    """
    i = int(index)
    parts = [f"sample {i}"]
    if dataset.labels is not None and 0 <= int(dataset.labels[i]) < len(dataset.label_names):
        parts.append(dataset.label_names[int(dataset.labels[i])])
    if dataset.params is not None:
        values = dataset.params[i]
        cm = {"block_x", "block_y", "block_size"}
        parts.append(", ".join(
            f"{n} {v * 100:.1f} cm" if n in cm else f"{n} {v:.4g}" for n, v in zip(dataset.param_names, values)
        ))
    images = None if dataset.images is None else np.asarray(dataset.images[i])
    return plot_motion_sample(
        dataset.motor[i], images, joint_names=[n.removeprefix("robot:panda0_") for n in dataset.joint_names],
        n_frames=n_frames, dt=dataset.dt, title=" | ".join(parts),
    )



# ==================================================================== clustering


def _label_colors(n: int):
    cmap = plt.get_cmap("tab10" if n <= 10 else "tab20" if n <= 20 else "turbo")
    return [cmap(i if n <= 20 else i / max(n - 1, 1)) for i in range(n)]


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
    from matplotlib.colors import PowerNorm
    from matplotlib.ticker import MaxNLocator, ScalarFormatter
    from scipy.optimize import linear_sum_assignment

    w = np.asarray(affinity, dtype=np.float64)
    pred = np.asarray(labels_pred)
    true = None if labels_true is None else np.asarray(labels_true)
    m = pred.size
    key = pred if true is None else np.where(true < 0, np.iinfo(np.int64).max, true)
    order = np.argsort(key, kind="stable")
    w = w[np.ix_(order, order)]
    pred = pred[order]
    true = None if true is None else true[order]

    pred_ids = np.unique(pred)
    shown = pred.copy()
    if true is not None and np.any(true >= 0):
        true_ids = np.unique(true[true >= 0])
        table = np.array([[np.sum((pred == p) & (true == t)) for t in true_ids] for p in pred_ids])
        rows, cols = linear_sum_assignment(table, maximize=True)
        mapping = {pred_ids[r]: true_ids[c] for r, c in zip(rows, cols)}
        next_id = int(true_ids.max()) + 1  # unmatched predicted clusters go above the true ids
        for p in pred_ids:
            if p not in mapping:
                mapping[p], next_id = next_id, next_id + 1
        shown = np.array([mapping[p] for p in pred])

    fig, (ax_w, ax_l) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1, 1.3]})
    # the colour scale ends at a high quantile of the off-diagonal entries: the diagonal
    # (a point's affinity with itself) and a few outliers would otherwise leave all dark
    off = w[~np.eye(m, dtype=bool)] if m > 1 else w.ravel()
    vmax = float(np.quantile(off, 0.995)) if off.size else 0.0
    if vmax <= 0:
        vmax = float(w.max()) if w.size and w.max() > 0 else 1.0
    image = ax_w.imshow(w, cmap="magma", norm=PowerNorm(gamma, vmin=0.0, vmax=vmax, clip=True), interpolation="nearest")
    colorbar = fig.colorbar(image, ax=ax_w, fraction=0.046, pad=0.04, label="affinity (clipped at the 99.5th percentile)")
    colorbar.locator = MaxNLocator(4)
    colorbar.formatter = ScalarFormatter(useMathText=True)
    colorbar.formatter.set_powerlimits((-2, 3))
    colorbar.update_ticks()
    ax_w.set_title("affinity W (ordered by true label)" if true is not None else "affinity W (ordered by cluster)", fontsize=9)
    ax_w.set_xlabel("sample")
    ax_w.set_ylabel("sample")

    n_colors = int(max(shown.max(initial=0), (true.max(initial=0) if true is not None else 0))) + 1
    colors = _label_colors(n_colors)
    x = np.arange(m)
    point_colors = [colors[int(s)] for s in shown]
    if true is not None:
        wrong = (true >= 0) & (shown != true)
        unknown = true < 0
        from matplotlib.lines import Line2D

        handles = []
        for name, mask, marker in (("correct", ~wrong & ~unknown, "o"), ("wrong", wrong, "x")):
            if mask.any():
                ax_l.scatter(x[mask], shown[mask], c=[point_colors[i] for i in np.flatnonzero(mask)], s=10, marker=marker)
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
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


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


# ========================================================== training, latents (model)


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
        of histories under one label is drawn as mean ± std over them (paper Fig.
        ``loss_inter``); on a log axis the band's lower edge stops at the lowest run.
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
    for label, runs in histories.items():
        runs = [runs] if runs and isinstance(runs[0], dict) else list(runs)
        curves = [
            (np.array([h["epoch"] for h in r]), np.array([np.nan if h.get(key) is None else h[key] for h in r], float))
            for r in runs
        ]
        if not curves:
            continue
        color = (colors or {}).get(label) or next(
            (c for name, c in INIT_COLORS.items() if str(label).startswith(name)), None
        )
        n = min(len(e) for e, _ in curves)
        epochs = curves[0][0][:n]
        values = np.stack([v[:n] for _, v in curves])
        mean = values.mean(axis=0)
        ax.plot(epochs, mean, color=color, lw=1.5, label=str(label))
        if len(curves) > 1:
            std = values.std(axis=0)
            lower = mean - std
            if log_scale:  # a band below zero has no place on a log axis: stop it at the lowest run
                lower = np.maximum(lower, values.min(axis=0))
            ax.fill_between(epochs, lower, mean + std, color=color, alpha=0.2, lw=0)
    if log_scale:
        ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.set_ylabel(f"{key} (mean squared error)" if key != "loss" else "loss")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def plot_reconstruction(run, dataset, sample: int, *, n_frames: int = 8) -> Figure:
    """Generated against ground-truth joints and frames for one sample (paper Appendix B).

    Parameters
    ----------
    run : primspace.train.TrainedRun
    dataset : primspace.data.MotionDataset
        The data file the run used (``run.indices`` index it).
    sample : int
        Index of the sample in ``dataset``; it must be one of the run's samples.
    n_frames : int
    """
    from primspace.errors import UserError
    from primspace.train import reconstruct

    rows = np.flatnonzero(run.indices == int(sample))
    if rows.size == 0:
        shown = ", ".join(map(str, run.indices[:5])) + (" ..." if len(run.indices) > 5 else "")
        raise UserError(f"sample {sample} is not one of the run's {len(run.indices)} samples ({shown})")
    if not 0 <= int(sample) < len(dataset):
        raise UserError(f"sample {sample} out of range for {len(dataset)} samples")
    row = int(rows[0])
    motor, frames = reconstruct(run, run.latents[row : row + 1])
    truth = dataset.subset([int(sample)])
    images = None if truth.images is None else np.asarray(truth.images)[0]
    label = "" if truth.labels is None or truth.labels[0] < 0 else f" (primitive {truth.label_names[truth.labels[0]]})"
    return plot_motion_sample(
        truth.motor[0], images, joint_names=truth.joint_names, generated_motor=motor[0],
        generated_images=None if frames is None or images is None else frames[0], n_frames=n_frames,
        dt=truth.dt, title=f"sample {sample}{label}: {run.kind} run, init {run.init}, q={run.model_config.latent_dim}",
    )



# ============================================================= experiments, report


def plot_intra_losses(runs: Sequence[dict], *, phase: str = "fit", key: str = "loss", title: str = "") -> Figure:
    """The paper's convergence figures: loss per epoch, one panel per latent size q.

    Parameters
    ----------
    runs : list of dict
        Intra-primitive run results (``init``, ``latent_dim``, ``seed``, and the per-epoch
        histories ``fit`` / ``infer``); several seeds of one (init, q) are drawn as mean ± std.
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
    fig.suptitle(f"Codes of primitive '{primitive_name}' (train and eval), first {n_components} principal components", fontsize=10)
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
        color = (colors or {}).get(name) or next((c for k, c in INIT_COLORS.items() if str(name).startswith(k)), None)
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
