"""The ``primspace`` Typer application and its entry point.

Commands register themselves on :data:`app` from the modules of this package; a
:class:`~primspace.utils.errors.UserError` raised anywhere below is printed by :func:`main` as
one line, ``primspace: error: ...``, with exit status 2 and no traceback. So is every
error of the option parser (an unknown option or command, a bad or missing value): one
line naming the option, not Click's usage box.
"""

from __future__ import annotations

import errno
import os
import re
import sys

import typer
import typer.main

from primspace.utils.errors import UserError, first_line

try:  # typer >= 0.2x carries its own copy of Click
    from typer._click import core as _click_core
    from typer._click import exceptions as _click_errors
except ImportError:  # pragma: no cover - older typer runs on Click itself
    from click import core as _click_core
    from click import exceptions as _click_errors

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
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Latent spaces of robot motion primitives (Nikulin & Tani): data, simulator, MTRNN
    decoder, subspace clustering, experiments."""


# Library errors name Python parameters; the command line names its flags instead.
_PARAMETER_FLAGS = (
    (re.compile(r"\bresume=True\b"), "--resume"),
    (re.compile(r"\boverwrite=True\b"), "--overwrite"),
    (re.compile(r"\bepochs=(\d+)"), r"--epochs \1"),
    (re.compile(r"\bout_dir\b"), "--out"),
    (re.compile(r"\bfitted_data=MotionDataset\.load\(PATH\)"), "--fitted-data PATH"),  # train.rundata
    (re.compile(r"\bfitted_data=(?= )"), "--fitted-data FILE"),
    (re.compile(r"\bprimitives='clusters'"), "--primitives clusters"),  # the prior (predict.primitives)
    (re.compile(r"\bneed n_clusters\b"), "need --primitives K"),
    (re.compile(r"\bfitted_per_primitive\b"), "--fitted-per-primitive"),  # experiments.regime
    (re.compile(r"\beval_per_primitive\b"), "--eval-per-primitive"),
)


def as_flags(message: str) -> str:
    """A library error message in the command line's words (``resume=True`` -> ``--resume``)."""
    for pattern, flag in _PARAMETER_FLAGS:
        message = pattern.sub(flag, message)
    return message


def _given_value(exc, args: list[str]) -> str | None:
    """The value given to the option a :class:`BadParameter` names (``--k 1.5`` -> ``1.5``)."""
    if not isinstance(exc, _click_errors.BadParameter) or isinstance(exc, _click_errors.MissingParameter):
        return None
    opts = getattr(getattr(exc, "param", None), "opts", None) or []
    for i, arg in enumerate(args):
        for opt in opts:
            if arg == opt and i + 1 < len(args):
                return args[i + 1]
            if opt.startswith("--") and arg.startswith(opt + "="):
                return arg[len(opt) + 1 :]
    return None


def _usage_line(exc, args: list[str]) -> str:
    """A Click usage error as one line: its message, the value given, where to find help."""
    text = " ".join(exc.format_message().split())
    value = _given_value(exc, args)
    if value is not None and repr(value) not in text:
        text = f"{text.rstrip('.')}; got {value!r}"
    ctx = getattr(exc, "ctx", None)
    if ctx is not None and ctx.command.get_help_option(ctx) is not None:
        text += f" (see '{ctx.command_path} --help')"
    return text


def click_command():
    """The Click command of :data:`app`, its help made readable: an option of a few choices
    shows a short metavar (its name) instead of ``<zero|random|...>``, which the help's
    type column folds mid-word on a narrow terminal, and its help names the choices."""
    root = typer.main.get_command(app)
    todo = [root]
    _no_flag_types(root)
    while todo:
        group = todo.pop()
        for sub in getattr(group, "commands", {}).values():
            todo.append(sub)
            _no_flag_types(sub)
            for param in sub.params:
                _short_choices(param)
    return root


def _no_flag_types(command) -> None:
    """A flag (``--overwrite``, ``--version``, ``--help``) takes no value: its help shows no type
    (typer shows ``<bool>``). The help option is made here, as Click caches it, to be marked too."""
    context = _click_core.Context(command, help_option_names=app.info.context_settings["help_option_names"])
    for param in [*command.params, command.get_help_option(context)]:
        if param is not None and getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""


def _short_choices(param) -> None:
    described = getattr(param, "type_descriptor", None)
    if param.param_type_name != "option" or described is None or not described.is_choice or param.metavar:
        return
    choices = [str(getattr(c, "value", c)) for c in described.choices]
    param.metavar = param.name.upper()
    words = set(re.findall(r"[\w-]+", param.help or ""))
    if not all(c in words for c in choices):
        param.help = ((param.help or "").rstrip() + f" One of: {', '.join(choices)}.").strip()


def _run(args: list[str]) -> int:
    """Parse ``args`` and run the command; return the exit status (Click's errors propagate)."""
    command = click_command()
    try:
        with command.make_context("primspace", args) as ctx:
            command.invoke(ctx)
    except typer.Exit as exc:  # --help, --version, a command's own exit status
        return exc.exit_code
    return 0


#: The arguments of the command :func:`main` is running (None outside it): experiments
#: record them in experiment.json, so a summary names the commands that made its runs.
INVOCATION: list[str] | None = None


def invocation() -> list[str] | None:
    """The arguments of the running ``primspace`` command (:data:`INVOCATION`)."""
    return INVOCATION


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``primspace`` command (and ``python -m primspace``).

    Every error a user can fix is one line on stderr, ``primspace: error: ...``, exit 2:
    a :class:`~primspace.utils.errors.UserError`, a refusal of the file system, and any error
    of the option parser. Ctrl-C is one line and exit 130. ``primspace`` alone prints the
    help (exit 2, as Click does).
    """
    global INVOCATION
    args = list(sys.argv[1:] if argv is None else argv)
    INVOCATION = args
    try:
        code = _run(args)
    except getattr(_click_errors, "NoArgsIsHelpError", ()) as exc:  # the help, printed already or here
        if exc.format_message().strip():
            typer.echo(exc.format_message())
        sys.exit(exc.exit_code)
    except _click_errors.ClickException as exc:  # the option parser's usage errors
        typer.echo(f"primspace: error: {_usage_line(exc, args)}", err=True)
        sys.exit(2)
    except (KeyboardInterrupt, EOFError, typer.Abort) as exc:  # Interrupted says what was saved
        said = first_line(exc) if isinstance(exc, KeyboardInterrupt) and str(exc) else ""
        typer.echo("primspace: error: interrupted" + (f": {as_flags(said)}" if said else ""), err=True)
        sys.exit(130)
    except UserError as exc:
        typer.echo(f"primspace: error: {as_flags(str(exc))}", err=True)
        sys.exit(2)
    except OSError as exc:  # the file system said no (permissions, disk full, read-only): one line
        if exc.errno == errno.EPIPE:  # the reader left (`primspace info ... | head`): quietly, as Click does
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            sys.exit(1)
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        typer.echo(f"primspace: error: {where}{exc.strerror or first_line(exc)}", err=True)
        sys.exit(2)
    if code:
        sys.exit(code)
