"""Motion command: animate (one sample as an animated GIF)."""

from __future__ import annotations

from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.options import configure_threads, device_option, threads_option
from primspace.cli.train import run_sample

# primspace.plots.animation.MAX_FRAMES, repeated so that `primspace --help` does not load
# matplotlib (tests/test_animate.py checks that the two agree).
_MAX_FRAMES = 30
#: The mark ``animate`` writes into its GIF (primspace.utils.outputs).
_ANIMATE_MARK = "primspace animate"


@app.command("animate")
def animate_command(
    run: Path = typer.Argument(..., help="A run directory (fit or infer)."),
    sample: int = typer.Option(..., "--sample", help="Sample index in the data file (one the run used)."),
    out: str = typer.Option(..., "--out", "-o", help="The GIF to write."),
    data: Path | None = typer.Option(None, "--data", help="The data file (default: the run's)."),
    frames: int = typer.Option(
        _MAX_FRAMES, "--frames", help="Most frames in the GIF (time is subsampled evenly; at least 2)."
    ),
    no_replay: bool = typer.Option(
        False, "--no-replay", help="Leave out the simulator replaying the generated joints."
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUT if it is an earlier animate output."),
    device: str = device_option("cpu"),
    threads: int | None = threads_option(),
) -> None:
    """Animate one sample as a GIF: recorded, generated and simulator-replayed frames beside a joint trace.

    The replay panel needs simulator data (the Panda's joints, the seven primitives); for other data it is left out and the title says so.
    """
    from primspace.experiments.animations import sample_motion
    from primspace.plots import draw_animation

    configure_threads(threads, device)
    out, trained, ds, _ = run_sample(run, sample, out, data, frames, overwrite, min_frames=2, writer=_ANIMATE_MARK)
    arrays, info = sample_motion(trained, ds, sample, replay=not no_replay, device=device)
    draw_animation(
        out,
        **arrays,
        joint_names=info["joint_names"],
        dt=info["dt"],
        title=info["title"],
        max_frames=frames,
        writer=_ANIMATE_MARK,
        overwrite=overwrite,
    )
    panels = ", ".join(info["panels"]) or "no camera frames"
    note = f"; {info['note']}" if info["note"] else ""
    typer.echo(f"wrote {out} ({out.stat().st_size // 1024} kB; panels: {panels}, joint trace{note})")
