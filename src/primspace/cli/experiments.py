"""The paper's experiments, the report and the demo."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.options import check_workers, device_option, echo_table, int_list, name_list, threads_option
from primspace.cli.train import OPTIMIZER_HELP, LossReduction, Optimizer
from primspace.utils.errors import UserError
from primspace.utils.seeds import check_seed

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


def _experiment(preset: str | None, data, out, backend, address, workers, seed, overrides: dict, pack: int = 1):
    from primspace.cli.app import invocation
    from primspace.experiments.presets import DEFAULT_PRESET, resolve_preset
    from primspace.experiments.workspace import ExperimentDir
    from primspace.utils.parallel import default_workers

    check_workers(workers)
    if pack < 1:
        raise UserError(f"--pack {pack}: must be at least 1")
    chosen = resolve_preset(preset or DEFAULT_PRESET).with_overrides(**overrides)
    exp = ExperimentDir(
        out,
        chosen,
        data=data,
        backend=backend.value,
        address=address,
        workers=workers or default_workers(),
        pack=pack,
        **({} if seed is None else {"seed": seed}),  # else ExperimentDir's default
    )
    if invocation() is not None:
        exp.record_invocation(invocation())
    return exp


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


def _judgeable_steps(exp, name: str, steps: tuple[str, ...]) -> tuple[str, ...]:
    """``steps``, checked up front (before hours of training) that the simulator can judge
    the data when success is one of them. ``experiment all`` on data it cannot judge (LASA,
    imported demonstrations) leaves the success step out, with a note, instead of failing."""
    if "success:run_success" not in steps:
        return steps
    from primspace.sim.success import check_judgeable
    from primspace.utils.errors import DataError

    try:
        check_judgeable(exp.dataset())
    except DataError as exc:
        if name != "all":
            raise
        typer.echo(f"success: skipped, the simulator cannot judge these data ({exc})")
        return tuple(s for s in steps if s != "success:run_success")
    return steps


def _fit_infer_epochs(text: str) -> tuple[int, int | None]:
    """``--epochs FIT[,INFER]``: one or two whole numbers (infer None: as fit)."""
    values = int_list(text, "--epochs")
    if len(values) > 2:
        raise UserError(f"--epochs takes at most two values (fit, infer), got {len(values)}: '{text}'")
    return (values + (None,))[:2]


def _overrides(
    name: str, latent_dims, inits, seeds, epochs, images, vision_frames, loss_reduction, device, threads, optimizer=None
) -> dict:
    """The preset's fields that the options of ``primspace experiment NAME`` override (None: kept)."""
    overrides = {
        "latent_dims": int_list(latent_dims, "--latent-dims") if latent_dims is not None else None,
        "inits": name_list(inits, "--inits") if inits is not None else None,
        # the inter-primitive experiment compares its own inits (the paper: zero and projection)
        "inter_inits": name_list(inits, "--inits") if inits is not None and name in ("inter", "all") else None,
        "seeds": tuple(check_seed(s, "--seeds") for s in int_list(seeds, "--seeds")) if seeds is not None else None,
        "images": images,
        "vision_frames": vision_frames,
        "loss_reduction": None if loss_reduction is None else loss_reduction.value,
        "device": device,
        "threads": threads,
    }
    if optimizer is not None:  # (optimizer, lr, latent_lr, step): how θ and the codes step, and their rates
        keys = ("optimizer", "lr", "latent_lr", "step")
        overrides |= dict(zip(keys, (optimizer[0] and optimizer[0].value, *optimizer[1:])))
    if epochs is not None:
        fit_epochs, infer_epochs = _fit_infer_epochs(epochs)
        overrides |= {"fit_epochs": fit_epochs, "infer_epochs": infer_epochs or fit_epochs}
    return overrides


def _preset_of(preset: str | None, preset_names: str | None) -> str | None:
    """The preset an experiment runs for the ``--preset`` given: through the map of
    :mod:`primspace.experiments.presets` named ``preset_names`` where there is one."""
    if preset_names is None:
        return preset
    from primspace.experiments import presets as experiment_presets

    names = getattr(experiment_presets, preset_names)
    return names.get(preset or experiment_presets.DEFAULT_PRESET, preset)


def _run_steps(exp, name: str, steps: tuple[str, ...], table: str | None, options: dict | None = None) -> None:
    """Run each step (``module:function`` of :mod:`primspace.experiments`) on ``exp`` (with the
    keyword ``options``), then print ``table`` of the first step's results."""
    import importlib

    results = []
    for step in _judgeable_steps(exp, name, steps):
        module, function = step.split(":")
        run = getattr(importlib.import_module(f"primspace.experiments.{module}"), function)
        results.append(run(exp, **(options or {})))
    if table is not None:  # "function" of results.tables, or "module:function" of another module of results
        module, _, function = table.rpartition(":")
        tables = importlib.import_module(f"primspace.results.{module or 'tables'}")
        echo_table(*getattr(tables, function)(results[0]))


#: --device and --threads of the commands that run a grid of runs (the preset's TrainConfig).
_RUN_DEVICE_HELP = "Where each run trains: auto, cpu, cuda or cuda:N (default: the preset's, auto)."
_RUN_THREADS_HELP = (
    "CPU threads of torch and BLAS per run (default: the preset's, 1: the runs go in parallel, --workers of them)."
)
_INITS_HELP = (
    "Override the initialisations compared (by inter too, for inter and all), e.g. zero,projection,calibrated."
)
_VISION_FRAMES_HELP = "Vision loss on K drawn frames per sequence and step (default: every frame)."
_PACK_HELP = (
    "Train up to N runs of the intra-primitive grid at once on one device, packed (primspace.train.packed; "
    "within float tolerance of each run alone, not bit-identical). Default 1: each run alone."
)


_MOVE_AT_HELP = "experiment act: when the block is moved, fractions of the motion (default 0.2,0.3)."


def _act_options(name: str, move_at: str | None) -> dict:
    """The keyword options of ``experiment act`` (``--move-at``, checked before any work); one
    UserError when another experiment is given one."""
    if move_at is None:
        return {}
    if name != "act":
        raise UserError(f"--move-at is an option of experiment act, not of experiment {name}")
    from primspace.experiments.act import check_move_at

    return {"move_at": check_move_at(move_at)}


#: How a grid's runs step (the preset's TrainConfig): the options of every experiment command.
_STEPPING = {
    "optimizer": typer.Option(None, "--optimizer", help="Override: " + OPTIMIZER_HELP),
    "lr": typer.Option(None, "--lr", help="Override the learning rate of the weights."),
    "latent_lr": typer.Option(None, "--latent-lr", help="Override the learning rate of the codes."),
    "step": typer.Option(
        None, "--step", help="How each run's batches step: eager (default), compiled or captured (docs/performance.md)."
    ),
}


def _experiment_command(
    name: str, doc: str, steps: tuple[str, ...], table: str | None, preset_names: str | None = None
) -> None:
    """Register ``primspace experiment NAME``: run ``steps`` (``primspace.experiments.<module>:<function>``),
    then print ``table`` (a function of :mod:`primspace.results.tables`, or ``module:function`` of another
    module of :mod:`primspace.results`) of the first step's results.
    ``preset_names`` names the map in :mod:`primspace.experiments.presets` from the
    ``--preset`` a user gives to the preset this experiment runs (composite:
    ``COMPOSITE_PRESET_OF``, ``demo`` -> ``composite-demo``; read when the command runs, so
    the CLI starts without importing torch)."""

    def command(
        preset: str | None = typer.Option(
            None,
            "--preset",
            help="Experiment preset: demo (CPU, minutes; the default), paper (GPU recommended), lasa (real demonstrations, CPU) or real (the intra protocol on an imported --data file, docs/real.md); composite takes demo, paper or lasa.",
        ),
        data: Path | None = typer.Option(
            None, "--data", help="A data set file; default: generate the preset's simulated data into OUT."
        ),
        out: Path = typer.Option(..., "--out", "-o", help="The experiment directory."),
        backend: Backend = typer.Option(Backend.local, "--backend", help="local (process pool) or ray."),
        address: str | None = typer.Option(
            None, "--address", help="Ray cluster address (default: start a local Ray instance)."
        ),
        workers: int | None = typer.Option(None, "--workers", "-j", help="Parallel runs (default: all cores)."),
        pack: int = typer.Option(1, "--pack", metavar="N", help=_PACK_HELP),
        seed: int | None = typer.Option(
            None, "--seed", help="Seed of the generated data (default: the experiment's, 0)."
        ),
        latent_dims: str | None = typer.Option(
            None, "--latent-dims", help="Override the preset's latent sizes, e.g. 10,20,40."
        ),
        inits: str | None = typer.Option(None, "--inits", help=_INITS_HELP),
        seeds: str | None = typer.Option(None, "--seeds", help="Override the run seeds, e.g. 0,1,2."),
        epochs: str | None = typer.Option(None, "--epochs", help="Override the fit and infer epochs, e.g. 800,600."),
        images: bool | None = typer.Option(
            None, "--images/--no-images", help="Override whether the vision loss is trained."
        ),
        vision_frames: int | None = typer.Option(None, "--vision-frames", help=_VISION_FRAMES_HELP),
        loss_reduction: LossReduction | None = typer.Option(
            None,
            "--loss-reduction",
            help="Override the loss: mean, sum (the paper's) or precision (each modality weighed by its learned precision).",
        ),
        optimizer: Optimizer | None = _STEPPING["optimizer"],
        lr: float | None = _STEPPING["lr"],
        latent_lr: float | None = _STEPPING["latent_lr"],
        step: str | None = _STEPPING["step"],
        report: bool = typer.Option(True, "--report/--no-report", help="Write OUT/report.html at the end."),
        device: str | None = device_option(None, _RUN_DEVICE_HELP),
        threads: int | None = threads_option(None, _RUN_THREADS_HELP),
        move_at: str | None = typer.Option(None, "--move-at", help=_MOVE_AT_HELP),
    ) -> None:
        options = _act_options(name, move_at)
        stepping = (optimizer, lr, latent_lr, step)
        overrides = _overrides(
            name, latent_dims, inits, seeds, epochs, images, vision_frames, loss_reduction, device, threads, stepping
        )
        exp = _experiment(
            _preset_of(preset, preset_names), data, out, backend, address, workers, seed, overrides, pack=pack
        )
        _run_steps(exp, name, steps, table, options)
        _finish(exp, report or name == "all")

    command.__doc__ = doc
    experiment_app.command(name)(command)


_experiment_command(
    "intra",
    "Intra-primitive generalisation: fit on 20%, infer codes for 80%, per init and latent size.",
    ("intra:run_intra",),
    "final_loss_table",
)
_experiment_command(
    "clustering",
    "Subspace clustering of learned codes (runs intra if needed) and of raw trajectories (data, LASA).",
    ("clustering:run_clustering",),
    "latent_table",
)
_experiment_command(
    "success",
    "Success rates of generated eval motions, judged by the simulator (runs intra if needed).",
    ("success:run_success",),
    "success_table",
)
_experiment_command(
    "inter",
    "Inter-primitive generalisation: leave one primitive out, then learn it with 10% replay.",
    ("inter:run_inter",),
    "inter_table",
)
_experiment_command(
    "composite",
    "Long demonstrations of several primitives: a code per window, inferred with θ frozen, then "
    "segmented and labelled without labels (--preset demo or paper; docs/sequences.md).",
    ("composite.experiment:run_composite",),
    "composite:composite_table",
    preset_names="COMPOSITE_PRESET_OF",
)
_experiment_command(
    "tune",
    "Fair baselines: tune each init's layer time constants and latent learning rate on a validation split "
    "carved from the fitted part (the same grid and epochs for all), then rerun intra with each init's choice "
    "beside the shared setting (runs intra if needed).",
    ("tuning:run_tune",),
    "tuning_table",
)
_experiment_command(
    "predict",
    "Predict the rest of each motion from its beginning (10, 25, 50 % observed): primspace's starts "
    "against ProMP conditioning (given the labels), the nearest neighbour and the mean motion, on the intra split "
    "over seeds; judged in the simulator where it can (runs intra if needed; docs/predict.md).",
    ("prediction:run_predict",),
    "predict_error_table",
)
_experiment_command(
    "act",
    "Act from the scene and in closed loop in MuJoCo (see the block, do the primitive; the block moved 2-4 cm at "
    "30 % of the motion): the scene policy against the contextual ProMP, the nearest first frame and the mean motion "
    "(scene only), and against its own open loop and ProMP re-conditioned on the executed joints (closed loop), "
    "over seeds (runs intra if needed; needs simulated data with frames; docs/act.md).",
    ("act:run_act",),
    "act:act_table",
)
_experiment_command(
    "all",
    "Every experiment in turn (intra, clustering, success, inter), then the report.",
    ("intra:run_intra", "clustering:run_clustering", "success:run_success", "inter:run_inter"),
    None,
)


_REGIME_N_HELP = (
    "Fitted demonstrations kept per primitive, each from 1 to the fewest the preset's fitted split has "
    "(default 2,3,5,10,20,49)."
)


@experiment_app.command("regime")
def regime_command(
    preset: str | None = typer.Option(None, "--preset", help="Experiment preset: demo, paper or lasa."),
    data: Path | None = typer.Option(None, "--data", help="A data set file; default: the preset's simulated data."),
    out: Path = typer.Option(..., "--out", "-o", help="The experiment directory."),
    workers: int | None = typer.Option(None, "--workers", "-j", help="Parallel runs (default: all cores)."),
    seed: int | None = typer.Option(None, "--seed", help="Seed of the generated data (default 0)."),
    latent_dims: str | None = typer.Option(None, "--latent-dims", help="Override the preset's latent sizes."),
    seeds: str | None = typer.Option(None, "--seeds", help="Override the run seeds, e.g. 0,1,2."),
    epochs: str | None = typer.Option(None, "--epochs", help="Override the fit epochs (FIT[,INFER])."),
    images: bool | None = typer.Option(None, "--images/--no-images", help="Override the vision loss."),
    train_fraction: float | None = typer.Option(
        None, "--train-fraction", help="Override the share of each primitive in the fitted split (LASA: 0.72)."
    ),
    fitted_per_primitive: str | None = typer.Option(None, "--fitted-per-primitive", help=_REGIME_N_HELP),
    eval_per_primitive: int | None = typer.Option(
        None, "--eval-per-primitive", help="At most this many evaluation motions per primitive (default: all)."
    ),
    mixed: bool = typer.Option(True, "--mixed/--no-mixed", help="Also one primitive with 2 among the largest n."),
    promp_basis: str | None = typer.Option(
        None, "--promp-basis", help="The tuned ProMP's basis counts tried, e.g. 10,15,20 (default 10,15,20,30,40)."
    ),
    report: bool = typer.Option(False, "--report/--no-report", help="Write OUT/report.html at the end."),
    device: str | None = device_option(None, _RUN_DEVICE_HELP),
    threads: int | None = threads_option(None, _RUN_THREADS_HELP),
) -> None:
    """The regime where codes help: n fitted demonstrations per primitive, the run trained on them, the
    same evaluation motions predicted at 10/25/50 % by the prior (blend chosen and forced to the decoded
    draws), the raw Gaussian, the tuned ProMP, the mixture and the nearest neighbour (docs/predict.md)."""
    from primspace.experiments.regime import REGIME_N, check_counts, run_regime

    counts = REGIME_N if fitted_per_primitive is None else int_list(fitted_per_primitive, "--fitted-per-primitive")
    check_counts(counts, 10**9, "--fitted-per-primitive")  # the bounds of the data are checked once it is read
    if eval_per_primitive is not None:
        check_counts((eval_per_primitive,), 10**9, "--eval-per-primitive")
    if train_fraction is not None and not 0.0 < train_fraction < 1.0:
        raise UserError(f"--train-fraction must be between 0 and 1, got {train_fraction:g}")
    overrides = _overrides("regime", latent_dims, None, seeds, epochs, images, None, None, device, threads)
    overrides["train_fraction"] = train_fraction
    exp = _experiment(preset, data, out, Backend.local, None, workers, seed, overrides)
    basis = (
        None if promp_basis is None else check_counts(int_list(promp_basis, "--promp-basis"), 10**9, "--promp-basis")
    )
    settings = None if basis is None else {"promp_tuned": {"n_basis": basis}}
    results = run_regime(exp, counts, eval_per_primitive, mixed=mixed, settings=settings)
    from primspace.results.claim_rules_regime import check_regime

    row = check_regime(results)
    typer.echo(f"{row['hypothesis']}\n{row['verdict']}: {row['ours']}")
    _finish(exp, report)


@app.command("summarize")
def summarize_command(
    directory: Path = typer.Argument(..., help="An experiment directory."),
    name: str = typer.Option(..., "--name", help="The summary's name (its heading in the docs)."),
    command: str | None = typer.Option(
        None,
        "--command",
        help="The command(s) that made DIRECTORY, exactly as run (default: the ones its experiment.json recorded).",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="The summary file, e.g. docs/results/NAME.json."),
    note: str = typer.Option("", "--note", help="What a reader must know (e.g. other jobs shared the cores)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an earlier summary at OUT (nothing else)."),
) -> None:
    """Write the small summary of an experiment that the docs' tables are generated from
    (`python -m primspace.report.markdown`), and beside it (OUT with suffix .codes.npz) the
    codes of its runs, compressed (`primspace.results.codes.read_codes` reads them);
    run it on the machine that ran the experiment (it records the CPU)."""
    from primspace.experiments.summary_codes import write_summary_with_codes
    from primspace.results.codes import check_codes_output, codes_path
    from primspace.results.summary import summarize
    from primspace.utils.outputs import output_file

    # --overwrite replaces a summary only (recognised by its summary_version), never another file,
    # and a codes file only (its primspace_codes_version entry): both checked before anything is read
    path = output_file(out, inputs=(directory,), overwrite=overwrite, writer="primspace summarize")
    check_codes_output(codes_path(path), overwrite, inputs=(directory,))
    codes = write_summary_with_codes(path, summarize(directory, name, command, note), directory, overwrite)["codes"]
    missing = f"; not kept, their folders unreadable: {', '.join(codes['missing'])}" if codes["missing"] else ""
    typer.echo(f"wrote {path} and {codes_path(path)} (the codes of {codes['runs']} runs{missing})")


@app.command("report")
def report_command(directory: Path = typer.Argument(..., help="An experiment directory.")) -> None:
    """Write DIR/report.html from the results the directory holds."""
    from primspace.report import build_report

    typer.echo(f"report: {build_report(directory)}")


@app.command("demo")
def demo_command(
    out: Path = typer.Option(Path("demo-out"), "--out", "-o", help="Where the demo writes its data, runs and report."),
    workers: int | None = typer.Option(None, "--workers", "-j", help="Parallel runs (default: all cores)."),
    device: str | None = device_option(None, _RUN_DEVICE_HELP),
    threads: int | None = threads_option(None, _RUN_THREADS_HELP),
) -> None:
    """The main demo: simulate data, run intra + clustering + success at demo scale, write the report."""
    from primspace.demo import run_demo
    from primspace.utils.parallel import default_workers

    check_workers(workers)
    summary = run_demo(out, workers=workers or default_workers(), device=device, threads=threads)
    typer.echo(summary)
