"""The output directory of ``primspace cluster``: labels, result JSON, figures, written atomically.

Layout of ``DIR``::

    labels.csv        sample, predicted[, true]   (sample: the data file's index; true: -1 = unknown)
    result.json       input, options, tau / tau_relative / R^2 / rank, singular values,
                      eigenvalues, spectral method, scores (or null), seconds
    clustering.png    the paper-style figure (affinity ordered by true label; predicted
                      label per sample); at most FIGURE_MAX_POINTS samples, drawn at random
    sweep.csv, sweep.json, sweep.png    with --sweep: tau, R^2, rank and scores per grid value

The directory is built beside ``DIR`` under a temporary name and published without
replacing anything, so a failure leaves nothing half-written and a ``DIR`` that another
run published meanwhile is never merged into. An existing empty ``DIR`` is written into in
place (never swapped for a new folder; refused in one line if it is not writable); a
non-empty one is refused unless ``overwrite``, and even then unless it is an earlier
cluster output: then only the files above are replaced, and any other file in ``DIR`` is
left alone.
"""

from __future__ import annotations

import contextlib
import csv
import functools
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from primspace import files
from primspace.errors import OutputExistsError, UserError
from primspace.files import atomic_write_json, atomic_write_text
from primspace.outputs import describe

__all__ = [
    "OutputKind",
    "CLUSTER_OUTPUT",
    "atomic_directory",
    "check_output_directory",
    "is_cluster_output",
    "is_output_of",
    "OUTPUT_FILES",
    "figure_indices",
    "write_labels_csv",
    "write_sweep_csv",
    "write_json",
    "to_jsonable",
    "FIGURE_MAX_POINTS",
]

FIGURE_MAX_POINTS = 2000
#: Every file ``primspace cluster`` writes into its output directory.
OUTPUT_FILES = ("labels.csv", "result.json", "clustering.png", "sweep.csv", "sweep.json", "sweep.png")


@dataclass(frozen=True)
class OutputKind:
    """A command's output directory: the command, the files it writes, and the keys its
    ``result.json`` always holds (how an earlier output of it is recognised)."""

    command: str
    files: tuple[str, ...]
    result_keys: frozenset


#: ``primspace cluster``'s output directory.
CLUSTER_OUTPUT = OutputKind("primspace cluster", OUTPUT_FILES, frozenset({"n_clusters", "tau_option", "rank"}))

SWEEP_COLUMNS = ("grid", "value", "tau", "tau_relative", "r2", "rank", "accuracy", "nmi", "ari", "note")


def check_output_directory(path: str | os.PathLike, overwrite: bool = False, kind: OutputKind = CLUSTER_OUTPUT) -> Path:
    """Refuse a file, a non-empty directory unless ``overwrite``, and (even with
    ``overwrite``) a non-empty directory that is not an earlier output of ``kind``'s
    command; return the path."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise UserError(f"{path}: exists and is not a directory")
        if any(path.iterdir()):
            if not overwrite:
                raise OutputExistsError(path)
            if not is_output_of(path, kind):
                raise UserError(
                    f"{path}: exists and is not a {kind.command} output ({_result_of(path)}); "
                    f"--overwrite only replaces an earlier {kind.command} output: choose another --out"
                )
    return path


def _result_of(path: Path) -> str:
    """What ``path``'s result.json is, for a refusal: none, or the mark of the command that wrote it."""
    result = Path(path) / "result.json"
    return f"its result.json is {describe(result)}" if result.is_file() else "it holds no result.json"


def is_output_of(path: Path, kind: OutputKind) -> bool:
    """Whether ``path`` holds a ``result.json`` written by ``kind``'s command."""
    try:
        result = json.loads((Path(path) / "result.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return False
    return isinstance(result, dict) and kind.result_keys <= set(result)


def is_cluster_output(path: Path) -> bool:
    """Whether ``path`` holds a ``result.json`` written by ``primspace cluster``."""
    return is_output_of(path, CLUSTER_OUTPUT)


@contextlib.contextmanager
def atomic_directory(
    path: str | os.PathLike, overwrite: bool = False, kind: OutputKind = CLUSTER_OUTPUT
) -> Iterator[Path]:
    """Yield a temporary directory beside ``path``; on success its files land in ``path``.

    :func:`primspace.files.atomic_directory` with this module's rules
    (:func:`check_output_directory`, checked again when publishing): a new ``path`` is the
    temporary directory renamed without replacing anything; an existing empty one is
    written into in place; an earlier output of ``kind``'s command (``overwrite``) gets
    each new file renamed over the old one and the earlier run's other outputs
    (``kind.files``, e.g. a sweep not asked for this time) removed; any other file in it
    is left alone. On failure the temporary directory is removed and ``path`` is untouched.
    """
    check = functools.partial(check_output_directory, overwrite=overwrite, kind=kind)
    with files.atomic_directory(path, check, owned=kind.files, last="result.json") as tmp:
        yield tmp


def figure_indices(n: int, max_points: int = FIGURE_MAX_POINTS, seed: int = 0) -> np.ndarray:
    """All samples, or ``max_points`` of them drawn without replacement (sorted)."""
    if n <= max_points:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=max_points, replace=False))


def write_labels_csv(path: str | os.PathLike, labels_pred, labels_true=None, samples=None) -> None:
    """``sample,predicted[,true]`` per point, atomically; ``sample`` is ``samples`` (the
    points' indices in the data file) or, without them, the row."""
    pred = np.asarray(labels_pred)
    numbers = np.arange(pred.size) if samples is None else np.asarray(samples)
    columns = [numbers, pred] + ([] if labels_true is None else [np.asarray(labels_true)])
    buf = io.StringIO()
    buf.write("sample,predicted\n" if labels_true is None else "sample,predicted,true\n")
    np.savetxt(buf, np.column_stack(columns), fmt="%d", delimiter=",")
    atomic_write_text(path, buf.getvalue())


def write_sweep_csv(path: str | os.PathLike, rows) -> None:
    """The sweep table as CSV (one row per grid value), atomically."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=SWEEP_COLUMNS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in SWEEP_COLUMNS})
    atomic_write_text(path, buf.getvalue())


def write_json(path: str | os.PathLike, obj) -> None:
    """JSON with numpy scalars and arrays converted, atomically."""
    atomic_write_json(path, to_jsonable(obj))


def to_jsonable(obj):
    """Numpy scalars/arrays to Python; NaN to None (JSON has no NaN)."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    return obj
