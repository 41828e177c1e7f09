"""Data and simulator commands: import, info, generate, show."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path
from typing import Optional

import typer

from primspace.errors import UserError

from primspace.cli.app import app
from primspace.cli.options import check_workers, echo_json


# ============================================================================ data


class ImportFormat(str, Enum):
    npz = "npz"
    csv = "csv"
    lasa = "lasa"


@app.command("import")
def import_command(
    src: Optional[Path] = typer.Argument(
        None, help="A .npz file, a folder of CSV files, or nothing / 'lasa' for --format lasa."
    ),
    format: Optional[ImportFormat] = typer.Option(
        None, "--format", "-f", help="Input format; guessed from SRC when omitted."
    ),
    length: int = typer.Option(..., "--length", "-T", help="Resample every sequence to T steps."),
    out: str = typer.Option(..., "--out", "-o", help="The HDF5 data set to write."),
    shapes: Optional[str] = typer.Option(None, help="lasa: comma-separated shape names (default: 26 single-pattern shapes)."),
    velocities: bool = typer.Option(False, help="lasa: add velocities vx, vy as joints."),
    overwrite: bool = typer.Option(False, help="Replace OUT if it exists."),
) -> None:
    """Import demonstrations (npz, CSV folder, LASA) into a MotionDataset file."""
    from primspace.data.importers import import_csv_folder, import_lasa, import_npz
    from primspace.files import output_file

    source = None if src is None or str(src).lower() == "lasa" else src
    out = output_file(out, inputs=(source,), overwrite=overwrite)
    fmt = format.value if format is not None else _guess_format(src)
    if fmt == "lasa":
        names = [s.strip() for s in shapes.split(",") if s.strip()] if shapes else None
        ds = import_lasa(length, shapes=names, velocities=velocities)
    elif src is None:
        raise UserError(f"--format {fmt} needs a source path")
    elif fmt == "npz":
        ds = import_npz(src, length)
    else:
        ds = import_csv_folder(src, length)
    ds.save(out, overwrite=overwrite)
    typer.echo(f"wrote {out}: {len(ds)} samples x {ds.length} steps x {ds.n_joints} joints")


def _guess_format(src: Optional[Path]) -> str:
    if src is None or str(src).lower() == "lasa":
        return "lasa"
    if src.is_dir():
        return "csv"
    if src.suffix.lower() == ".npz":
        return "npz"
    raise UserError(f"{src}: cannot tell the format; pass --format npz|csv|lasa")


@app.command("info")
def info_command(
    file: Path = typer.Argument(..., help="A MotionDataset HDF5 file."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of text."),
) -> None:
    """Summarise a data set: N, T, J, joint names, label counts, images, joint ranges."""
    from primspace.data.dataset import MotionDataset

    summary = MotionDataset.load(file).summary()
    if as_json:
        echo_json(summary)
        return
    typer.echo(_format_summary(summary))


def _format_summary(s: dict) -> str:
    lines = [
        f"{s['path'] or '<memory>'}",
        f"  samples  {s['n_samples']}    steps (T)  {s['length']}    joints (J)  {s['n_joints']}    dt  {s['dt']:.4g} s",
        f"  source   {s['source'] or '-'}",
    ]
    img = s["image_shape"]
    lines.append(f"  images   {'x'.join(map(str, img)) + ' uint8 per sample' if img else 'none'}")
    if s["label_counts"] is None:
        lines.append("  labels   none")
    else:
        counts = ", ".join(f"{k} {v}" for k, v in s["label_counts"].items())
        lines.append(f"  labels   {len(s['label_counts'])} classes: {counts}")
    lines.append("  joint ranges (physical units):")
    width = max(len(n) for n in s["joint_ranges"])
    for name, (lo, hi) in s["joint_ranges"].items():
        lines.append(f"    {name:<{width}}  [{lo:.5g}, {hi:.5g}]")
    for name, (lo, hi) in s.get("param_ranges", {}).items():
        lines.append(f"    param {name}  [{lo:.5g}, {hi:.5g}]")
    return "\n".join(lines)


# ======================================================================= simulator


@app.command("generate")
def generate_command(
    out: str = typer.Option(..., "--out", "-o", help="The HDF5 data set to write."),
    preset: str = typer.Option("demo", "--preset", "-p", help="demo (126 motions) or paper (1715 motions, as in the paper)."),
    workers: Optional[int] = typer.Option(None, "--workers", "-w", help="Processes (default: every usable core)."),
    backend: str = typer.Option("local", "--backend", help="local (process pool) or ray (identical data)."),
    address: Optional[str] = typer.Option(None, "--address", help="Ray cluster address (default: a local Ray instance)."),
    seed: int = typer.Option(0, "--seed", help="Moves each block within its grid cell; same seed, same data."),
    height: Optional[int] = typer.Option(None, "--height", help="Frame height in pixels (default 48)."),
    width: Optional[int] = typer.Option(None, "--width", help="Frame width in pixels (default 64)."),
    no_images: bool = typer.Option(False, "--no-images", help="Joint values only (no rendering)."),
    config_file: Optional[Path] = typer.Option(
        None, "--config", help="JSON object of generation settings over the preset's (block_x, block_y, "
        "block_size, primitives, length, jitter ...; see docs/simulator.md).",
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace OUT if it exists (and discard shards left by a run with other settings)."
    ),
) -> None:
    """Simulate the seven motion primitives on a Panda arm (MuJoCo) into a data set file.

    Workers write shards beside OUT (.OUT.shards/), merged into OUT as they finish (OUT
    appears, atomically, when complete); a re-run after a failure or an interruption
    generates only the missing shards.
    """
    import dataclasses
    import time

    from primspace.files import output_file
    from primspace.sim.generate import GenerationConfig, generate_dataset, resolve_config

    out = output_file(out, inputs=(config_file,), overwrite=overwrite)
    config = resolve_config(preset)
    if config_file is not None:
        try:
            settings = json.loads(config_file.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise UserError(f"{config_file}: cannot read a JSON object of settings ({exc})") from None
        try:
            config = GenerationConfig.from_dict(settings, base=config)
        except UserError as exc:
            raise UserError(f"{config_file}: {exc}") from None
    changes = {"images": False} if no_images else {}
    if height is not None:
        changes["height"] = height
    if width is not None:
        changes["width"] = width
    config = dataclasses.replace(config, **changes)
    try:
        config = resolve_config(config)
    except UserError as exc:
        raise UserError(f"{config_file}: {exc}" if config_file is not None else str(exc)) from None
    check_workers(workers)
    start = time.perf_counter()
    shards = []
    ds = generate_dataset(config, seed=seed, workers=workers, backend=backend, address=address, out=out,
                          overwrite=overwrite, on_shard=shards.append)
    took = time.perf_counter() - start
    frames = f"images {config.height}x{config.width}" if config.images else "no images"
    reused = sum(shard["reused"] for shard in shards)
    resumed = f"; {reused} of {len(shards)} shards from an earlier run" if reused else ""
    typer.echo(
        f"wrote {out}: {len(ds)} motions x {ds.length} steps x {ds.n_joints} joints, {frames} "
        f"({took:.1f} s, {len(ds) / took:.1f} motions/s{resumed})"
    )


@app.command("show")
def show_command(
    file: Path = typer.Argument(..., help="A MotionDataset HDF5 file (e.g. from primspace generate)."),
    sample: int = typer.Option(0, "--sample", "-i", help="Sample index."),
    out: str = typer.Option(..., "--out", "-o", help="PNG file to write."),
    frames: int = typer.Option(8, "--frames", help="Camera frames in the strip."),
    overwrite: bool = typer.Option(True, "--overwrite/--no-overwrite", help="Replace OUT if it exists."),
) -> None:
    """Draw one sample: a strip of camera frames and its joint curves."""
    from primspace.data.dataset import MotionDataset
    from primspace.files import output_file
    from primspace.plots import plot_sim_sample, save_figure

    out = output_file(out, inputs=(file,), overwrite=overwrite)
    if frames < 1:
        raise UserError(f"--frames {frames}: must be at least 1")
    ds = MotionDataset.load(file)
    if not 0 <= sample < len(ds):
        raise UserError(f"{file}: sample {sample} out of range 0..{len(ds) - 1}")
    save_figure(plot_sim_sample(ds, sample, n_frames=frames), out)
    typer.echo(f"wrote {out}")
