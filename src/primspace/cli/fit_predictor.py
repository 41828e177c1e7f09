"""``primspace fit-predictor``: choose a run's predictor for a task by held-out evidence, and keep the choice.

The choice ``primspace predict`` makes on its first call without ``--init``
(:class:`~primspace.predict.selection.SelectedPredictor`), made explicitly: every candidate's
K-fold error on the fitted demonstrations is printed as a table, and the choice is kept in the
run folder (``RUN/selection/``), where ``primspace predict`` with the same fitted data, task and
settings reads it (docs/predict.md, *How the predictor is chosen*).
"""

from __future__ import annotations

from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.observing import observed_amount
from primspace.cli.options import allow_unfinished_option, check_finished, threads_option


@app.command("fit-predictor")
def fit_predictor_command(
    run: Path = typer.Argument(..., help="A fitted run directory (its weights are frozen)."),
    fitted: Path | None = typer.Argument(
        None, metavar="[DATA]", help="The data file the run was fitted on (default: the run's own)."
    ),
    observe: str | None = typer.Option(
        None, "--observe", help="The task's observed joints: a fraction, 0.25 (the default) or 25%, as for predict."
    ),
    observe_steps: int | None = typer.Option(
        None, "--observe-steps", help="The task's observed joints: the first N steps (instead of --observe)."
    ),
    primitive: str | None = typer.Option(
        None,
        "--primitive",
        help="The task gives the primitive (a name or an id, as for predict): the candidates are the prior "
        "given it and the mixture restricted to it. Without it: the mixture and the prior's posterior.",
    ),
    primitives: str | None = typer.Option(
        None, "--primitives", "-k", help="The prior's primitives: labels (the default), clusters or a number K."
    ),
    prior_samples: int | None = typer.Option(
        None, "--prior-samples", help="The prior: codes drawn and decoded per primitive (default 2000)."
    ),
    seed: int | None = typer.Option(
        None, "--seed", help="Seed of the folds and the prior's draws (default: the run's)."
    ),
    continuity: bool = typer.Option(True, "--continuity/--no-continuity", help="As for predict (default on)."),
    threads: int | None = threads_option(),
    allow_unfinished: bool = allow_unfinished_option(),
) -> None:
    """Choose the predictor of a task by its K-fold error on the fitted demonstrations; print every
    candidate's error and keep the choice in the run folder for primspace predict."""
    from primspace.cli.predict import parse_primitives
    from primspace.data.dataset import MotionDataset
    from primspace.predict import AUTO, PredictRequest, fit_predictor, make_predictor
    from primspace.train import TrainConfig, configure_process, load_run
    from primspace.train.observe import NOTHING, Observation
    from primspace.utils.seeds import check_seed

    if seed is not None:
        check_seed(seed, "--seed")
    source, clusters = parse_primitives(primitives, clusters=None)
    amount = observed_amount(observe, observe_steps, "--observe", (NOTHING,))
    rule = Observation.build(0.25 if amount is None else amount)
    configure_process(TrainConfig(threads=threads).validate())
    trained = load_run(run)
    check_finished(trained, allow_unfinished)
    data = MotionDataset.load(fitted) if fitted is not None else None
    settings = dict(primitive=primitive, primitives=source, n_clusters=clusters, prior_samples=prior_samples)
    overrides = {} if seed is None else {"seed": seed}
    request = PredictRequest.of(init=AUTO, continuity=continuity, progress=None, **settings, **overrides)
    predictor = fit_predictor(make_predictor(trained, request=request), trained, data)
    selection = predictor.select(rule)
    typer.echo(selection_table(selection))
    if selection.get("reused"):
        typer.echo(f"reused the choice kept earlier for this run, data and task: {selection['reused']}")
    elif selection.get("kept"):
        typer.echo(f"kept in {selection['kept']}: primspace predict {run} ... reads it")
    else:
        typer.echo("not kept: the run folder cannot be written, or a file there is not a kept choice")


def selection_table(selection: dict) -> str:
    """The candidates' K-fold errors as a table, the chosen one marked."""
    folds = selection["folds"]
    width = max([len("candidate"), *map(len, selection["errors"])])
    head = f"{'candidate':<{width}} {f'{folds}-fold MSE' if folds else 'not scored':>14}"
    rows = [head]
    for name, error in selection["errors"].items():
        value = "-" if error is None else f"{error:.4g}"
        rows.append(f"{name:<{width}} {value:>14}" + ("   <- chosen" if name == selection["chosen"] else ""))
    return "\n".join(rows)
