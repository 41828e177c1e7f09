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

__all__ = ["save_figure", "plot_motion_sample"]

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


# ==================================================================== clustering


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
        ``loss_inter``).
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
            ax.fill_between(epochs, mean - std, mean + std, color=color, alpha=0.2, lw=0)
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
