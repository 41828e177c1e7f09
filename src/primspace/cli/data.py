"""Data and simulator commands: import, info, generate, show."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path
from typing import Optional

import typer

from primspace.errors import UserError

from primspace.cli.app import app
from primspace.cli.options import check_workers, echo_json, name_list


# ============================================================================ data


class ImportFormat(str, Enum):
    npz = "npz"
    csv = "csv"
    lasa = "lasa"
    robomimic = "robomimic"
    lerobot = "lerobot"


_FRAME_FORMATS = ("robomimic", "lerobot")  # formats that take --joints and --images
#: The most steps ``import -T`` resamples to: 100 s at 1 kHz. The arrays grow with T (N x T x J
#: float64 while resampling, N x T x H x W x 3 bytes of frames), so a larger T is a typo that
#: would end in a memory error, not a data set.
MAX_LENGTH = 100_000
# the marks these commands write into their outputs (primspace.outputs): --overwrite replaces only their own
_IMPORT_MARK, _GENERATE_MARK, _SHOW_MARK = "primspace import", "primspace generate", "primspace show"


@app.command("import")
def import_command(
    src: Optional[Path] = typer.Argument(
        None, help="A .npz file, a folder of CSV files, a robomimic .hdf5 file, a LeRobot data set folder, "
        "or nothing / 'lasa' for --format lasa."
    ),
    format: Optional[ImportFormat] = typer.Option(
        None, "--format", "-f", help="Input format; guessed from SRC when omitted."
    ),
    length: str = typer.Option(
        ..., "--length", "-T", metavar="T", help=f"Resample every sequence to T steps, 2 to {MAX_LENGTH:,} (memory "
        "grows with T: N x T x J x 8 bytes, and N x T x H x W x 3 with frames; 100,000 steps are 100 s at 1 kHz)."
    ),
    out: str = typer.Option(..., "--out", "-o", help="The HDF5 data set to write."),
    joints: Optional[str] = typer.Option(
        None, "--joints", help="robomimic: obs keys, comma-separated, concatenated in this order (required); "
        "lerobot: state features (default observation.state)."
    ),
    images: Optional[str] = typer.Option(
        None, "--images", help="robomimic: the obs key of the frames (e.g. agentview_image); "
        "lerobot: the camera feature (e.g. observation.images.top). npz: frames are read from 'images'."
    ),
    image_size: Optional[str] = typer.Option(
        None, "--image-size", help="HxW of the stored frames (default 48x64): resized with an anti-aliasing filter."
    ),
    shapes: Optional[str] = typer.Option(None, help="lasa: comma-separated shape names (default: 26 single-pattern shapes)."),
    velocities: bool = typer.Option(False, help="lasa: add velocities vx, vy as joints."),
    overwrite: bool = typer.Option(False, help="Replace OUT if it is an earlier import output (nothing else)."),
) -> None:
    """Import demonstrations (npz, CSV folder, LASA, robomimic HDF5, LeRobot) into a MotionDataset file.

    Frames: each step takes the recorded frame nearest in time, resized to --image-size.
    """
    from primspace.files import output_file

    length = _parse_length(length)
    source = None if src is None or str(src).lower() == "lasa" else src
    out = output_file(out, inputs=(source,), overwrite=overwrite, writer=_IMPORT_MARK)
    fmt = format.value if format is not None else _guess_format(src)
    _check_import_options(fmt, joints, images, image_size)
    if fmt == "lasa":
        from primspace.data.importers import import_lasa

        names = [s.strip() for s in shapes.split(",") if s.strip()] if shapes else None
        ds = import_lasa(length, shapes=names, velocities=velocities)
    elif src is None:
        raise UserError(f"--format {fmt} needs a source path")
    else:
        ds = _import_file(fmt, src, length, joints, images, _parse_image_size(image_size))
    ds.save(out, overwrite=overwrite, writer=_IMPORT_MARK)
    frames = f", frames {ds.image_size[0]}x{ds.image_size[1]}" if ds.has_images else ""
    typer.echo(f"wrote {out}: {len(ds)} samples x {ds.length} steps x {ds.n_joints} joints{frames}")


def _import_file(fmt: str, src: Path, length: int, joints: Optional[str], images: Optional[str], size):
    """Run the importer of ``fmt`` on ``src``."""
    from primspace.data import importers

    if fmt == "npz":
        return importers.import_npz(src, length, image_size=size)
    if fmt == "csv":
        return importers.import_csv_folder(src, length)
    keys = name_list(joints, "--joints") if joints is not None else None
    if fmt == "robomimic":
        return importers.import_robomimic(src, length, joints=keys or (), images=images, image_size=size)
    return importers.import_lerobot(
        src, length, joints=keys or ("observation.state",), images=images, image_size=size
    )


def _check_import_options(fmt: str, joints, images, image_size) -> None:
    """Refuse flags the format does not take (one line naming the flag)."""
    if fmt not in _FRAME_FORMATS:
        for flag, value in (("--joints", joints), ("--images", images)):
            if value is not None:
                raise UserError(f"{flag} applies to --format robomimic or lerobot, not {fmt}")
    if image_size is not None and (fmt in ("csv", "lasa") or (fmt in _FRAME_FORMATS and not images)):
        raise UserError(f"--image-size {image_size}: there are no frames to resize (--format {fmt}"
                        f"{' without --images' if fmt in _FRAME_FORMATS else ''})")


def _parse_length(text: str) -> int:
    """``-T``: a whole number of steps from 2 to :data:`MAX_LENGTH` (one line otherwise)."""
    value = text.strip()
    if not (value.isascii() and value.isdigit()):  # "1e30", "2.5", "-3", "²": not a count of steps
        raise UserError(f"--length {text}: must be a whole number of steps from 2 to {MAX_LENGTH:,}")
    if len(value) > 9 or int(value) > MAX_LENGTH:
        raise UserError(f"--length {text}: at most {MAX_LENGTH:,} steps (100 s at 1 kHz); the arrays grow with T "
                        "(N x T x J x 8 bytes, N x T x H x W x 3 with frames), a longer T is a typo that would "
                        "run out of memory")
    if int(value) < 2:
        raise UserError(f"--length {text}: must be at least 2 steps (a first and a last)")
    return int(value)


def _parse_image_size(text: Optional[str]) -> tuple[int, int]:
    """``"48x64"`` -> ``(48, 64)``, a size the decoder's image head can produce."""
    from primspace.data.importers import DEFAULT_IMAGE_SIZE
    from primspace.model_config import ModelConfig, check_image_size

    if text is None:
        return DEFAULT_IMAGE_SIZE
    parts = text.lower().replace(" ", "").split("x")
    if len(parts) != 2 or not all(p.isdigit() and int(p) > 0 for p in parts):
        raise UserError(f"--image-size must be HxW in pixels, e.g. 48x64; got '{text}'")
    size = (int(parts[0]), int(parts[1]))
    try:
        check_image_size(size, ModelConfig().image_channels)
    except UserError as exc:
        raise UserError(f"--image-size {text}: {exc}") from None
    return size


def _guess_format(src: Optional[Path]) -> str:
    """The format of ``src``; an HDF5 file is robomimic only when it is a ``.hdf5`` file with
    ``data/demo_N`` groups (a ``.h5`` file is usually a primspace data set already)."""
    if src is None or str(src).lower() == "lasa":
        return "lasa"
    if src.is_dir():
        from primspace.data.importers import is_lerobot_dir

        return "lerobot" if is_lerobot_dir(src) else "csv"
    suffix = src.suffix.lower()
    if suffix == ".npz":
        return "npz"
    if suffix == ".hdf5":
        from primspace.data.importers import looks_like_robomimic

        if not src.exists() or looks_like_robomimic(src):
            return "robomimic"
        raise UserError(f"{src}: cannot tell the format (an HDF5 file without data/demo_N groups); pass --format")
    if suffix == ".h5":
        raise UserError(
            f"{src}: cannot tell the format of a .h5 file (usually a primspace data set, which needs no import); "
            "pass --format robomimic for a robomimic-style file"
        )
    raise UserError(f"{src}: cannot tell the format; pass --format npz|csv|lasa|robomimic|lerobot")


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
    steps = s.get("steps")
    if steps is not None:
        lo, hi = steps["lengths"]
        lines.append(f"  long     valid steps {lo}..{hi} (padded to T), {steps['segments'][0]}..{steps['segments'][1]} "
                     f"primitives each, {steps['n_segments']} segments in all")
        lines.append("  steps    " + ", ".join(f"{k} {v}" for k, v in steps["steps_per_label"].items()))
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
    preset: str = typer.Option(
        "demo", "--preset", "-p", help="demo (126 motions) or paper (1715 motions, as in the paper); composite-demo "
        "or composite: long demonstrations of 2-4 primitives in a row, with per-step labels (joints only by default).",
    ),
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
        False, "--overwrite", help="Replace OUT if it is an earlier generate output (and discard shards left by a run "
        "with other settings)."
    ),
) -> None:
    """Simulate the seven motion primitives on a Panda arm (MuJoCo) into a data set file.

    Workers write shards beside OUT (.OUT.shards/), merged into OUT as they finish (OUT
    appears, atomically, when complete); a re-run after a failure or an interruption
    generates only the missing shards.
    """
    import time

    from primspace.files import output_file
    from primspace.sim import generate
    from primspace.sim.composite import COMPOSITE_PRESETS
    from primspace.sim.generate import generate_dataset

    out = output_file(out, inputs=(config_file,), overwrite=overwrite, writer=_GENERATE_MARK)
    if preset in COMPOSITE_PRESETS:
        _generate_composite(out, preset, config_file, (height, width, no_images), workers, backend, address, seed, overwrite)
        return
    if preset not in generate.PRESETS:
        raise UserError(f"unknown preset {preset!r}; choose from {', '.join([*generate.PRESETS, *COMPOSITE_PRESETS])}")
    config = _generation_config(preset, config_file, height, width, no_images)
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


def _generation_config(preset: str, config_file, height, width, no_images: bool):
    """The validated ``GenerationConfig`` of a single-primitive preset with --config and the frame flags over it."""
    import dataclasses

    from primspace.sim.generate import GenerationConfig, resolve_config

    config = resolve_config(preset)
    if config_file is not None:
        settings = _settings_file(config_file)
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
        return resolve_config(config)
    except UserError as exc:
        raise UserError(f"{config_file}: {exc}" if config_file is not None else str(exc)) from None


def _settings_file(config_file: Path) -> dict:
    """The JSON object of generation settings in ``config_file`` (one-line error otherwise)."""
    try:
        return json.loads(config_file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UserError(f"{config_file}: cannot read a JSON object of settings ({exc})") from None


def _generate_composite(out: Path, preset: str, config_file, frames, workers, backend, address, seed, overwrite) -> None:
    """``generate`` for a composite preset (:mod:`primspace.sim.composite`): --config takes
    ``CompositeConfig`` fields over the preset's; --height/--width turn frames on."""
    import time

    from primspace.sim.composite import COMPOSITE_PRESETS, generate_composite, resolve_composite

    if backend != "local" or address is not None:
        raise UserError(f"--preset {preset}: long demonstrations are generated locally (no --backend ray or --address)")
    settings = COMPOSITE_PRESETS[preset].to_dict()
    if config_file is not None:
        extra = _settings_file(config_file)
        if not isinstance(extra, dict):
            raise UserError(f"{config_file}: composite settings must be a JSON object")
        settings |= extra
    height, width, no_images = frames
    if no_images:
        settings["image_size"] = None
    elif height is not None or width is not None:
        h, w = settings["image_size"] or (48, 64)
        settings["image_size"] = (h if height is None else height, w if width is None else width)
    try:
        config = resolve_composite(settings)
    except UserError as exc:
        raise UserError(f"{config_file}: {exc}" if config_file is not None else str(exc)) from None
    check_workers(workers)
    start = time.perf_counter()
    generate_composite(config, seed=seed, out=out, overwrite=overwrite, workers=workers)
    took = time.perf_counter() - start
    frames_text = f"images {config.image_size[0]}x{config.image_size[1]}" if config.image_size else "no images"
    typer.echo(f"wrote {out}: {config.n_sequences} long demonstrations of {config.min_primitives}-{config.max_primitives} "
               f"primitives, T = {config.length} steps x 9 joints, {frames_text} ({took:.1f} s)")


@app.command("show")
def show_command(
    file: Path = typer.Argument(..., help="A MotionDataset HDF5 file (e.g. from primspace generate)."),
    sample: int = typer.Option(0, "--sample", "-i", help="Sample index."),
    out: str = typer.Option(..., "--out", "-o", help="PNG file to write."),
    frames: int = typer.Option(8, "--frames", help="Camera frames in the strip."),
    overwrite: bool = typer.Option(
        False, "--overwrite/--no-overwrite", help="Replace OUT if it is an earlier show output (nothing else)."
    ),
) -> None:
    """Draw one sample: a strip of camera frames and its joint curves."""
    from primspace.data.dataset import MotionDataset
    from primspace.files import output_file
    from primspace.plots import plot_sim_sample, save_figure

    if frames < 1:
        raise UserError(f"--frames {frames}: must be at least 1")
    ds = MotionDataset.load(file)  # the input's errors first (reading writes nothing), then the output's
    if not 0 <= sample < len(ds):
        raise UserError(f"{file}: sample {sample} out of range 0..{len(ds) - 1}")
    out = output_file(out, inputs=(file,), overwrite=overwrite, writer=_SHOW_MARK)
    save_figure(plot_sim_sample(ds, sample, n_frames=frames), out, writer=_SHOW_MARK, overwrite=overwrite)
    typer.echo(f"wrote {out}")
