"""Progress of long work on stderr: rich bars and spinners in a terminal, timestamped lines
in a log (stderr not a terminal), nothing when asked.

Three helpers, one rule for all: ``enabled=None`` (the default) draws in a terminal and
writes lines otherwise; ``True`` draws; ``False`` is silent.

* :func:`progress_bar`: work of counted steps (epochs, jobs);
* :func:`stage`: one long call with nothing to count (a spinner and the time elapsed);
* :func:`announce`: the heading of a stage of several (one line, in a terminal too).

In a log, a step that ends within :data:`LOG_AFTER` seconds writes nothing (quick commands
and tests stay clean); a longer one writes a line when it has run that long, a line each
tenth of its steps (with the time left at the average pace so far), and a line when it
ends, with its time.
"""

from __future__ import annotations

import contextlib
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator
from types import SimpleNamespace

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)
from rich.text import Text

__all__ = ["LOG_AFTER", "announce", "progress_bar", "remaining_seconds", "stage"]

#: Seconds a step runs before it writes its lines to a log (stderr not a terminal).
LOG_AFTER = 5.0


def _mode(enabled: bool | None) -> str:
    """``"bar"``, ``"log"`` or ``"off"`` for an ``enabled`` argument (module docstring)."""
    if enabled is None:
        return "bar" if sys.stderr.isatty() else "log"
    return "bar" if enabled else "off"


def _write(text: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


class _LogLines:
    """The lines of one step in a log: after :data:`LOG_AFTER` seconds, each tenth, the end."""

    def __init__(self, description: str, total: int | None, fields: str):
        self.description, self.total, self.fields = description, total, fields
        self.done, self.values, self.started = 0, {}, time.monotonic()
        self.shown, self.next_tenth = False, 1
        self.lock = threading.Lock()
        self.timer = threading.Timer(LOG_AFTER, self._first)
        self.timer.daemon = True
        self.timer.start()

    def _state(self) -> str:
        count = f"{self.done}/{self.total}" if self.total else str(self.done) if self.done else ""
        shown = ""
        if self.fields and self.values:
            try:
                shown = self.fields.format(task=SimpleNamespace(fields=self.values))
            except (KeyError, ValueError, TypeError):
                shown = ""
        return ", ".join(p for p in (count, re.sub(r"\s{2,}", ", ", shown.strip())) if p)  # a bar's gaps: commas

    def _first(self) -> None:
        with self.lock:
            if not self.shown:
                self.shown = True
                state = self._state()
                _write(f"{self.description}: running" + (f" ({state})" if state else ""))

    def advance(self, n: int, values: dict) -> None:
        with self.lock:
            self.done += n
            self.values |= values
            if not self.shown or not self.total or self.done * 10 < self.next_tenth * self.total:
                return
            while self.done * 10 >= self.next_tenth * self.total:
                self.next_tenth += 1
            if self.done < self.total:
                elapsed = time.monotonic() - self.started
                left = remaining_seconds(elapsed, self.done, self.total)
                _write(f"{self.description}: {self._state()}, {elapsed:.0f} s, about {left:.0f} s left")

    def finish(self, ok: bool) -> None:
        self.timer.cancel()
        with self.lock:
            if self.shown or time.monotonic() - self.started >= LOG_AFTER:
                state = self._state()
                end = "done" if ok else "stopped"
                _write(
                    f"{self.description}: {end}"
                    + (f" ({state})" if state else "")
                    + f" in {time.monotonic() - self.started:.1f} s"
                )


def remaining_seconds(elapsed: float | None, done: float, total: float | None) -> float | None:
    """The time left at the average pace since the start: ``elapsed * (total - done) / done``;
    None before the first step is done (or with no total): nothing to estimate from yet."""
    if not total or not done or elapsed is None:
        return None
    return max(0.0, elapsed * (total - done) / done)


class AverageRemainingColumn(ProgressColumn):
    """A bar's time left at its average pace since it started (:func:`remaining_seconds`), shown
    as ``-:--:--`` until a step is done. Rich's own column extrapolates the pace of the last 30 s
    from the first step on, which claims seconds left when jobs running in parallel end together
    after minutes."""

    def render(self, task) -> Text:
        left = remaining_seconds(task.elapsed, task.completed, task.total)
        if left is None:
            return Text("-:--:--", style="progress.remaining")
        minutes, seconds = divmod(int(round(left)), 60)
        hours, minutes = divmod(minutes, 60)
        return Text(f"{hours}:{minutes:02d}:{seconds:02d}", style="progress.remaining")


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
        True draws the bar, False is silent. By default it draws when stderr is a
        terminal and otherwise writes a log's lines (module docstring).
    fields : str
        A rich format string shown after the bar, filled from the keyword arguments of
        ``advance`` (e.g. ``"loss {task.fields[loss]:.4g}"``).

    Examples
    --------
    >>> with progress_bar(3, "epochs", enabled=False) as advance:
    ...     for _ in range(3):
    ...         advance()
    """
    mode = _mode(enabled)
    if mode == "off":
        yield lambda n=1, **kw: None
        return
    if mode == "log":
        lines = _LogLines(description, total, fields)
        ok = False
        try:
            yield lambda n=1, **kw: lines.advance(n, kw)
            ok = True
        finally:
            lines.finish(ok)
        return
    columns = [
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        AverageRemainingColumn(),
    ]
    if fields:
        columns.append(TextColumn(fields))
    with Progress(*columns, console=Console(stderr=True), transient=False) as progress:
        task = progress.add_task(description, total=total, **_placeholders(fields))

        def advance(n: int = 1, **kw) -> None:
            progress.update(task, advance=n, **kw)

        yield advance


@contextlib.contextmanager
def stage(description: str, *, enabled: bool | None = None) -> Iterator[None]:
    """One long call with nothing to count: a spinner and the time elapsed in a terminal
    (cleared when it ends), a log's lines otherwise (module docstring). Not around work
    that draws bars of its own (rich shows one live display at a time): use
    :func:`announce` there.
    """
    mode = _mode(enabled)
    if mode == "off":
        yield
        return
    if mode == "log":
        with progress_bar(None, description, enabled=None):
            yield
        return
    columns = [SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn()]
    with Progress(*columns, console=Console(stderr=True), transient=True) as progress:
        progress.add_task(description, total=None)
        yield


def announce(text: str, *, enabled: bool | None = None) -> None:
    """One line on stderr naming a stage of several (timestamped in a log); nothing when
    ``enabled`` is False."""
    mode = _mode(enabled)
    if mode == "log":
        _write(text)
    elif mode == "bar":
        Console(stderr=True).print(f"[bold]{text}[/bold]", highlight=False)


def _placeholders(fields: str) -> dict:
    """Initial values for the fields a format string names, so it renders before the first update."""
    names = re.findall(r"task\.fields\[(\w+)\]", fields)
    return {name: float("nan") for name in names}
