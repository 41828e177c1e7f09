"""One motion as an animated GIF: camera panels side by side with a joint-angle trace.

What ``primspace animate`` writes and the report embeds, one per primitive. Panels (each
optional): the recorded frames, the generated frames, and the simulator replaying the
generated joints; to their right the recorded (solid) and generated (dashed) joint values
of every joint against time, with a cursor at the frame's time step. Drawn from arrays
alone: the caller decodes the code (:func:`primspace.train.reconstruct`) and replays the
joints (:func:`primspace.sim.render.replay_frames`).

**Size bound.** At most :data:`MAX_FRAMES` frames (time is subsampled evenly, the first
and last step kept) of at most :data:`MAX_SIZE` pixels (the resolution is lowered to fit),
in one shared palette of 255 colours with no dithering; Pillow writes each frame after the
first as its change from the one before (unchanged pixels transparent). Measured on the
demo's 61-step, 48 x 64 motions, 30 frames of 608 x 184 pixels: 80-105 kB with the recorded
and replay panels, about 130 kB with generated frames as well (760 x 184).

Encoded with Pillow (no ffmpeg): matplotlib (Agg) draws the figure once, then each frame
redraws only the panels' images and the cursor (blitting).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from PIL import Image

from primspace.utils.files import atomic_path
from primspace.utils.outputs import gif_comment

__all__ = ["animation_frames", "save_gif", "draw_animation", "frame_steps", "MAX_FRAMES", "MAX_SIZE", "FRAME_MS"]

#: Most frames an animation holds (the motion's steps are subsampled evenly to fit).
MAX_FRAMES = 30

#: Largest (height, width) of an animation in pixels.
MAX_SIZE = (280, 800)

#: Display time of each frame (ms): playback is not real time (the demo's motions last a
#: minute); the trace's time axis gives the real time.
FRAME_MS = 150

# colours every palette holds exactly: the background, text and cursor
_EXACT = ((255, 255, 255), (0, 0, 0))

_DPI = 80
_PANEL_IN = 1.9  # inches per camera panel (4:3 frames)
_TRACE_IN = 3.8  # inches of the joint trace
_HEIGHT_IN = 2.3


def frame_steps(length: int, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """The time steps shown: ``min(max_frames, length)`` evenly spaced, first and last kept."""
    if length < 1 or max_frames < 1:
        raise ValueError(f"need at least one step and one frame, got length {length}, max_frames {max_frames}")
    return np.unique(np.linspace(0, length - 1, min(int(max_frames), int(length))).round().astype(int))


def animation_frames(
    motor: np.ndarray,
    generated_motor: np.ndarray | None = None,
    *,
    images: np.ndarray | None = None,
    generated_images: np.ndarray | None = None,
    replay_images: np.ndarray | None = None,
    joint_names: Sequence[str] | None = None,
    dt: float | None = None,
    title: str = "",
    max_frames: int = MAX_FRAMES,
    max_size: tuple[int, int] = MAX_SIZE,
    panel_titles: Sequence[str] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Draw the animation's frames as RGB arrays.

    Parameters
    ----------
    motor : ndarray, shape (T, J)
        Recorded joint values.
    generated_motor : ndarray, shape (T, J), optional
        Generated joint values (dashed).
    images, generated_images, replay_images : ndarray, shape (T, H, W, 3), uint8, optional
        Recorded frames, generated frames, and the simulator's replay of the generated
        joints; each given one is a panel, in this order.
    joint_names : list of str, optional
        Shown beside the trace (the ``robot:panda0_`` prefix dropped).
    dt : float, optional
        Seconds per step (the time axis is in steps otherwise).
    title : str
    max_frames : int
        At most this many frames (:func:`frame_steps`).
    max_size : (int, int)
        At most this many pixels (height, width).
    panel_titles : list of str, optional
        The panels' titles, in order (default: "recorded", "generated", "simulator replay"); the
        first two also name the solid and dashed joint traces.

    Returns
    -------
    frames : ndarray, shape (n, h, w, 3), uint8
        ``n <= max_frames``, ``h, w <= max_size``.
    steps : ndarray, shape (n,)
        The time step of each frame.
    """
    motor = np.asarray(motor, dtype=float)
    steps = frame_steps(len(motor), max_frames)
    panels = [
        (label, np.asarray(a))
        for label, a in (("recorded", images), ("generated", generated_images), ("simulator replay", replay_images))
        if a is not None
    ]
    if panel_titles is not None:
        if len(panel_titles) != len(panels):
            raise ValueError(f"{len(panel_titles)} panel titles for {len(panels)} panels")
        panels = [(str(t), a) for t, (_, a) in zip(panel_titles, panels)]
    for label, frames in panels:
        if frames.ndim != 4 or len(frames) != len(motor):
            raise ValueError(f"{label} frames must have shape ({len(motor)}, H, W, 3), got {frames.shape}")
    fig, artists, cursor = _figure(
        motor,
        generated_motor,
        panels,
        joint_names,
        dt,
        title,
        max_size,
        None if panel_titles is None else panel_titles[:2],
    )
    try:
        return _blit(fig, artists, panels, cursor, steps, dt), steps
    finally:
        plt.close(fig)


def _figure(motor, generated_motor, panels, joint_names, dt, title, max_size, panels_named=None):
    """The figure with its static parts; the panels' images and the cursor are animated."""
    width_in = _PANEL_IN * len(panels) + _TRACE_IN
    dpi = min(_DPI, max_size[1] / width_in, max_size[0] / _HEIGHT_IN)
    fig = plt.figure(figsize=(width_in, _HEIGHT_IN), dpi=dpi)
    grid = fig.add_gridspec(
        1,
        len(panels) + 1,
        width_ratios=[_PANEL_IN] * len(panels) + [_TRACE_IN - 0.9],
        left=0.02,
        right=0.99 - 0.85 / width_in,
        top=0.80,
        bottom=0.22,
        wspace=0.12,
    )
    artists = []
    for k, (label, frames) in enumerate(panels):
        ax = fig.add_subplot(grid[0, k])
        artists.append(ax.imshow(frames[0], animated=True, interpolation="nearest"))
        ax.set_axis_off()
        ax.set_title(label, fontsize=7)
    trace = fig.add_subplot(grid[0, len(panels)])
    time = np.arange(len(motor)) * (dt if dt else 1.0)
    n = motor.shape[1]
    colors = plt.get_cmap("tab10")(np.arange(n)) if n <= 10 else plt.get_cmap("turbo")(np.linspace(0, 1, n))
    names = [str(name).removeprefix("robot:panda0_") for name in (joint_names or [f"j{j}" for j in range(n)])]
    for j in range(n):
        trace.plot(time, motor[:, j], color=colors[j], lw=1.0, label=names[j])
        if generated_motor is not None:
            trace.plot(time, np.asarray(generated_motor)[:, j], color=colors[j], lw=1.0, ls="--")
    names = ("recorded", "generated") if panels_named is None else panels_named
    trace.set_title(f"joints: {names[0]} —, {names[1]} --" if generated_motor is not None else "joints", fontsize=7)
    trace.set_xlabel("time [s]" if dt else "step", fontsize=6, labelpad=1)
    trace.tick_params(labelsize=6, pad=1)
    trace.set_xlim(time[0], time[-1] if len(time) > 1 else time[0] + 1)
    if n <= 10:
        trace.legend(
            fontsize=5.5,
            loc="upper left",
            bbox_to_anchor=(1.0, 1.05),
            frameon=False,
            handlelength=1.0,
            borderaxespad=0.2,
            labelspacing=0.25,
        )
    cursor = trace.axvline(time[0], color="black", lw=1.2, animated=True)
    if title:
        fig.suptitle(title, fontsize=7, y=0.97)
    return fig, artists, cursor


def _blit(fig, artists, panels, cursor, steps, dt) -> np.ndarray:
    """Each frame: the static background, then the panels at step t and the cursor."""
    canvas = fig.canvas
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    height, width = canvas.get_width_height()[::-1]
    out = np.empty((len(steps), height, width, 3), dtype=np.uint8)
    for i, t in enumerate(steps):
        canvas.restore_region(background)
        for artist, (_, frames) in zip(artists, panels):
            artist.set_data(frames[t])
            artist.axes.draw_artist(artist)
        x = t * (dt if dt else 1.0)
        cursor.set_xdata([x, x])
        cursor.axes.draw_artist(cursor)
        out[i] = np.asarray(canvas.buffer_rgba())[..., :3]
    return out


def save_gif(
    frames: np.ndarray,
    path: str | os.PathLike,
    frame_ms: int = FRAME_MS,
    *,
    writer: str | None = None,
    overwrite: bool = True,
) -> Path:
    """Write RGB frames ``(n, h, w, 3)`` as a looping animated GIF, atomically.

    ``writer`` (a command's mark) is stored as the GIF's comment
    (:func:`primspace.utils.outputs.gif_comment`); ``overwrite=False`` never replaces an
    existing ``path`` (:func:`primspace.utils.files.atomic_path`).

    One palette of at most 255 colours maps every frame without dithering, so unchanged
    pixels keep their colour and Pillow stores them as transparent (an index is left free
    for that). It is Pillow's maximum-coverage quantisation of up to four frames spread
    over the motion, plus exact white and black, which the background, text and cursor
    keep (Pillow's mapping to a given palette is approximate; these are set exactly).
    """
    frames = np.asarray(frames, dtype=np.uint8)
    if frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) < 1:
        raise ValueError(f"frames must have shape (n, h, w, 3), got {frames.shape}")
    picks = np.unique(np.linspace(0, len(frames) - 1, min(4, len(frames))).round().astype(int))
    quantized = Image.fromarray(np.concatenate(frames[picks], axis=0)).quantize(
        colors=255 - len(_EXACT), method=Image.Quantize.MAXCOVERAGE, dither=Image.Dither.NONE
    )
    colours = quantized.getpalette()[: 3 * (255 - len(_EXACT))]
    first_exact = len(colours) // 3
    colours += [c for rgb in _EXACT for c in rgb]
    palette = Image.new("P", (1, 1))
    palette.putpalette(colours)
    images = []
    for frame in frames:
        index = np.array(Image.fromarray(frame).quantize(palette=palette, dither=Image.Dither.NONE))
        for k, rgb in enumerate(_EXACT):
            index[(frame == np.array(rgb, dtype=np.uint8)).all(axis=-1)] = first_exact + k
        image = Image.frombytes("P", (index.shape[1], index.shape[0]), index.tobytes())
        image.putpalette(colours)
        images.append(image)
    path = Path(path)
    with atomic_path(path, overwrite) as tmp:
        images[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=int(frame_ms),
            loop=0,
            optimize=True,
            **gif_comment(writer),
        )
    return path


def draw_animation(
    path: str | os.PathLike,
    motor: np.ndarray,
    generated_motor: np.ndarray | None = None,
    *,
    frame_ms: int = FRAME_MS,
    writer: str | None = None,
    overwrite: bool = True,
    **kwargs,
) -> Path:
    """:func:`animation_frames` written by :func:`save_gif` to ``path`` (``writer``,
    ``overwrite`` as there); other keyword arguments as :func:`animation_frames`'s.
    Returns ``path``."""
    frames, _ = animation_frames(motor, generated_motor, **kwargs)
    return save_gif(frames, path, frame_ms, writer=writer, overwrite=overwrite)
