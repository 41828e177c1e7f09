"""Diagnostics of a trained run: ``primspace diagnose loss-balance``."""

from __future__ import annotations

import os
from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.options import configure_threads, threads_option
from primspace.utils.errors import UserError

diagnose_app = typer.Typer(
    help="Diagnostics of a trained run: what its loss and its errors are made of.", no_args_is_help=True
)
app.add_typer(diagnose_app, name="diagnose")

#: The mark ``diagnose loss-balance`` writes into its JSON (``writer``, :mod:`primspace.utils.outputs`).
_LOSS_BALANCE_MARK = "primspace diagnose loss-balance"


@diagnose_app.command("loss-balance")
def loss_balance_command(
    run: Path = typer.Argument(..., help="A run directory (fit or infer)."),
    data: Path | None = typer.Option(None, "--data", help="The data file, with labels (default: the run's)."),
    json_out: str | None = typer.Option(None, "--json", help="Also write the full result to this JSON file."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an earlier loss-balance JSON at --json."),
    batch_size: int = typer.Option(8, "--batch-size", help="Samples per forward and backward pass (bounds memory)."),
    no_gradients: bool = typer.Option(False, "--no-gradients", help="Leave out the gradients (faster)."),
    threads: int | None = threads_option(),
) -> None:
    """How the loss's motor and vision terms share the training signal, on the run's own samples.

    Prints the terms of the run's own loss (its reduction and weights), the norms of their
    gradients with respect to the decoder's weights and to the codes with the cosine between
    them, and the motor RMS error per primitive and joint in the data's joint units.
    """
    from primspace.data import MotionDataset
    from primspace.experiments.loss_balance import loss_balance
    from primspace.train import load_run
    from primspace.utils.files import atomic_write_json
    from primspace.utils.outputs import output_file

    configure_threads(threads, "cpu")
    if not run.is_dir():
        raise UserError(f"{run}: no such run directory")
    trained = load_run(run)
    path = data if data is not None else trained.data_path
    if path is None:
        raise UserError(f"{run}: the run does not record its data file; pass --data FILE")
    if not Path(path).is_file():
        raise UserError(
            f"{path}: no such data file" + ("" if data is not None else f" (recorded by run {run}); pass --data")
        )
    out = (
        None
        if json_out is None
        else output_file(json_out, inputs=(run, path), overwrite=overwrite, option="--json", writer=_LOSS_BALANCE_MARK)
    )
    result = loss_balance(trained, MotionDataset.load(path), batch_size=batch_size, gradients=not no_gradients)
    _print_result(result)
    if out is not None:
        atomic_write_json(out, {"writer": _LOSS_BALANCE_MARK, **result})
        typer.echo(f"wrote {out}")


def _print_result(result: dict) -> None:
    typer.echo(
        f"{result['run']}: {result['kind']} run ({result['init']}, epoch {result['epoch']}), "
        f"{result['n_samples']} samples; loss reduction {result['loss_reduction']}, weights motor "
        f"{result['motor_weight']:g} vision {result['vision_weight']:g}; images {'on' if result['images'] else 'off'}"
    )
    if result.get("precision"):
        typer.echo("learned precisions (loss reduction precision): " + _precision_line(result["precision"]))
    groups = [("all", result), *result["per_primitive"].items()]
    typer.echo("the loss's terms (the run's reduction and weights), per primitive:")
    _echo_table(
        ["primitive", "n", "motor term", "vision term", "vision share", "motor MSE", "vision MSE", "motor RMS"],
        [[name, part["n_samples" if name == "all" else "n"], *_term_cells(part)] for name, part in groups],
    )
    if "gradients" in result:
        typer.echo("gradient norms (theta: of the mean loss; codes: mean over samples of each code's own):")
        _echo_table(
            ["primitive", "theta motor", "theta vision", "cos (dynamics)", "codes motor", "codes vision", "cos codes"],
            [[name, *_gradient_cells(part["gradients"])] for name, part in groups],
        )
        theta = result["gradients"]["theta"]
        parts = [k for k in ("dynamics", "motor_head", "image_head", "all") if k in theta["motor"]]
        typer.echo("theta gradient norm by part (all samples):")
        _echo_table(
            ["term", *parts], [[t, *(theta[t].get(k, "") for k in parts)] for t in ("motor", "vision") if t in theta]
        )
    joints = _short_names(result["joints"])
    table = [[name, *row] for name, row in zip(result["primitives"], result["joint_rms"]["values"])]
    table.append(["all", *result["joint_rms"]["all"]])
    typer.echo("motor RMS error per primitive and joint, in the data's joint units:")
    _echo_table(["primitive", *joints], table)


def _precision_line(precision: dict) -> str:
    """``motor s_m … weight e^(-s_m) …; vision …`` of a loss-balance result's ``precision``."""
    return "; ".join(
        f"{m} log-variance s {v['log_variance']:.3g}, weight exp(-s) {v['weight']:.3g}" for m, v in precision.items()
    )


def _short_names(names: list[str]) -> list[str]:
    """Joint names without their common prefix (``robot:panda0_joint1`` -> ``joint1``)."""
    prefix = os.path.commonprefix(names) if len(names) > 1 else ""
    prefix = prefix[: max(prefix.rfind(c) for c in ":_") + 1] if prefix else ""
    return [name[len(prefix) :] or name for name in names]


def _term_cells(part: dict) -> list:
    """A row's terms, vision share, per-element MSEs and motor RMS ('' where absent)."""
    terms, mse, share = part["terms"], part["mse"], part["vision_share"]
    return [
        terms.get("motor", ""),
        terms.get("vision", ""),
        "" if share is None else f"{share:.1%}",
        mse.get("motor", ""),
        mse.get("vision", ""),
        part["motor_rms"],
    ]


def _gradient_cells(grads: dict) -> list:
    """A row's gradient norms and cosines ('' where absent)."""
    theta, codes = grads["theta"], grads["codes"]
    return [
        theta.get("motor", {}).get("all", ""),
        theta.get("vision", {}).get("all", ""),
        _number(theta.get("cosine", {}).get("dynamics")),
        codes.get("motor", ""),
        codes.get("vision", ""),
        _number(codes.get("cosine")),
    ]


def _number(value) -> str:
    return "" if value is None else f"{value:.3f}"


def _echo_table(columns: list, rows: list) -> None:
    """A plain table, numbers to 3 digits, never cut short (a wide table runs past the terminal)."""
    cells = [[str(c) for c in columns]] + [[v if isinstance(v, str) else _short(v) for v in row] for row in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(columns))]
    for k, row in enumerate(cells):
        typer.echo("  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))))
        if k == 0:
            typer.echo("  ".join("-" * w for w in widths))


def _short(value) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)
