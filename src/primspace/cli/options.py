"""Option parsing and output helpers shared by the commands."""

from __future__ import annotations

import json

import typer

from primspace.train.config import TrainConfig
from primspace.utils.errors import UserError

#: ``--threads``'s help, the same wherever torch runs (the default is ``TrainConfig.threads``).
THREADS_HELP = (
    "CPU threads of torch and of numpy's BLAS (more than the free cores make them wait on each other: "
    "13x slower on a busy machine; raise it on a machine of your own)."
)
DEVICE_HELP = "Where the model runs: auto (CUDA when present), cpu, cuda or cuda:N."


def threads_option(default=TrainConfig.threads, help: str = THREADS_HELP):
    """``--threads`` (:attr:`TrainConfig.threads`, torch's intra-op threads and BLAS's)."""
    return typer.Option(default, "--threads", help=help)


def device_option(default: str = TrainConfig.device, help: str = DEVICE_HELP):
    """``--device`` (:attr:`TrainConfig.device`)."""
    return typer.Option(default, "--device", help=help)


def configure_threads(threads: int | None, device: str = "cpu") -> None:
    """An entry point's process-wide settings for commands that run a model without training it."""
    from primspace.train import configure_process

    configure_process(TrainConfig(threads=threads, device=device).validate())


#: ``--allow-unfinished``'s help: the commands that use a trained run refuse one that stopped early.
ALLOW_UNFINISHED_HELP = "Use a run that stopped before its last epoch (Ctrl-C, a kill); default: refuse it."


def allow_unfinished_option():
    """``--allow-unfinished`` (:func:`check_finished`)."""
    return typer.Option(False, "--allow-unfinished", help=ALLOW_UNFINISHED_HELP)


def check_finished(run, allow: bool) -> None:
    """One line when ``run`` (a :class:`~primspace.train.run.TrainedRun`) stopped before its last
    epoch, unless ``allow``: it names the epochs done and the two ways on."""
    if allow or run.finished:
        return
    verb = "train" if run.kind == "fit" else "infer"
    raise UserError(
        f"{run.run_dir}: stopped after epoch {run.epoch} of {run.train_config.epochs}; finish it "
        f"(primspace {verb} ... --out {run.run_dir} --resume) or pass --allow-unfinished"
    )


#: ``train --scale-over-file``'s help.
SCALE_OVER_FILE_HELP = (
    "Fit the joints' scaling to [-1, 1] on every sample of DATA, as the experiments do (errors then in their "
    "units), not only on the samples trained on (--indices)."
)


def file_scaler(dataset, weights_from=None):
    """``train --scale-over-file``: the joint scaler fitted on every sample of ``dataset`` (what the
    experiments give every run); refused with ``--weights-from`` (the parent run's scaler is used)."""
    if weights_from is not None:
        raise UserError("--scale-over-file goes without --weights-from (the parent run's scaler is used)")
    from primspace.data import JointScaler

    return JointScaler().fit(dataset.motor)


def require_extra(module: str, package: str, extra: str, command: str, why: str) -> None:
    """One line naming ``pip install 'primspace[EXTRA]'`` when ``module`` (of ``package``, in the
    ``extra`` extra) is not installed: a command checks it before any work."""
    from importlib.util import find_spec

    if find_spec(module) is None:
        raise UserError(f"{command} needs the {package} package ({why}): pip install 'primspace[{extra}]'")


def echo_json(obj) -> None:
    typer.echo(json.dumps(obj, indent=2))


def int_list(text: str, option: str) -> tuple[int, ...]:
    return _number_list(text, option, int, "whole numbers")


def name_list(text: str, option: str) -> tuple[str, ...]:
    values = tuple(v.strip() for v in text.split(",") if v.strip())
    if not values:
        raise UserError(f"{option} is empty")
    return values


def check_workers(workers: int | None) -> None:
    """The same rule for every command's --workers: absent means every core, else >= 1."""
    if workers is not None and workers < 1:
        raise UserError(f"--workers {workers}: must be at least 1")


def float_list(text: str, option: str) -> tuple[float, ...]:
    return _number_list(text, option, float, "numbers")


def _number_list(text: str, option: str, kind: type, what: str) -> tuple:
    """``"1, 2,3"`` -> ``(1, 2, 3)``; one line naming ``option`` if a value is not a ``kind`` or none is given."""
    try:
        values = tuple(kind(v) for v in text.replace(" ", "").split(",") if v)
    except ValueError:
        raise UserError(f"{option} must be comma-separated {what}, got '{text}'") from None
    if not values:
        raise UserError(f"{option} is empty")
    return values


def echo_table(columns, rows) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(*[str(c) for c in columns])
    for row in rows:
        table.add_row(*[cell_text(v) for v in row])
    Console().print(table)


def cell_text(value) -> str:
    """A value as a table cell or an output line: numbers to 4 digits, a dict as ``key value, ...``
    and a list as ``a, b`` (never Python's ``{'key': ...}``)."""
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, dict):
        return ", ".join(f"{k} {cell_text(v)}" for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return ", ".join(cell_text(v) for v in value)
    return str(value)
