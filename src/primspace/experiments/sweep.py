"""Run a grid of independent experiment runs: resumable, failure-tolerant, any backend.

Each grid point has a key (``"intra/projection-q40-s0"``) that names its run directory
``OUT/runs/<key>``. A point whose ``result.json`` exists is finished and is not run
again; a point that was interrupted resumes from its own checkpoints (the run function
decides how); a point that fails leaves ``error.txt`` with the error and does not stop
the others. Seeds come from the grid point (they are part of its arguments), never from
the worker or backend, so ``local`` and ``ray`` give identical results.

On a Ray cluster ``OUT`` must be a directory every node sees (a shared file system):
each run writes its own directory there, atomically.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from primspace.results.layout import ERROR_FILE, RESULT_FILE, run_dir_of
from primspace.utils.files import atomic_write_json, atomic_write_text
from primspace.utils.parallel import run_jobs

__all__ = ["GridPoint", "GridResult", "run_grid", "complete_result"]


@dataclass(frozen=True)
class GridPoint:
    """One run of a grid: ``fn(run_dir, *args)`` with ``run_dir = OUT/runs/<key>``."""

    key: str
    args: tuple = ()


@dataclass
class GridResult:
    """What a grid produced: results by key, errors by key, and the keys found finished."""

    results: dict[str, Any] = field(default_factory=dict)
    failures: dict[str, str] = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failures


def run_grid(
    fn: Callable[..., Any],
    points: Sequence[GridPoint],
    out_dir: str | Path,
    *,
    backend: str = "local",
    workers: int | None = 1,
    address: str | None = None,
    description: str = "runs",
    progress: bool | None = None,
) -> GridResult:
    """Run every unfinished grid point; return all results (finished earlier ones included).

    Parameters
    ----------
    fn : callable
        Module-level ``fn(run_dir, *args) -> JSON-serialisable result``.
    points : sequence of GridPoint
        Keys must be unique.
    out_dir : path
        The experiment directory; runs go to ``out_dir/runs/<key>``.
    backend, workers, address
        See :func:`primspace.utils.parallel.run_jobs`.
    """
    keys = [p.key for p in points]
    if len(set(keys)) != len(keys):
        raise ValueError("grid keys must be unique")
    grid = GridResult()
    todo: list[GridPoint] = []
    for point in points:
        done = run_dir_of(out_dir, point.key) / RESULT_FILE
        if done.exists():
            grid.results[point.key] = json.loads(done.read_text())
            grid.skipped.append(point.key)
        else:
            todo.append(point)
    items = [(fn, str(run_dir_of(out_dir, p.key)), p.args) for p in todo]
    for outcome in run_jobs(
        _run_point,
        items,
        backend=backend,
        workers=workers,
        address=address,
        description=description,
        progress=progress,
    ):
        point = todo[outcome.index]
        run_dir = run_dir_of(out_dir, point.key)
        if outcome.ok:
            grid.results[point.key] = outcome.value
        else:
            grid.failures[point.key] = outcome.error
            run_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(run_dir / ERROR_FILE, (outcome.traceback or outcome.error) + "\n")
    return grid


def complete_result(out_dir: str | Path, key: str, extra: dict) -> dict:
    """Add ``extra`` to the stored result of the finished grid point ``key`` (written
    atomically) and return the whole result: for values a later version computes
    from a finished run, so that old runs are completed once instead of re-run."""
    path = run_dir_of(out_dir, key) / RESULT_FILE
    value = json.loads(path.read_text()) | extra
    atomic_write_json(path, value)
    return value


def _run_point(fn: Callable[..., Any], run_dir: str, args: tuple) -> Any:
    path = Path(run_dir)
    path.mkdir(parents=True, exist_ok=True)
    (path / ERROR_FILE).unlink(missing_ok=True)
    value = fn(path, *args)
    atomic_write_json(path / RESULT_FILE, value)
    return value
