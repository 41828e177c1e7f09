"""One motion: a strip of camera frames above its joint curves, recorded against generated.

What ``primspace show`` (:func:`plot_sim_sample`) and ``primspace reconstruct`` and the
paper's Appendix B (:func:`plot_reconstruction`) draw. Every function here takes arrays:
the generated motion is decoded by the caller (:func:`primspace.train.reconstruct`).
"""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

__all__ = [
    "plot_motion_sample",
    "plot_sim_sample",
    "plot_reconstruction",
    "plot_image_strips",
    "reconstruction_title",
    "step_segments",
]


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
    segments: Sequence[tuple[int, int, str]] | None = None,
    observed: np.ndarray | None = None,
    generated_keypoints: np.ndarray | None = None,
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
    segments : sequence of (start, stop, name), optional
        The primitives of a long demonstration, steps ``start`` to ``stop - 1`` each:
        drawn as coloured bands behind the curves, named above the first panel.
    observed : ndarray (T,) bool, optional
        The observed steps of a prediction: shaded grey, the rest is predicted.
    generated_keypoints : ndarray (T, K, 2), optional
        The keypoints the generated frames were drawn through (``x, y`` in [-1, 1],
        :func:`primspace.train.decode_keypoints`): dots on the generated strip.
    """
    motor = np.asarray(motor)
    t_len, n_joints = motor.shape
    names = list(joint_names) if joint_names is not None else [f"j{i}" for i in range(n_joints)]
    strips = [s for s in (images, generated_images) if s is not None]
    n_frames = min(n_frames, t_len)
    n_cols = 3 if n_joints > 4 else min(n_joints, 2)
    n_rows_j = int(np.ceil(n_joints / n_cols))
    fig = plt.figure(figsize=(2.0 * max(n_frames, 2 * n_cols), 1.4 * len(strips) + 1.9 * n_rows_j + 0.4))
    grid = fig.add_gridspec(
        len(strips) + n_rows_j, max(n_frames, 1), height_ratios=[1.2] * len(strips) + [1.6] * n_rows_j
    )
    dots = [None] * len(strips)
    if generated_images is not None and generated_keypoints is not None:
        dots[-1] = np.asarray(generated_keypoints)
    _frame_strips(fig, grid, strips, np.linspace(0, t_len - 1, n_frames).round().astype(int), dots)
    sub = grid[len(strips) :, :].subgridspec(n_rows_j, n_cols, hspace=0.6, wspace=0.25)
    axes = _joint_curves(fig, sub, motor, generated_motor, names, n_cols, n_rows_j, dt)
    _step_bands(axes, segments, observed, dt if dt else 1.0)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def _frame_strips(fig: Figure, grid, strips: list, frame_idx: np.ndarray, dots: list) -> None:
    """One row of frames per strip (recorded, then generated), times above the first;
    ``dots[row]`` (T, K, 2) or None: keypoints drawn on that strip's frames."""
    strip_labels = ["recorded", "generated"] if len(strips) == 2 else [None]
    for row, (strip, label, points) in enumerate(zip(strips, strip_labels, dots)):
        for col, t in enumerate(frame_idx):
            ax = fig.add_subplot(grid[row, col])
            ax.imshow(np.asarray(strip[t]))
            if points is not None:
                h, w = np.asarray(strip[t]).shape[:2]  # [-1, 1] to pixel centres
                x, y = (points[t, :, 0] + 1) / 2 * w - 0.5, (points[t, :, 1] + 1) / 2 * h - 0.5
                ax.scatter(x, y, s=9, c="yellow", edgecolors="black", linewidths=0.5)
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(f"t={t}", fontsize=8)
            if col == 0 and label:
                ax.set_ylabel(label, fontsize=8)


def _step_bands(axes: list, segments, observed, dt: float) -> None:
    """Behind every joint panel: a coloured band per segment (its name above the first
    panel) and the observed steps shaded grey (the legend says which is which)."""
    colors = plt.get_cmap("tab10").colors
    names = list(dict.fromkeys(name for _, _, name in segments or ()))
    for ax in axes:
        for start, stop, name in segments or ():
            ax.axvspan((start - 0.5) * dt, (stop - 0.5) * dt, color=colors[names.index(name) % 10], alpha=0.18, lw=0)
        if observed is not None and np.any(observed):
            ax.axvspan(
                -0.5 * dt,
                (np.flatnonzero(observed)[-1] + 0.5) * dt,
                color="0.6",
                alpha=0.3,
                lw=0,
                label="observed" if ax is axes[0] else None,
            )
    for start, stop, name in segments or ():
        axes[0].text(
            (start + stop - 1) / 2 * dt,
            1.02,
            name,
            transform=axes[0].get_xaxis_transform(),
            ha="center",
            va="bottom",
            fontsize=7,
            color=colors[names.index(name) % 10],
        )
    if observed is not None and np.any(observed):
        axes[0].legend(fontsize=7, loc="best")


def _joint_curves(fig: Figure, sub, motor, generated_motor, names, n_cols: int, n_rows_j: int, dt) -> list:
    """One panel per joint: ground truth (solid black), generated (dashed orange); the panels."""
    t_len, n_joints = motor.shape
    time = np.arange(t_len) * (dt if dt else 1.0)
    axes = []
    for j in range(n_joints):
        ax = fig.add_subplot(sub[j // n_cols, j % n_cols])
        axes.append(ax)
        ax.plot(time, motor[:, j], color="black", lw=1.4, label="ground truth" if generated_motor is not None else None)
        if generated_motor is not None:
            ax.plot(time, np.asarray(generated_motor)[:, j], color="tab:orange", lw=1.4, ls="--", label="generated")
        ax.set_title(names[j], fontsize=8)
        ax.tick_params(labelsize=7)
        if j == 0 and generated_motor is not None:
            ax.legend(fontsize=7, loc="best")
        if j // n_cols == n_rows_j - 1:
            ax.set_xlabel("time [s]" if dt else "step", fontsize=7)
    return axes


def plot_sim_sample(dataset, index: int, n_frames: int = 8) -> Figure:
    """One sample of a data set (simulated or not): frame strip and joint curves.

    The title names the sample, its source id (where it was recorded, for imported
    data), its primitive and, for simulated data, the block (``block_x``, ``block_y``,
    ``block_size`` in cm). What ``primspace show`` draws.

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
    if dataset.source_ids is not None:
        parts.append(str(dataset.source_ids[i]))
    if dataset.labels is not None and 0 <= int(dataset.labels[i]) < len(dataset.label_names):
        parts.append(dataset.label_names[int(dataset.labels[i])])
    if dataset.params is not None:
        values = dataset.params[i]
        cm = {"block_x", "block_y", "block_size"}
        parts.append(
            ", ".join(
                f"{n} {v * 100:.1f} cm" if n in cm else f"{n} {v:.4g}" for n, v in zip(dataset.param_names, values)
            )
        )
    valid = dataset.length if dataset.lengths is None else int(dataset.lengths[i])  # the padding is no part of it
    images = None if dataset.images is None else np.asarray(dataset.images[i])[:valid]
    observed = getattr(dataset, "observed", None)  # a prediction's observed steps, where the data set has them
    return plot_motion_sample(
        dataset.motor[i][:valid],
        images,
        joint_names=[n.removeprefix("robot:panda0_") for n in dataset.joint_names],
        n_frames=n_frames,
        dt=dataset.dt,
        title=" | ".join(parts),
        segments=step_segments(dataset, i),
        observed=None if observed is None else np.asarray(observed[i], dtype=bool)[:valid],
    )


def step_segments(dataset, index: int) -> list[tuple[int, int, str]] | None:
    """The segments of a long demonstration (its step fields) as ``(start, stop, name)``;
    None for a data set of single primitives."""
    if dataset.step_segments is None:
        return None
    i = int(index)
    valid = int(dataset.lengths[i])
    seg, lab = dataset.step_segments[i, :valid], dataset.step_labels[i, :valid]
    starts = np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]])
    stops = np.r_[starts[1:], valid]
    names = dataset.label_names
    return [(int(a), int(b), names[lab[a]] if 0 <= lab[a] < len(names) else "?") for a, b in zip(starts, stops)]


def plot_reconstruction(
    motor: np.ndarray,
    generated_motor: np.ndarray,
    *,
    images: np.ndarray | None = None,
    generated_images: np.ndarray | None = None,
    joint_names: Sequence[str] | None = None,
    dt: float | None = None,
    n_frames: int = 8,
    title: str = "",
    generated_keypoints: np.ndarray | None = None,
) -> Figure:
    """Generated against ground-truth joints and frames for one sample (paper Appendix B).

    The caller decodes the sample's code (:func:`primspace.train.reconstruct`); this only
    draws. Generated frames are shown only beside recorded ones.

    Parameters
    ----------
    motor, generated_motor : ndarray, shape (T, J)
        Recorded and generated joint values (physical units).
    images, generated_images : ndarray, shape (T, H, W, 3), uint8, optional
        Recorded and generated frames.
    joint_names : list of str, optional
    dt : float, optional
        Seconds per step.
    n_frames : int
        Frames shown per strip.
    title : str
        E.g. :func:`reconstruction_title`.
    generated_keypoints : ndarray (T, K, 2), optional
        Keypoints of a model that draws through them: dots on the generated frames.
    """
    return plot_motion_sample(
        motor,
        images,
        joint_names=joint_names,
        generated_motor=generated_motor,
        generated_images=None if images is None else generated_images,
        n_frames=n_frames,
        dt=dt,
        title=title,
        generated_keypoints=generated_keypoints,
    )


def plot_image_strips(
    strips: Sequence[tuple[str, np.ndarray, np.ndarray]], n_frames: int = 8, title: str = ""
) -> Figure:
    """Generated against recorded camera frames, one pair of rows per primitive.

    Parameters
    ----------
    strips : sequence of (name, recorded, generated)
        ``recorded`` and ``generated``: (T, H, W, 3) uint8 frames of one sample.
    n_frames : int
        Frames per row, evenly spaced in time (the same steps in every row).
    title : str
    """
    if not strips:
        raise ValueError("plot_image_strips needs at least one (name, recorded, generated) strip")
    t_len = min(min(len(rec), len(gen)) for _, rec, gen in strips)
    n_frames = min(n_frames, t_len)
    steps = np.linspace(0, t_len - 1, n_frames).round().astype(int)
    height, width = np.asarray(strips[0][1]).shape[1:3]
    fig_height = 1.3 * 2 * len(strips) + 0.8
    fig, axes = plt.subplots(
        2 * len(strips), n_frames, squeeze=False, figsize=(1.3 * n_frames * width / height + 0.5, fig_height)
    )
    for k, (name, recorded, generated) in enumerate(strips):
        for half, (frames, kind) in enumerate(((recorded, "recorded"), (generated, "generated"))):
            row = 2 * k + half
            for col, t in enumerate(steps):
                ax = axes[row, col]
                ax.imshow(np.asarray(frames[t]))
                ax.set_xticks([])
                ax.set_yticks([])
                if row == 0:
                    ax.set_title(f"t={t}", fontsize=8)
                if col == 0:
                    ax.set_ylabel(f"{name}\n{kind}", fontsize=7)
    fig.subplots_adjust(wspace=0.03, hspace=0.08, left=0.07, right=0.99, bottom=0.01, top=1 - 0.7 / fig_height)
    if title:
        fig.suptitle(title, fontsize=10, y=1 - 0.1 / fig_height, va="top")
    return fig


def reconstruction_title(sample: int, primitive: str | None, kind: str, init: str, latent_dim: int) -> str:
    """``sample 12 (primitive grasp): infer run, init projection, q=40``."""
    label = "" if primitive is None else f" (primitive {primitive})"
    return f"sample {sample}{label}: {kind} run, init {init}, q={latent_dim}"
