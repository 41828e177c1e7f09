"""Model commands: train, infer, reconstruct."""

from __future__ import annotations

from dataclasses import replace
from enum import Enum
from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.options import (
    SCALE_OVER_FILE_HELP,
    allow_unfinished_option,
    check_finished,
    configure_threads,
    device_option,
    file_scaler,
    float_list,
    int_list,
    threads_option,
)
from primspace.model.config import ModelConfig
from primspace.train.config import TrainConfig
from primspace.utils.errors import UserError

# =================================================================== model, train


class LatentInit(str, Enum):
    zero = "zero"
    random = "random"
    projection = "projection"
    pca = "pca"
    calibrated = "calibrated"
    projection_vision = "projection-vision"


class LossReduction(str, Enum):
    """``TrainConfig.loss_reduction``: per-element means (primspace), the paper's sums, or the means
    weighed by learned precisions."""

    mean = "mean"
    sum = "sum"
    precision = "precision"


class Optimizer(str, Enum):
    """``TrainConfig.optimizer``: Adam (primspace) or the paper's plain gradient descent."""

    adam = "adam"
    sgd = "sgd"


OPTIMIZER_HELP = (
    "adam: Adam for the weights, a row-wise Adam for the codes; sgd: plain gradient descent of both, the "
    "paper's (its rates are not Adam's: choose --lr and --latent-lr on a validation split)."
)


class LogTarget(str, Enum):
    """What ``--log-to`` writes to (:mod:`primspace.train.logger`)."""

    tensorboard = "tensorboard"


_LOG_TO_HELP = (
    "Also write each epoch's metrics (those of metrics.jsonl) as TensorBoard event files into the "
    "folder DIR (new files only: an existing folder is fine; give each run its own). Needs "
    "pip install 'primspace\\[tensorboard]'."
)


def _log_to(value, inputs: tuple) -> tuple | None:
    """``--log-to tensorboard DIR`` as the library's ``log_to`` pair, checked before any data is read."""
    if value is None:
        return None
    from primspace.train.logger import check_log_to

    log_to = (value[0].value, value[1])
    check_log_to(log_to, inputs, option="--log-to")
    return log_to


def _log_to_option():
    return typer.Option(None, "--log-to", metavar="tensorboard DIR", help=_LOG_TO_HELP)


#: The mark ``reconstruct`` writes into its PNG (primspace.utils.outputs).
_RECONSTRUCT_MARK = "primspace reconstruct"

_LOSS_REDUCTION_HELP = (
    "mean: per-element mean squared errors (motor and vision weigh alike); sum: the paper's "
    "summed squared errors per sample; precision: each modality's mean weighed by its learned "
    "precision, one log-variance per modality trained with the weights (docs/model.md). "
    "Learning rates are not rescaled."
)


def _run_summary(run) -> str:
    last = run.history[-1] if run.history else {}
    vision = last.get("vision")
    parts = [f"loss {last.get('loss', float('nan')):.5g}", f"motor {last.get('motor', float('nan')):.5g}"]
    if vision is not None:
        parts.append(f"vision {vision:.5g}")
    line = (
        f"wrote {run.run_dir}: {run.kind}, {len(run.indices)} samples, init {run.init}, "
        f"q={run.model_config.latent_dim}, epoch {run.epoch}: " + ", ".join(parts)
    )
    if run.kind == "fit" and run.calibration is not None:
        d = run.calibration.diagnostics()
        heldout = "n/a (under 3 samples)" if d["heldout_r2"] is None else f"{d['heldout_r2']:.3f}"
        line += (
            f"\ncalibration (for --init calibrated): the fitted codes moved {100 * d['movement']:.1f}% from their "
            f"initial codes; R^2 of the initial codes {d['identity_r2']:.3f}, of the map (held out) {heldout}"
        )
    return line


# Defaults come from the configuration classes (written once there); these two imports
# do not load torch.
_MC, _TC = ModelConfig(), TrainConfig()


def _csv(values) -> str:
    return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in values)


def _inputs(out: Path, file: Path, indices: Path | None, other: Path | None):
    """The data set and its --indices selection, once --out is known to lie outside every input."""
    from primspace.data.dataset import MotionDataset
    from primspace.data.indices import read_indices
    from primspace.utils.files import check_outside_inputs

    check_outside_inputs(out, (file, indices, other))
    ds = MotionDataset.load(file)
    return ds, (read_indices(indices, ds) if indices is not None else None)


def _train_inputs(out: Path, file: Path, indices: Path | None, other: Path | None, tc: TrainConfig, no_images: bool):
    """:func:`_inputs`, refusing a run with no loss left: ``--motor-weight 0`` without the
    vision loss (``--no-images``, or data without images) trains on a loss that is 0."""
    ds, idx = _inputs(out, file, indices, other)
    if tc.motor_weight == 0 and (no_images or not ds.has_images):
        why = "with --no-images" if no_images else f"and {file} has no images"
        raise UserError(f"--motor-weight 0 {why}: no loss is left to train (the loss is 0 at every epoch)")
    return ds, idx


#: The train command's arguments that are TrainConfig fields of the same name.
_TRAIN_FLAGS = (
    "epochs",
    "batch_size",
    "lr",
    "latent_lr",
    "optimizer",
    "final_lr_fraction",
    "motor_weight",
    "vision_weight",
    "vision_frames",
    "loss_reduction",
    "code_smoothness",
    "seed",
    "device",
    "amp",
    "threads",
    "checkpoint_every",
    "checkpoint_seconds",
) + ("stream_frames", "frames_memory_gb", "loader_workers", "micro_batches", "step")

#: The options of streaming and data-parallel training, shared by train and infer (docs/scale.md).
_SCALE_HELP = {
    "stream_frames": "Read each batch's frames from the data file while training instead of loading them all "
    "first (the same numbers). Default: stream when they would not fit --frames-memory-gb.",
    "frames_memory_gb": "Memory the loaded frames may take, all processes of a machine together (default: half "
    "of the device's memory).",
    "loader_workers": "Processes that read and decode streamed frames (0: the training process).",
    "micro_batches": "Split each batch into this many parts computed one after another (less memory; the numbers "
    "of as many torchrun processes).",
    "step": "How each batch steps: eager (op by op, the default), compiled (torch.compile of the recurrent loop) or "
    "captured (padded batches; on CUDA the whole step as one CUDA graph). docs/performance.md.",
}


def _scale_options(defaults: TrainConfig | None):
    """The typer options of :data:`_SCALE_HELP` (``defaults`` None: each defaults to the run's, for infer)."""
    d = defaults
    return {
        "stream_frames": typer.Option(None, "--stream-frames/--load-frames", help=_SCALE_HELP["stream_frames"]),
        "frames_memory_gb": typer.Option(None, "--frames-memory-gb", help=_SCALE_HELP["frames_memory_gb"]),
        "loader_workers": typer.Option(
            None if d is None else d.loader_workers, "--loader-workers", help=_SCALE_HELP["loader_workers"]
        ),
        "micro_batches": typer.Option(
            None if d is None else d.micro_batches, "--micro-batches", help=_SCALE_HELP["micro_batches"]
        ),
        "step": typer.Option(None if d is None else d.step, "--step", help=_SCALE_HELP["step"]),
    }


_TRAIN_SCALE, _INFER_SCALE = _scale_options(_TC), _scale_options(None)


def _launch(tc: TrainConfig, call) -> None:
    """Apply ``tc``'s process-wide settings, run ``call()`` (fit or infer) in the process
    group a launcher asked for (torchrun: docs/scale.md) and print the run's summary once
    (every process of a torchrun launch runs the command)."""
    from primspace.train import configure_process
    from primspace.train.distributed import launched

    configure_process(tc)
    with launched(tc.device) as rank:
        run = call()
    if rank == 0:
        typer.echo(_run_summary(run))


_TRAIN_INIT_HELP = (
    "How the latent codes start (calibrated: only with --weights-from a projection or pca run; "
    "projection-vision: the motor and the keypoints of the frames, data with frames)."
)
#: The help of train's options that are plain TrainConfig fields.
_HELP = {
    "seed": "Seeds the weights, the projection P, random codes and the batch order (same seed, same machine: same "
    "numbers).",
    "batch_size": "Samples per mini-batch (every code is updated once per epoch, the weights once per batch).",
    "motor_weight": "Weight of the joints' loss.",
    "vision_weight": "Weight of the frames' loss (0: no image head is trained).",
}


@app.command("train")
def train_command(
    file: Path = typer.Argument(..., metavar="DATA", help="A MotionDataset HDF5 file."),
    out: Path = typer.Option(..., "--out", "-o", help="The run directory to create."),
    init: LatentInit = typer.Option(LatentInit.projection, "--init", help=_TRAIN_INIT_HELP),
    latent_dim: int = typer.Option(_MC.latent_dim, "--latent-dim", "-q", help="q, the size of each latent code."),
    epochs: int = typer.Option(_TC.epochs, "--epochs", help="Total epochs (with --resume: train up to this many)."),
    no_images: bool = typer.Option(False, "--no-images", help="Motor only: no image head, images ignored."),
    indices: Path | None = typer.Option(None, "--indices", help="Sample indices to train on (.npy or text)."),
    batch_size: int = typer.Option(_TC.batch_size, "--batch-size", help=_HELP["batch_size"]),
    lr: float = typer.Option(_TC.lr, "--lr", help="Learning rate of the weights."),
    latent_lr: float = typer.Option(_TC.latent_lr, "--latent-lr", help="Learning rate of the latent codes."),
    final_lr_fraction: float = typer.Option(
        _TC.final_lr_fraction,
        "--final-lr-fraction",
        help="Cosine decay of both learning rates to this fraction by the last epoch (1: constant).",
    ),
    motor_weight: float = typer.Option(_TC.motor_weight, "--motor-weight", help=_HELP["motor_weight"]),
    vision_weight: float = typer.Option(_TC.vision_weight, "--vision-weight", help=_HELP["vision_weight"]),
    vision_frames: int | None = typer.Option(
        _TC.vision_frames,
        "--vision-frames",
        help="Vision loss on K randomly drawn frames per sequence and step (unbiased; default: every frame).",
    ),
    loss_reduction: LossReduction = typer.Option(_TC.loss_reduction, "--loss-reduction", help=_LOSS_REDUCTION_HELP),
    optimizer: Optimizer = typer.Option(_TC.optimizer, "--optimizer", help=OPTIMIZER_HELP),
    code_window: int | None = typer.Option(
        None,
        "--code-window",
        help="One code per window of W steps (a sequence of codes, for long demonstrations of several primitives).",
    ),
    code_smoothness: float = typer.Option(
        _TC.code_smoothness,
        "--code-smoothness",
        help="With --code-window: weight of the total variation of consecutive codes (piecewise-constant codes).",
    ),
    keypoints: int = typer.Option(0, "--keypoints", help="K > 0: draw frames through K keypoints (docs/model.md)."),
    layers: str = typer.Option(_csv(_MC.layer_sizes), "--layers", help="Units per MTRNN layer, fastest first."),
    taus: str = typer.Option(_csv(_MC.taus), "--taus", help="Time constant per layer, fastest first."),
    image_channels: str = typer.Option(
        _csv(_MC.image_channels), "--image-channels", help="Channels of the deconvolution stack."
    ),
    seed: int = typer.Option(_TC.seed, "--seed", help=_HELP["seed"]),
    device: str = device_option(),
    amp: bool = typer.Option(_TC.amp, "--amp", help="bfloat16 mixed precision (CUDA only)."),
    threads: int | None = threads_option(),
    checkpoint_every: int | None = typer.Option(
        _TC.checkpoint_every, "--checkpoint-every", help="Also checkpoint every N epochs."
    ),
    checkpoint_seconds: float = typer.Option(
        _TC.checkpoint_seconds, "--checkpoint-seconds", help="Checkpoint at least this often."
    ),
    weights_from: Path | None = typer.Option(
        None,
        "--weights-from",
        help="Start from this run's weights, scaler and initialiser (its model config: model flags are ignored).",
    ),
    resume: bool = typer.Option(False, "--resume", help="Continue the run in OUT from its checkpoint."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUT if it exists."),
    scale_over_file: bool = typer.Option(False, "--scale-over-file", help=SCALE_OVER_FILE_HELP),
    log_to: tuple[LogTarget, Path] | None = _log_to_option(),
    stream_frames: bool | None = _TRAIN_SCALE["stream_frames"],
    loader_workers: int = _TRAIN_SCALE["loader_workers"],
    frames_memory_gb: float | None = _TRAIN_SCALE["frames_memory_gb"],
    micro_batches: int = _TRAIN_SCALE["micro_batches"],
    step: str = _TRAIN_SCALE["step"],
) -> None:
    """Train the MTRNN decoder and one latent code per sample (theta and Z jointly).

    Under torchrun (torchrun --nproc-per-node G -m primspace train ...) the processes
    train one model together (docs/scale.md).
    """
    from primspace.train import fit

    given = dict(locals()) | {"loss_reduction": loss_reduction.value, "optimizer": optimizer.value}
    log_to = _log_to(log_to, (file, indices, weights_from))
    mc = replace(
        _MC,
        **{k: given[k] for k in ("latent_dim", "code_window", "keypoints")},
        layer_sizes=int_list(layers, "--layers"),
        taus=float_list(taus, "--taus"),
        image_channels=int_list(image_channels, "--image-channels"),
    )
    tc = replace(_TC, **{k: given[k] for k in _TRAIN_FLAGS}).validate()
    ds, idx = _train_inputs(out, file, indices, weights_from, tc, no_images)
    scaler = file_scaler(ds, weights_from) if scale_over_file else None
    _launch(
        tc,
        lambda: fit(
            ds,
            out,
            model_config=None if weights_from is not None else mc,
            train_config=tc,
            init=init.value,
            indices=idx,
            resume=resume,
            overwrite=overwrite,
            weights_from=weights_from,
            images=False if no_images else None,
            log_to=log_to,
            scaler=scaler,
        ),
    )


@app.command("infer")
def infer_command(
    run: Path = typer.Argument(..., help="A trained run directory."),
    file: Path = typer.Argument(..., metavar="DATA", help="A MotionDataset HDF5 file with the new samples."),
    out: Path = typer.Option(..., "--out", "-o", help="The run directory to create for the new codes."),
    epochs: int = typer.Option(_TC.epochs, "--epochs", help="Total epochs of code optimisation."),
    init: LatentInit | None = typer.Option(
        None,
        "--init",
        help="How the codes start (default: the run's). calibrated: the run's projection mapped by its ridge "
        "calibration onto where its fitted codes ended (runs fitted with projection or pca init).",
    ),
    indices: Path | None = typer.Option(None, "--indices", help="Sample indices to use (.npy or text)."),
    batch_size: int | None = typer.Option(None, "--batch-size", help="Default: the run's."),
    latent_lr: float | None = typer.Option(None, "--latent-lr", help="Default: the run's."),
    seed: int | None = typer.Option(None, "--seed", help="Default: the run's."),
    loss_reduction: LossReduction | None = typer.Option(
        None, "--loss-reduction", help="Default: the run's. " + _LOSS_REDUCTION_HELP
    ),
    device: str = device_option(),
    amp: bool = typer.Option(_TC.amp, "--amp", help="bfloat16 mixed precision (CUDA only)."),
    threads: int | None = threads_option(),
    resume: bool = typer.Option(False, "--resume", help="Continue the inference in OUT from its checkpoint."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUT if it is an earlier infer run."),
    allow_unfinished: bool = allow_unfinished_option(),
    log_to: tuple[LogTarget, Path] | None = _log_to_option(),
    stream_frames: bool | None = _INFER_SCALE["stream_frames"],
    frames_memory_gb: float | None = _INFER_SCALE["frames_memory_gb"],
    loader_workers: int | None = _INFER_SCALE["loader_workers"],
    micro_batches: int | None = _INFER_SCALE["micro_batches"],
    step: str | None = _INFER_SCALE["step"],
) -> None:
    """Find latent codes for new samples with the trained weights frozen (under torchrun:
    each batch's samples split across the processes)."""
    from primspace.train import infer, load_run

    log_to = _log_to(log_to, (file, indices, run))
    overrides = {"device": device, "amp": amp, "threads": threads}
    reduction = None if loss_reduction is None else loss_reduction.value
    for name, value in (
        ("batch_size", batch_size),
        ("latent_lr", latent_lr),
        ("seed", seed),
        ("loss_reduction", reduction),
        ("stream_frames", stream_frames),
        ("frames_memory_gb", frames_memory_gb),
        ("loader_workers", loader_workers),
        ("micro_batches", micro_batches),
        ("step", step),
    ):
        if value is not None:
            overrides[name] = value
    ds, idx = _inputs(out, file, indices, run)
    trained = load_run(run)
    check_finished(trained, allow_unfinished)
    _launch(
        replace(_TC, device=device, amp=amp, threads=threads).validate(),
        lambda: infer(
            trained,
            ds,
            out,
            epochs=epochs,
            init=None if init is None else init.value,
            indices=idx,
            resume=resume,
            overwrite=overwrite,
            log_to=log_to,
            **overrides,
        ),
    )


@app.command("reconstruct")
def reconstruct_command(
    run: Path = typer.Argument(..., help="A run directory (fit or infer)."),
    sample: int = typer.Option(..., "--sample", help="Sample index in the data file (one the run used)."),
    out: str = typer.Option(..., "--out", "-o", help="The PNG to write."),
    data: Path | None = typer.Option(None, "--data", help="The data file (default: the run's)."),
    frames: int = typer.Option(8, "--frames", help="Camera frames shown in the strip (data with images)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUT if it is an earlier reconstruct output."),
    device: str = device_option("cpu"),
    threads: int | None = threads_option(),
    allow_unfinished: bool = allow_unfinished_option(),
) -> None:
    """Draw generated against ground-truth joints (and frames) for one sample."""
    import numpy as np

    from primspace.plots import plot_reconstruction, reconstruction_title, save_figure
    from primspace.train import decode_keypoints, reconstruct

    configure_threads(threads, device)
    out, trained, ds, row = run_sample(run, sample, out, data, frames, overwrite, writer=_RECONSTRUCT_MARK)
    check_finished(trained, allow_unfinished)
    motor, generated = reconstruct(trained, trained.latents[row : row + 1], device=device)  # here, not in plots
    points = decode_keypoints(trained, trained.latents[row : row + 1], device=device)  # None: no keypoints
    truth = ds.subset([int(sample)])
    images = None if truth.images is None else np.asarray(truth.images)[0]
    primitive = None if truth.labels is None or truth.labels[0] < 0 else truth.label_names[truth.labels[0]]
    fig = plot_reconstruction(
        truth.motor[0],
        motor[0],
        images=images,
        generated_images=None if generated is None else generated[0],
        generated_keypoints=None if points is None else points[0],
        joint_names=truth.joint_names,
        dt=truth.dt,
        n_frames=frames,
        title=reconstruction_title(sample, primitive, trained.kind, trained.init, trained.model_config.latent_dim),
    )
    save_figure(fig, out, writer=_RECONSTRUCT_MARK, overwrite=overwrite)
    typer.echo(f"wrote {out}")


def run_sample(
    run: Path,
    sample: int,
    out: str,
    data: Path | None,
    frames: int,
    overwrite: bool,
    min_frames: int = 1,
    *,
    writer: str,
):
    """What ``reconstruct`` and ``animate`` check and load: the output (``--overwrite``
    replaces only an earlier output marked by ``writer``), ``--frames``, the run, its data
    file (``--data`` or the run's) and that ``sample`` is one the run used.

    Returns
    -------
    (Path, TrainedRun, MotionDataset, int)
        The checked output, the run, its data set and the sample's row in the run's codes.
    """
    import numpy as np

    from primspace.data.dataset import MotionDataset
    from primspace.train import check_run_data, load_run
    from primspace.utils.outputs import output_file

    if frames < min_frames:
        raise UserError(f"--frames {frames}: must be at least {min_frames}")
    trained = load_run(run)
    path = data if data is not None else trained.data_path
    if path is None:
        raise UserError(f"{run}: the run does not record its data file; pass --data FILE")
    if data is None and not Path(path).is_file():
        raise UserError(
            f"{path}: no such file: it is the data file run {run} was fitted on (recorded in its "
            "config.json); if it moved, pass --data NEW_PATH"
        )
    # the data file is an input even when it is the run's (not given as --data): never written over
    out = output_file(out, inputs=(run, path), overwrite=overwrite, writer=writer)
    ds = MotionDataset.load(path)
    check_run_data(trained, ds)
    rows = np.flatnonzero(trained.indices == int(sample))
    if rows.size == 0:
        shown = ", ".join(map(str, trained.indices[:5])) + (" ..." if len(trained.indices) > 5 else "")
        raise UserError(
            f"sample {sample} is not one of the run's {len(trained.indices)} samples ({shown}; a sample "
            f"is numbered by its index in the data file, {path})"
        )
    if not 0 <= int(sample) < len(ds):
        raise UserError(f"sample {sample} out of range for {len(ds)} samples")
    return out, trained, ds, int(rows[0])
