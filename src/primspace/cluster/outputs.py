"""The output directory of ``primspace cluster``: labels, result JSON, figures, written atomically.

Layout of ``DIR``::

    labels.csv        sample, predicted[, true]   (sample: the data file's index; true: -1 = unknown)
    result.json       input, options, tau / tau_relative / R^2 / rank, singular values,
                      eigenvalues, spectral method, scores (or null), seconds
    clustering.png    the paper-style figure (affinity ordered by true label; predicted
                      label per sample); at most FIGURE_MAX_POINTS samples, drawn at random
    sweep.csv, sweep.json, sweep.png    with --sweep: tau, R^2, rank and scores per grid value

The folder is published whole by :func:`primspace.utils.folders.atomic_directory` with
:data:`CLUSTER_OUTPUT` (the rules for an existing folder are there).
"""

from __future__ import annotations

import csv
import io
import os

import numpy as np

from primspace.utils.files import atomic_write_text
from primspace.utils.folders import OutputKind

__all__ = [
    "CLUSTER_OUTPUT",
    "OUTPUT_FILES",
    "figure_indices",
    "write_labels_csv",
    "write_sweep_csv",
    "FIGURE_MAX_POINTS",
]

FIGURE_MAX_POINTS = 2000
#: Every file ``primspace cluster`` writes into its output directory.
OUTPUT_FILES = ("labels.csv", "result.json", "clustering.png", "sweep.csv", "sweep.json", "sweep.png")


#: ``primspace cluster``'s output directory.
CLUSTER_OUTPUT = OutputKind("primspace cluster", OUTPUT_FILES, frozenset({"n_clusters", "tau_option", "rank"}))

SWEEP_COLUMNS = ("grid", "value", "tau", "tau_relative", "r2", "rank", "accuracy", "nmi", "ari", "note")


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
