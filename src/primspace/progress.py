"""Progress bars for long work (rich), silent when asked or when not on a terminal."""

from __future__ import annotations

import contextlib
import sys
from typing import Callable, Iterator

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

__all__ = ["progress_bar"]


@contextlib.contextmanager
def progress_bar(
    total: int | None,
    description: str,
    *,
    enabled: bool | None = None,
    fields: str = "",
) -> Iterator[Callable[..., None]]:
    """Show a progress bar on stderr; yield ``advance(n=1, **fields)``.

    Parameters
    ----------
    total : int or None
        Number of steps (None: unknown).
    description : str
        Text before the bar.
    enabled : bool, optional
        Force the bar on or off. By default it shows only when stderr is a terminal,
        so logs and tests stay clean.
    fields : str
        A rich format string shown after the bar, filled from the keyword arguments of
        ``advance`` (e.g. ``"loss {task.fields[loss]:.4g}"``).

    Examples
    --------
    >>> with progress_bar(3, "epochs", enabled=False) as advance:
    ...     for _ in range(3):
    ...         advance()
    """
    if enabled is None:
        enabled = sys.stderr.isatty()
    if not enabled:
        yield lambda n=1, **kw: None
        return
    columns = [
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    ]
    if fields:
        columns.append(TextColumn(fields))
    with Progress(*columns, console=Console(stderr=True), transient=False) as progress:
        task = progress.add_task(description, total=total, **_placeholders(fields))

        def advance(n: int = 1, **kw) -> None:
            progress.update(task, advance=n, **kw)

        yield advance


def _placeholders(fields: str) -> dict:
    """Initial values for the fields a format string names, so it renders before the first update."""
    import re

    names = re.findall(r"task\.fields\[(\w+)\]", fields)
    return {name: float("nan") for name in names}
