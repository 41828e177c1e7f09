"""Data and simulator commands: info, generate, show (import: :mod:`primspace.cli.importing`)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.options import check_workers, echo_json
from primspace.utils.errors import UserError

# the marks these commands write into their outputs (primspace.utils.outputs): --overwrite replaces only their own
_GENERATE_MARK, _SHOW_MARK = "primspace generate", "primspace show"

# ============================================================================ data


@app.command("info")
def info_command(
    file: Path = typer.Argument(..., metavar="DATA", help="A MotionDataset HDF5 file."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of text."),
) -> None:
    """Summarise a data set: N, T, J, joint names, source and source ids, label counts, images, joint ranges."""
    from primspace.data.dataset import MotionDataset

    summary = MotionDataset.load(file).summary()
    if as_json:
        echo_json(summary)
        return
    typer.echo(_format_summary(summary))


def _labels_line(counts: dict | None, per_step: bool) -> str:
    """The labels: samples per class; long demonstrations (``per_step``) are labelled step by
    step (the ``steps`` line), not as a whole: their classes only. A sample of no class
    (``-1``, ``<unknown>`` in the summary) counts as unlabelled."""
    if counts is None:
        return "  labels   none"
    unlabelled = counts.get("<unknown>", 0)
    classes = {k: v for k, v in counts.items() if k != "<unknown>"}
    if per_step and not any(classes.values()):
        return f"  labels   {len(classes)} classes, per step (below): {', '.join(classes)}"
    text = ", ".join(f"{k} {v}" for k, v in classes.items()) + (f"; unlabelled {unlabelled}" if unlabelled else "")
    return f"  labels   {len(classes)} classes: {text}"


def _format_summary(s: dict) -> str:
    lines = [
        f"{s['path'] or '<memory>'}",
        f"  samples  {s['n_samples']}    steps (T)  {s['length']}    joints (J)  {s['n_joints']}    dt  {s['dt']:.4g} s",
        f"  source   {s['source'] or '-'}",
    ]
    if s.get("source_ids") is not None:
        lines.append(f"  ids      {', '.join(s['source_ids'])}")
    img = s["image_shape"]
    lines.append(f"  images   {'x'.join(map(str, img)) + ' uint8 per sample' if img else 'none'}")
    steps = s.get("steps")
    lines.append(_labels_line(s["label_counts"], steps is not None))
    if steps is not None:
        lo, hi = steps["lengths"]
        lines.append(
            f"  long     valid steps {lo}..{hi} (padded to T), {steps['segments'][0]}..{steps['segments'][1]} "
            f"primitives each, {steps['n_segments']} segments in all"
        )
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
        "demo",
        "--preset",
        "-p",
        help="demo (126 motions) or paper (1715 motions, as in the paper); paper-varied: paper's in scenes that "
        "vary (--scene-variation varied); composite-demo "
        "or composite: long demonstrations of 2-4 primitives in a row, with per-step labels (joints only by default).",
    ),
    workers: int | None = typer.Option(None, "--workers", "-w", help="Processes (default: every usable core)."),
    backend: str = typer.Option("local", "--backend", help="local (process pool) or ray (identical data)."),
    address: str | None = typer.Option(None, "--address", help="Ray cluster address (default: a local Ray instance)."),
    seed: int = typer.Option(0, "--seed", help="Moves each block within its grid cell; same seed, same data."),
    height: int | None = typer.Option(None, "--height", help="Frame height in pixels (default 48)."),
    width: int | None = typer.Option(None, "--width", help="Frame width in pixels (default 64)."),
    no_images: bool = typer.Option(False, "--no-images", help="Joint values only (no rendering)."),
    block_jitter: str | None = typer.Option(
        None,
        "--block-jitter",
        help="each: every sample's block jittered on its own (every preset's default); shared: one jitter "
        "per primitive and grid cell, shared by the cell's block sizes (the paper's layout). Grid presets only.",
    ),
    scene_variation: str | None = typer.Option(
        None,
        "--scene-variation",
        help="none: the standard scene (the default but for paper-varied); varied: each sample's block and "
        "table colours, light, camera pose and a distractor drawn from its seed and recorded in the file "
        "(docs/data.md). Grid presets only.",
    ),
    config_file: Path | None = typer.Option(
        None,
        "--config",
        help="JSON object of generation settings over the preset's (block_x, block_y, "
        "block_size, primitives, length, jitter ...; see docs/simulator.md).",
    ),
    overwrite: bool = typer.Option(
        False,
        "--overwrite",
        help="Replace OUT if it is an earlier generate output (and discard shards left by a run with other settings).",
    ),
) -> None:
    """Simulate the seven motion primitives on a Panda arm (MuJoCo) into a data set file.

    Workers write shards beside OUT (.OUT.shards/), merged into OUT as they finish (OUT
    appears, atomically, when complete); a re-run after a failure or an interruption
    generates only the missing shards.
    """
    import time

    from primspace.sim import generate
    from primspace.sim.composite import COMPOSITE_PRESETS
    from primspace.sim.generate import generate_dataset
    from primspace.utils.outputs import output_file

    out = output_file(out, inputs=(config_file,), overwrite=overwrite, writer=_GENERATE_MARK)
    if preset in COMPOSITE_PRESETS:
        if block_jitter is not None:
            raise UserError(
                f"--block-jitter: --preset {preset} draws its blocks anywhere (no grid); it applies to paper and demo"
            )
        if scene_variation is not None:
            raise UserError(f"--scene-variation: --preset {preset} has the standard scene; it applies to grid presets")
        _generate_composite(
            out, preset, config_file, (height, width, no_images), workers, backend, address, seed, overwrite
        )
        return
    if preset not in generate.PRESETS:
        raise UserError(f"unknown preset {preset!r}; choose from {', '.join([*generate.PRESETS, *COMPOSITE_PRESETS])}")
    config = _generation_config(preset, config_file, height, width, no_images, block_jitter, scene_variation)
    check_workers(workers)
    start = time.perf_counter()
    shards = []
    ds = generate_dataset(
        config,
        seed=seed,
        workers=workers,
        backend=backend,
        address=address,
        out=out,
        overwrite=overwrite,
        on_shard=shards.append,
    )
    took = time.perf_counter() - start
    frames = f"images {config.height}x{config.width}" if config.images else "no images"
    reused = sum(shard["reused"] for shard in shards)
    resumed = f"; {reused} of {len(shards)} shards from an earlier run" if reused else ""
    typer.echo(
        f"wrote {out}: {len(ds)} motions x {ds.length} steps x {ds.n_joints} joints, {frames} "
        f"({took:.1f} s, {len(ds) / took:.1f} motions/s{resumed})"
    )


def _generation_config(preset: str, config_file, height, width, no_images: bool, block_jitter=None, scene=None):
    """The validated ``GenerationConfig`` of a single-primitive preset with --config, the frame flags,
    --block-jitter and --scene-variation (``scene``) over it."""
    import dataclasses

    from primspace.sim.config import BLOCK_JITTERS
    from primspace.sim.generate import GenerationConfig, resolve_config
    from primspace.sim.variation import VARIATIONS

    if block_jitter is not None and block_jitter not in BLOCK_JITTERS:
        raise UserError(f"--block-jitter {block_jitter!r}: choose from {', '.join(BLOCK_JITTERS)}")
    if scene is not None and scene not in VARIATIONS:
        raise UserError(f"--scene-variation {scene!r}: choose from {', '.join(VARIATIONS)}")

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
    if block_jitter is not None:
        changes["block_jitter"] = block_jitter
    if scene is not None:
        changes["scene_variation"] = scene
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


def _generate_composite(
    out: Path, preset: str, config_file, frames, workers, backend, address, seed, overwrite
) -> None:
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
    typer.echo(
        f"wrote {out}: {config.n_sequences} long demonstrations of {config.min_primitives}-{config.max_primitives} "
        f"primitives, T = {config.length} steps x 9 joints, {frames_text} ({took:.1f} s)"
    )


@app.command("show")
def show_command(
    file: Path = typer.Argument(..., metavar="DATA", help="A MotionDataset HDF5 file (e.g. from primspace generate)."),
    sample: int = typer.Option(0, "--sample", "-i", help="Sample index."),
    out: str = typer.Option(..., "--out", "-o", help="PNG file to write."),
    frames: int = typer.Option(8, "--frames", help="Camera frames in the strip (data with images)."),
    overwrite: bool = typer.Option(
        False, "--overwrite/--no-overwrite", help="Replace OUT if it is an earlier show output (nothing else)."
    ),
) -> None:
    """Draw one sample: a strip of camera frames and its joint curves."""
    from primspace.data.dataset import MotionDataset
    from primspace.plots import plot_sim_sample, save_figure
    from primspace.utils.outputs import output_file

    if frames < 1:
        raise UserError(f"--frames {frames}: must be at least 1")
    ds = MotionDataset.load(file)  # the input's errors first (reading writes nothing), then the output's
    if not 0 <= sample < len(ds):
        raise UserError(f"{file}: sample {sample} out of range 0..{len(ds) - 1}")
    out = output_file(out, inputs=(file,), overwrite=overwrite, writer=_SHOW_MARK)
    save_figure(plot_sim_sample(ds, sample, n_frames=frames), out, writer=_SHOW_MARK, overwrite=overwrite)
    typer.echo(f"wrote {out}" + ("" if ds.source_ids is None else f" (sample {sample}: {ds.source_id(sample)})"))
