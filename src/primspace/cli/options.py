"""Option parsing and output helpers shared by the commands."""

from __future__ import annotations

import json
from typing import Optional

import typer

from primspace.errors import UserError


def echo_json(obj) -> None:
    typer.echo(json.dumps(obj, indent=2))


def int_list(text: str, option: str) -> tuple[int, ...]:
    return _number_list(text, option, int, "whole numbers")


def name_list(text: str, option: str) -> tuple[str, ...]:
    values = tuple(v.strip() for v in text.split(",") if v.strip())
    if not values:
        raise UserError(f"{option} is empty")
    return values


def check_workers(workers: Optional[int]) -> None:
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
        table.add_row(*[f"{v:.4g}" if isinstance(v, float) else str(v) for v in row])
    Console().print(table)
