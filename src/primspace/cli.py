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

from primspace.errors import UserError, first_line

app = typer.Typer(
    name="primspace",
    help="Latent spaces of robot motion primitives (Nikulin & Tani): data, simulator, "
    "MTRNN decoder, subspace clustering, experiments.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        from primspace import __version__

        typer.echo(f"primspace {__version__}")
        raise typer.Exit()


@app.callback()
def _main_options(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit."),
) -> None:
    """Latent spaces of robot motion primitives (Nikulin & Tani): data, simulator, MTRNN
    decoder, subspace clustering, experiments."""


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
    _check_workers(workers)
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



# ====================================================================== clustering


class ClusterAffinity(str, Enum):
    squared = "squared"
    abs = "abs"


class ClusterSpectral(str, Enum):
    auto = "auto"
    dense = "dense"
    implicit = "implicit"


@app.command("cluster")
def cluster_command(
    src: Path = typer.Argument(
        ..., help="A MotionDataset .h5 (raw trajectories: joints scaled to [-1, 1], flattened) or an (N, q) .npy of latents."
    ),
    k: int = typer.Option(..., "--k", "-k", help="Number of clusters K."),
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (labels.csv, result.json, clustering.png)."),
    tau: Optional[float] = typer.Option(None, "--tau", help="The paper's tau, absolute (> 0)."),
    tau_relative: Optional[float] = typer.Option(
        None, "--tau-relative", help="Scale-free tau: tau = R / sigma_1^2 (keeps sigma_k / sigma_1 > 1/sqrt(R))."
    ),
    r2: Optional[float] = typer.Option(
        None, "--r2", help="Smallest tau whose R^2 of Z ~ Z Q* reaches this target in (0, 1) (default 0.99)."
    ),
    linear: bool = typer.Option(False, "--linear", help="Linear subspaces (no ones row) instead of affine."),
    affinity: ClusterAffinity = typer.Option(ClusterAffinity.squared, help="W = Q*^2 (scales) or |Q*| (dense only)."),
    ones_weight: float = typer.Option(1.0, help="Value of the appended ones row (affine)."),
    spectral: ClusterSpectral = typer.Option(ClusterSpectral.auto, help="Spectral step: dense n x n, implicit, or auto by n."),
    n_init: int = typer.Option(20, help="k-means restarts."),
    seed: int = typer.Option(0, help="Random seed (k-means; same seed, same labels)."),
    labels: Optional[Path] = typer.Option(None, "--labels", help="(N,) integer .npy of true labels (-1 = unknown) for scoring."),
    do_sweep: bool = typer.Option(False, "--sweep", help="Also print and save R^2, rank and scores over a tau grid."),
    sweep_taus: Optional[str] = typer.Option(
        None, "--sweep-taus", help="Comma-separated absolute taus for --sweep (default: R^2 targets 0.5 ... 0.9999)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the result JSON instead of text."),
    overwrite: bool = typer.Option(False, help="Replace a non-empty OUT directory."),
) -> None:
    """Affine low-rank subspace clustering (paper, Background): labels, scores, figure."""
    import time

    from primspace.cluster import LowRankSubspaceClustering, affinity_from_factor, clustering_scores, sweep
    from primspace.cluster.inputs import load_points
    from primspace.cluster.outputs import (
        atomic_directory,
        check_output_directory,
        figure_indices,
        to_jsonable,
        write_json,
        write_labels_csv,
        write_sweep_csv,
    )
    from primspace.errors import first_line
    from primspace.files import check_outside_inputs
    from primspace.plots import plot_clustering, plot_tau_sweep, save_figure

    check_outside_inputs(out, (src, labels))
    check_output_directory(out, overwrite)
    _check_cluster_options(k, tau, tau_relative, r2, ones_weight, n_init)
    grid = _parse_float_list(sweep_taus, "--sweep-taus") if sweep_taus else None
    points = load_points(src, labels)
    n, dim = points.X.shape
    if k > n:
        raise UserError(f"--k {k} exceeds the {n} samples in {src}")
    model = LowRankSubspaceClustering(
        k,
        affine=not linear,
        tau=tau,
        tau_relative=tau_relative,
        r2_target=r2,
        affinity=affinity.value,
        ones_weight=ones_weight,
        spectral=spectral.value,
        n_init=n_init,
        random_state=seed,
    )
    started = time.perf_counter()
    try:
        model.fit(points.X)
        seconds = time.perf_counter() - started
        rows = None
        if do_sweep or grid is not None:
            rows = sweep(
                points.X, k, taus=grid, labels_true=points.labels, affine=not linear, affinity=affinity.value,
                ones_weight=ones_weight, spectral=spectral.value, n_init=n_init, random_state=seed,
            )
    except ValueError as exc:  # parameter / data problems the estimator found
        raise UserError(f"{src}: {first_line(exc)}") from None
    scores = clustering_scores(points.labels, model.labels_) if points.labels is not None else None
    result = {
        "input": str(src),
        "points": points.description,
        "n_samples": n,
        "n_features": dim,
        "n_clusters": k,
        "affine": not linear,
        "affinity": affinity.value,
        "ones_weight": ones_weight,
        "tau_option": _tau_option_text(tau, tau_relative, r2),
        "tau": model.tau_,
        "tau_relative": model.tau_relative_,
        "r2": model.r2_,
        "rank": model.rank_,
        "spectral_method": model.spectral_method_,
        "eigenvalues": model.eigenvalues_,
        "singular_values": model.singular_values_[:100],
        "n_init": n_init,
        "seed": seed,
        "seconds": round(seconds, 3),
        "scores": scores,
        "sweep": None if rows is None else [{k2: v for k2, v in r.items() if k2 != "labels"} for r in rows],
    }
    idx = figure_indices(n)
    shown = "" if idx.size == n else f" ({idx.size} of {n} samples)"
    acc = "" if scores is None or scores["accuracy"] is None else f", accuracy {scores['accuracy']:.3f}"
    figure = plot_clustering(
        affinity_from_factor(model.representation_factor_, affinity.value, rows=idx),
        model.labels_[idx],
        None if points.labels is None else points.labels[idx],
        label_names=points.label_names,
        title=f"{src.name}: tau = {model.tau_:.3g}, R^2 = {model.r2_:.4f}, rank {model.rank_}{acc}{shown}",
    )
    with atomic_directory(out, overwrite) as tmp:
        write_labels_csv(tmp / "labels.csv", model.labels_, points.labels)
        write_json(tmp / "result.json", result)
        save_figure(figure, tmp / "clustering.png")
        if rows is not None:
            write_sweep_csv(tmp / "sweep.csv", rows)
            write_json(tmp / "sweep.json", result["sweep"])
            save_figure(plot_tau_sweep(rows, title=f"{src.name}: tau sweep"), tmp / "sweep.png")
    if as_json:
        _echo_json(to_jsonable(result))
        return
    if rows is not None:
        typer.echo(_format_sweep(rows))
    typer.echo(
        f"{n} samples x {dim} features -> {k} clusters: tau {model.tau_:.4g} (relative {model.tau_relative_:.4g}), "
        f"R^2 {model.r2_:.4f}, rank {model.rank_}, spectral {model.spectral_method_}, {seconds:.2f} s"
    )
    if scores is not None:
        if scores["accuracy"] is None:
            typer.echo("no sample has a known true label: nothing scored")
        else:
            typer.echo(
                f"accuracy {scores['accuracy']:.4f}  NMI {scores['nmi']:.4f}  ARI {scores['ari']:.4f}  "
                f"({scores['n_scored']} scored, {scores['n_ignored']} with unknown label)"
            )
    typer.echo(f"wrote {out}/: labels.csv, result.json, clustering.png" + (", sweep.csv, sweep.json, sweep.png" if rows else ""))


def _check_cluster_options(k, tau, tau_relative, r2, ones_weight, n_init) -> None:
    if k < 1:
        raise UserError(f"--k must be at least 1, got {k}")
    given = [name for name, v in (("--tau", tau), ("--tau-relative", tau_relative), ("--r2", r2)) if v is not None]
    if len(given) > 1:
        raise UserError(f"give at most one of --tau, --tau-relative, --r2; got {' and '.join(given)}")
    for name, value in (("--tau", tau), ("--tau-relative", tau_relative), ("--ones-weight", ones_weight)):
        if value is not None and not (value > 0 and value != float("inf")):
            raise UserError(f"{name} must be a positive number, got {value}")
    if r2 is not None and not 0 < r2 < 1:
        raise UserError(f"--r2 must lie in (0, 1), got {r2}")
    if n_init < 1:
        raise UserError(f"--n-init must be at least 1, got {n_init}")


def _parse_float_list(text: str, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UserError(f"{option} must be comma-separated numbers, got {text!r}") from None
    if not values or any(not (v > 0 and v != float("inf")) for v in values):
        raise UserError(f"{option} must list positive numbers, got {text!r}")
    return values


def _tau_option_text(tau, tau_relative, r2) -> dict:
    from primspace.cluster import DEFAULT_R2_TARGET

    if tau is not None:
        return {"tau": tau}
    if tau_relative is not None:
        return {"tau_relative": tau_relative}
    return {"r2_target": DEFAULT_R2_TARGET if r2 is None else r2}


def _format_sweep(rows: list[dict]) -> str:
    def f(v, spec):
        width = int(spec.split(".")[0].rstrip("df"))
        return "-".rjust(width) if v is None else format(v, spec)

    grid = rows[0]["grid"] if rows else "tau"
    head = f"  {grid:>12} {'tau':>10} {'tau_rel':>10} {'R^2':>8} {'rank':>5} {'accuracy':>9} {'NMI':>7} {'ARI':>7}"
    lines = ["tau sweep (one SVD):", head]
    for r in rows:
        lines.append(
            f"  {r['value']:>12.6g} {f(r.get('tau'), '10.4g')} {f(r.get('tau_relative'), '10.4g')} "
            f"{f(r.get('r2'), '8.4f')} {f(r.get('rank'), '5d')} {f(r.get('accuracy'), '9.4f')} "
            f"{f(r.get('nmi'), '7.4f')} {f(r.get('ari'), '7.4f')}"
        )
    return "\n".join(lines)


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


def _name_list(text: str, option: str) -> tuple[str, ...]:
    values = tuple(v.strip() for v in text.split(",") if v.strip())
    if not values:
        raise UserError(f"{option} is empty")
    return values


def _check_workers(workers: Optional[int]) -> None:
    """The same rule for every command's --workers: absent means every core, else >= 1."""
    if workers is not None and workers < 1:
        raise UserError(f"--workers {workers}: must be at least 1")


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
    final_lr_fraction: float = typer.Option(
        1.0, "--final-lr-fraction", help="Cosine decay of both learning rates to this fraction by the last epoch (1: constant)."
    ),
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
        epochs=epochs, batch_size=batch_size, lr=lr, latent_lr=latent_lr, final_lr_fraction=final_lr_fraction,
        motor_weight=motor_weight,
        vision_weight=vision_weight, seed=seed, device=device, amp=amp, threads=threads,
        checkpoint_every=checkpoint_every, checkpoint_seconds=checkpoint_seconds,
    )
    from primspace.files import check_outside_inputs

    check_outside_inputs(out, (file, indices, weights_from))
    ds = MotionDataset.load(file)
    idx = read_indices(indices, ds) if indices is not None else None
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
    from primspace.files import check_outside_inputs

    check_outside_inputs(out, (run, file, indices))
    ds = MotionDataset.load(file)
    idx = read_indices(indices, ds) if indices is not None else None
    result = infer(
        run, ds, out, epochs=epochs, init=None if init is None else init.value, indices=idx,
        resume=resume, overwrite=overwrite, **overrides,
    )
    typer.echo(_run_summary(result))


@app.command("reconstruct")
def reconstruct_command(
    run: Path = typer.Argument(..., help="A run directory (fit or infer)."),
    sample: int = typer.Option(..., "--sample", help="Sample index in the data file (one the run used)."),
    out: str = typer.Option(..., "--out", "-o", help="The PNG to write."),
    data: Optional[Path] = typer.Option(None, "--data", help="The data file (default: the run's)."),
    frames: int = typer.Option(8, "--frames", help="Frames shown per strip."),
    overwrite: bool = typer.Option(False, "--overwrite"),
) -> None:
    """Draw generated against ground-truth joints (and frames) for one sample."""
    from primspace.data.dataset import MotionDataset
    from primspace.files import output_file
    from primspace.plots import plot_reconstruction, save_figure
    from primspace.train import check_run_data, load_run

    out = output_file(out, inputs=(run, data), overwrite=overwrite)
    if frames < 1:
        raise UserError(f"--frames {frames}: must be at least 1")
    trained = load_run(run)
    path = data if data is not None else trained.data_path
    if path is None:
        raise UserError(f"{run}: the run does not record its data file; pass --data FILE")
    ds = MotionDataset.load(path)
    check_run_data(trained, ds)
    fig = plot_reconstruction(trained, ds, sample, n_frames=frames)
    save_figure(fig, out)
    typer.echo(f"wrote {out}")



# ============================================================ experiments, report

experiment_app = typer.Typer(
    help="The paper's experiments (Experimental Results). Re-running with the same --out skips "
    "finished runs and resumes interrupted ones.",
    no_args_is_help=True,
)
app.add_typer(experiment_app, name="experiment")


class Backend(str, Enum):
    local = "local"
    ray = "ray"


def _experiment(preset: str, data, out, backend, address, workers, seed, overrides: dict):
    from primspace.experiments.presets import resolve_preset
    from primspace.experiments.workspace import ExperimentDir
    from primspace.parallel import default_workers

    _check_workers(workers)
    return ExperimentDir(
        out, resolve_preset(preset).with_overrides(**overrides), data=data, backend=backend.value,
        address=address, workers=workers or default_workers(), seed=seed,
    )


def _finish(exp, report: bool) -> None:
    failures = exp.meta.get("failures", {})
    if report:
        from primspace.report import build_report

        typer.echo(f"report: {build_report(exp.path)}")
    if failures:
        key, error = next(iter(failures.items()))
        more = f" and {len(failures) - 1} more" if len(failures) > 1 else ""
        raise UserError(
            f"{len(failures)} run(s) failed, the others finished: {key} ({error}){more}; "
            f"tracebacks in {exp.path}/runs/<run>/error.txt; re-run the same command to retry them"
        )


def _experiment_command(name: str, doc: str, steps: tuple[str, ...], table: str | None) -> None:
    """Register ``primspace experiment NAME``: run ``steps`` (``module:function``), print ``table``."""

    def command(
        preset: str = typer.Option("demo", "--preset", help="Experiment preset: demo (CPU, minutes) or paper (GPU recommended)."),
        data: Optional[Path] = typer.Option(None, "--data", help="A data set file; default: generate the preset's simulated data into OUT."),
        out: Path = typer.Option(..., "--out", "-o", help="The experiment directory."),
        backend: Backend = typer.Option(Backend.local, "--backend", help="local (process pool) or ray."),
        address: Optional[str] = typer.Option(None, "--address", help="Ray cluster address (default: start a local Ray instance)."),
        workers: Optional[int] = typer.Option(None, "--workers", "-j", help="Parallel runs (default: all cores)."),
        seed: int = typer.Option(0, "--seed", help="Seed of the generated data."),
        latent_dims: Optional[str] = typer.Option(None, "--latent-dims", help="Override the preset's latent sizes, e.g. 10,20,40."),
        inits: Optional[str] = typer.Option(None, "--inits", help="Override the initialisations, e.g. zero,projection."),
        seeds: Optional[str] = typer.Option(None, "--seeds", help="Override the run seeds, e.g. 0,1,2."),
        epochs: Optional[str] = typer.Option(None, "--epochs", help="Override the fit and infer epochs, e.g. 800,600."),
        images: Optional[bool] = typer.Option(None, "--images/--no-images", help="Override whether the vision loss is trained."),
        report: bool = typer.Option(True, "--report/--no-report", help="Write OUT/report.html at the end."),
    ) -> None:
        import importlib

        overrides = {
            "latent_dims": _int_list(latent_dims, "--latent-dims") if latent_dims is not None else None,
            "inits": _name_list(inits, "--inits") if inits is not None else None,
            "seeds": _int_list(seeds, "--seeds") if seeds is not None else None,
            "images": images,
        }
        if epochs is not None:
            fit_epochs, infer_epochs = (_int_list(epochs, "--epochs") + (None,))[:2]
            overrides |= {"fit_epochs": fit_epochs, "infer_epochs": infer_epochs or fit_epochs}
        exp = _experiment(preset, data, out, backend, address, workers, seed, overrides)
        if "success:run_success" in steps and data is not None:
            from primspace.sim.success import check_judgeable

            check_judgeable(exp.dataset())  # up front: before hours of training, not after
        result = None
        for step in steps:
            module, function = step.split(":")
            result = getattr(importlib.import_module(f"primspace.experiments.{module}"), function)(exp)
        if table is not None:
            module, function = table.split(":")
            _echo_table(*getattr(importlib.import_module(f"primspace.experiments.{module}"), function)(result))
        _finish(exp, report or name == "all")

    command.__doc__ = doc
    experiment_app.command(name)(command)


_experiment_command(
    "intra", "Intra-primitive generalisation: fit on 20%, infer codes for 80%, per init and latent size.",
    ("intra:run_intra",), "intra:final_loss_table",
)
_experiment_command(
    "clustering", "Subspace clustering of learned codes (runs intra if needed) and of raw trajectories (data, LASA).",
    ("clustering:run_clustering",), "clustering:latent_table",
)
_experiment_command(
    "success", "Success rates of generated eval motions, judged by the simulator (runs intra if needed).",
    ("success:run_success",), "success:success_table",
)
_experiment_command(
    "inter", "Inter-primitive generalisation: leave one primitive out, then learn it with 10% replay.",
    ("inter:run_inter",), "inter:inter_table",
)
_experiment_command(
    "all", "Every experiment in turn (intra, clustering, success, inter), then the report.",
    ("intra:run_intra", "clustering:run_clustering", "success:run_success", "inter:run_inter"), None,
)


@app.command("report")
def report_command(directory: Path = typer.Argument(..., help="An experiment directory.")) -> None:
    """Write DIR/report.html from the results the directory holds."""
    from primspace.report import build_report

    typer.echo(f"report: {build_report(directory)}")


@app.command("demo")
def demo_command(
    out: Path = typer.Option(Path("demo-out"), "--out", "-o", help="Where the demo writes its data, runs and report."),
    workers: Optional[int] = typer.Option(None, "--workers", "-j", help="Parallel runs (default: all cores)."),
) -> None:
    """The main demo: simulate data, run intra + clustering + success at demo scale, write the report."""
    from primspace.experiments.demo import run_demo
    from primspace.parallel import default_workers

    _check_workers(workers)
    summary = run_demo(out, workers=workers or default_workers())
    typer.echo(summary)


def _echo_table(columns, rows) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(*[str(c) for c in columns])
    for row in rows:
        table.add_row(*[f"{v:.4g}" if isinstance(v, float) else str(v) for v in row])
    Console().print(table)


# ============================================================================ main


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``primspace`` command (and ``python -m primspace``)."""
    try:
        app(args=argv, prog_name="primspace")
    except UserError as exc:
        typer.echo(f"primspace: error: {exc}", err=True)
        sys.exit(2)
    except OSError as exc:  # the file system said no (permissions, disk full, read-only): one line
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        typer.echo(f"primspace: error: {where}{exc.strerror or first_line(exc)}", err=True)
        sys.exit(2)
