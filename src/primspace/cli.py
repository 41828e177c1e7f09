"""The ``primspace`` command.

Each command parses its flags and calls the library; the work lives in the modules.
A :class:`~primspace.errors.UserError` raised anywhere below is printed as one line,
``primspace: error: ...``, with exit status 2 and no traceback.
"""

from __future__ import annotations

import json
import sys
from enum import Enum
from pathlib import Path
from typing import Optional

import typer

from primspace.errors import UserError

app = typer.Typer(
    name="primspace",
    help="Latent spaces of robot motion primitives (Nikulin & Tani): data, simulator, "
    "MTRNN decoder, subspace clustering, experiments.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _echo_json(obj) -> None:
    typer.echo(json.dumps(obj, indent=2))


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
    out: Path = typer.Option(..., "--out", "-o", help="The HDF5 data set to write."),
    shapes: Optional[str] = typer.Option(None, help="lasa: comma-separated shape names (default: 26 single-pattern shapes)."),
    velocities: bool = typer.Option(False, help="lasa: add velocities vx, vy as joints."),
    overwrite: bool = typer.Option(False, help="Replace OUT if it exists."),
) -> None:
    """Import demonstrations (npz, CSV folder, LASA) into a MotionDataset file."""
    from primspace.data.importers import import_csv_folder, import_lasa, import_npz
    from primspace.files import check_output

    check_output(out, overwrite)
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
        _echo_json(summary)
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


# ====================================================================== clustering


# =================================================================== model, train


class LatentInit(str, Enum):
    zero = "zero"
    random = "random"
    projection = "projection"
    pca = "pca"


def _int_list(text: str, option: str) -> tuple[int, ...]:
    try:
        values = tuple(int(v) for v in text.replace(" ", "").split(",") if v)
    except ValueError:
        raise UserError(f"{option} must be comma-separated whole numbers, got '{text}'") from None
    if not values:
        raise UserError(f"{option} is empty")
    return values


def _float_list(text: str, option: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(",") if v)
    except ValueError:
        raise UserError(f"{option} must be comma-separated numbers, got '{text}'") from None
    if not values:
        raise UserError(f"{option} is empty")
    return values


def _run_summary(run) -> str:
    last = run.history[-1] if run.history else {}
    vision = last.get("vision")
    parts = [f"loss {last.get('loss', float('nan')):.5g}", f"motor {last.get('motor', float('nan')):.5g}"]
    if vision is not None:
        parts.append(f"vision {vision:.5g}")
    return (
        f"wrote {run.run_dir}: {run.kind}, {len(run.indices)} samples, init {run.init}, "
        f"q={run.model_config.latent_dim}, epoch {run.epoch}: " + ", ".join(parts)
    )


@app.command("train")
def train_command(
    file: Path = typer.Argument(..., help="A MotionDataset HDF5 file."),
    out: Path = typer.Option(..., "--out", "-o", help="The run directory to create."),
    init: LatentInit = typer.Option(LatentInit.projection, "--init", help="How the latent codes start."),
    latent_dim: int = typer.Option(20, "--latent-dim", "-q", help="q, the size of each latent code."),
    epochs: int = typer.Option(100, "--epochs", help="Total epochs (with --resume: train up to this many)."),
    no_images: bool = typer.Option(False, "--no-images", help="Motor only: no image head, images ignored."),
    indices: Optional[Path] = typer.Option(None, "--indices", help="Sample indices to train on (.npy or text)."),
    batch_size: int = typer.Option(32, "--batch-size"),
    lr: float = typer.Option(1e-3, "--lr", help="Learning rate of the weights."),
    latent_lr: float = typer.Option(1e-2, "--latent-lr", help="Learning rate of the latent codes."),
    motor_weight: float = typer.Option(1.0, "--motor-weight"),
    vision_weight: float = typer.Option(1.0, "--vision-weight"),
    layers: str = typer.Option("32,12", "--layers", help="Units per MTRNN layer, fastest first."),
    taus: str = typer.Option("2,8", "--taus", help="Time constant per layer, fastest first."),
    image_channels: str = typer.Option("64,32,16", "--image-channels", help="Channels of the deconvolution stack."),
    seed: int = typer.Option(0, "--seed"),
    device: str = typer.Option("auto", "--device", help="auto, cpu, cuda or cuda:N."),
    amp: bool = typer.Option(False, "--amp", help="bfloat16 mixed precision (CUDA only)."),
    threads: Optional[int] = typer.Option(None, "--threads", help="Torch CPU threads."),
    checkpoint_every: Optional[int] = typer.Option(None, "--checkpoint-every", help="Also checkpoint every N epochs."),
    checkpoint_seconds: float = typer.Option(60.0, "--checkpoint-seconds", help="Checkpoint at least this often."),
    weights_from: Optional[Path] = typer.Option(
        None, "--weights-from",
        help="Start from this run's weights, scaler and initialiser (its model config: model flags are ignored).",
    ),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in OUT from its checkpoint."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUT if it exists."),
) -> None:
    """Train the MTRNN decoder and one latent code per sample (theta and Z jointly)."""
    from primspace.data.dataset import MotionDataset
    from primspace.model import ModelConfig
    from primspace.train import TrainConfig, fit, read_indices

    mc = ModelConfig(
        latent_dim=latent_dim, layer_sizes=_int_list(layers, "--layers"), taus=_float_list(taus, "--taus"),
        image_channels=_int_list(image_channels, "--image-channels"),
    )
    tc = TrainConfig(
        epochs=epochs, batch_size=batch_size, lr=lr, latent_lr=latent_lr, motor_weight=motor_weight,
        vision_weight=vision_weight, seed=seed, device=device, amp=amp, threads=threads,
        checkpoint_every=checkpoint_every, checkpoint_seconds=checkpoint_seconds,
    )
    idx = read_indices(indices) if indices is not None else None
    ds = MotionDataset.load(file)
    run = fit(
        ds, out, model_config=None if weights_from is not None else mc, train_config=tc, init=init.value,
        indices=idx, resume=resume, overwrite=overwrite, weights_from=weights_from,
        images=False if no_images else None,
    )
    typer.echo(_run_summary(run))


@app.command("infer")
def infer_command(
    run: Path = typer.Argument(..., help="A trained run directory."),
    file: Path = typer.Argument(..., help="A MotionDataset HDF5 file with the new samples."),
    out: Path = typer.Option(..., "--out", "-o", help="The run directory to create for the new codes."),
    epochs: int = typer.Option(100, "--epochs", help="Total epochs of code optimisation."),
    init: Optional[LatentInit] = typer.Option(None, "--init", help="How the codes start (default: the run's)."),
    indices: Optional[Path] = typer.Option(None, "--indices", help="Sample indices to use (.npy or text)."),
    batch_size: Optional[int] = typer.Option(None, "--batch-size"),
    latent_lr: Optional[float] = typer.Option(None, "--latent-lr", help="Default: the run's."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Default: the run's."),
    device: str = typer.Option("auto", "--device"),
    amp: bool = typer.Option(False, "--amp"),
    threads: Optional[int] = typer.Option(None, "--threads"),
    resume: bool = typer.Option(False, "--resume"),
    overwrite: bool = typer.Option(False, "--overwrite"),
) -> None:
    """Find latent codes for new samples with the trained weights frozen."""
    from primspace.data.dataset import MotionDataset
    from primspace.train import infer, read_indices

    overrides = {"device": device, "amp": amp, "threads": threads}
    for name, value in (("batch_size", batch_size), ("latent_lr", latent_lr), ("seed", seed)):
        if value is not None:
            overrides[name] = value
    idx = read_indices(indices) if indices is not None else None
    ds = MotionDataset.load(file)
    result = infer(
        run, ds, out, epochs=epochs, init=None if init is None else init.value, indices=idx,
        resume=resume, overwrite=overwrite, **overrides,
    )
    typer.echo(_run_summary(result))


@app.command("reconstruct")
def reconstruct_command(
    run: Path = typer.Argument(..., help="A run directory (fit or infer)."),
    sample: int = typer.Option(..., "--sample", help="Sample index in the data file (one the run used)."),
    out: Path = typer.Option(..., "--out", "-o", help="The PNG to write."),
    data: Optional[Path] = typer.Option(None, "--data", help="The data file (default: the run's)."),
    frames: int = typer.Option(8, "--frames", help="Frames shown per strip."),
    overwrite: bool = typer.Option(False, "--overwrite"),
) -> None:
    """Draw generated against ground-truth joints (and frames) for one sample."""
    from primspace.data.dataset import MotionDataset
    from primspace.files import check_output
    from primspace.plots import plot_reconstruction, save_figure
    from primspace.train import load_run

    check_output(out, overwrite)
    trained = load_run(run)
    path = data if data is not None else trained.data_path
    if path is None:
        raise UserError(f"{run}: the run does not record its data file; pass --data FILE")
    ds = MotionDataset.load(path)
    fig = plot_reconstruction(trained, ds, sample, n_frames=frames)
    save_figure(fig, out)
    typer.echo(f"wrote {out}")



# ============================================================ experiments, report


@app.command("demo")
def demo_command() -> None:
    """Run the main demo (for now: import LASA and print its summary)."""
    from primspace.data.importers import import_lasa

    ds = import_lasa(length=100)
    typer.echo(_format_summary(ds.summary()))


# ============================================================================ main


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``primspace`` command (and ``python -m primspace``)."""
    try:
        app(args=argv, prog_name="primspace")
    except UserError as exc:
        typer.echo(f"primspace: error: {exc}", err=True)
        sys.exit(2)
