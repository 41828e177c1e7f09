"""The ``primspace`` Typer application and its entry point.

Commands register themselves on :data:`app` from the modules of this package; a
:class:`~primspace.errors.UserError` raised anywhere below is printed by :func:`main` as
one line, ``primspace: error: ...``, with exit status 2 and no traceback.
"""

from __future__ import annotations

import re
import sys

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


# Library errors name Python parameters; the command line names its flags instead.
_PARAMETER_FLAGS = (
    (re.compile(r"\bresume=True\b"), "--resume"),
    (re.compile(r"\boverwrite=True\b"), "--overwrite"),
    (re.compile(r"\bepochs=(\d+)"), r"--epochs \1"),
    (re.compile(r"\bout_dir\b"), "--out"),
)


def as_flags(message: str) -> str:
    """A library error message in the command line's words (``resume=True`` -> ``--resume``)."""
    for pattern, flag in _PARAMETER_FLAGS:
        message = pattern.sub(flag, message)
    return message


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``primspace`` command (and ``python -m primspace``)."""
    try:
        app(args=argv, prog_name="primspace")
    except UserError as exc:
        typer.echo(f"primspace: error: {as_flags(str(exc))}", err=True)
        sys.exit(2)
    except OSError as exc:  # the file system said no (permissions, disk full, read-only): one line
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        typer.echo(f"primspace: error: {where}{exc.strerror or first_line(exc)}", err=True)
        sys.exit(2)
