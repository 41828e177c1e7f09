"""Import a folder of CSV files, one demonstration each.

A file's header row holds the joint names. A file in a subfolder gets the subfolder's
name as its label; files directly in the folder are unlabelled. A column named ``t`` or
``time`` is the time stamp (used for ``dt``, not a joint); its values must be finite and
strictly increasing, and a file may have only one such column. Joint values must fit in
float32, the type they are stored in: a larger finite value is refused before the cast,
naming the file, line and column.

Durations
---------
Each file is resampled to ``length`` steps whatever its duration: time is normalised per
demonstration, as the paper resamples its motion-capture sequences and as every importer
does, so that a primitive demonstrated slower or faster is the same shape over the same T
steps. The data set's ``dt`` is then the mean duration / (``length`` - 1). When the files'
durations differ (by their time columns), nothing is lost silently: each file's duration
in seconds is kept as the parameter ``duration`` (``params``, ``param_names``), and the
``source`` text says the range (``csv:demos; durations 1.2-2.5 s, each resampled to 61
steps, dt = their mean / 60``). Refusing them instead would refuse nearly every set of
human demonstrations; putting them on one clock would need padding (valid lengths), which
the data set keeps only for demonstrations of several primitives.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import resample_located
from primspace.data.values import FLOAT32_MAX, too_large
from primspace.utils.errors import DataError, first_line

__all__ = ["import_csv_folder"]

_TIME_COLUMNS = {"t", "time"}


def import_csv_folder(path: str | os.PathLike, length: int) -> MotionDataset:
    """Read a folder of CSV files, one demonstration each (see module docstring)."""
    root = Path(path)
    if not root.is_dir():
        raise DataError("not a folder of CSV files", path=root)
    files = sorted(p for p in root.rglob("*.csv") if p.is_file())
    if not files:
        raise DataError("holds no .csv files", path=root)
    header: list[str] | None = None
    header_file: Path | None = None
    sequences, durations, label_of = [], [], []
    for i, file in enumerate(files):
        columns, rows = _read_csv(file, i)
        if header is None:
            header, header_file = columns, file
        elif columns != header:
            raise DataError(
                f"header {columns} differs from {header} in {header_file}", path=file, field="header", index=i
            )
        rel = file.relative_to(root)
        label_of.append(rel.parts[0] if len(rel.parts) > 1 else None)
        time_cols = [k for k, c in enumerate(columns) if c.strip().lower() in _TIME_COLUMNS]
        joint_cols = [k for k in range(len(columns)) if k not in time_cols]
        if not joint_cols:
            raise DataError("has no joint columns", path=file, field="header", index=i)
        if time_cols and len(rows) > 1:
            t = rows[:, time_cols[0]]
            durations.append(float(t[-1] - t[0]))
        sequences.append(rows[:, joint_cols])
    joint_names = [c for c in header if c.strip().lower() not in _TIME_COLUMNS]
    names = sorted({lab for lab in label_of if lab is not None})
    labels = np.array([names.index(lab) if lab is not None else -1 for lab in label_of], dtype=np.int32)
    try:
        motor = resample_located(sequences, length)
    except DataError as exc:
        bad = files[exc.index] if exc.index is not None else root
        raise exc.located(path=bad) from None
    dt = float(np.mean(durations)) / (length - 1) if durations and np.mean(durations) > 0 else 1.0
    params, note = _durations(durations, len(files), length)
    try:
        return MotionDataset(
            motor=motor,
            labels=labels if names or (labels == -1).any() else None,
            label_names=names,
            joint_names=joint_names,
            dt=dt,
            params=params,
            param_names=None if params is None else ["duration"],
            source=f"csv:{root.name}{note}",
            source_ids=[f"csv:{root.name}/{file.relative_to(root).as_posix()}" for file in files],
        )
    except DataError as exc:
        raise exc.located(path=root) from None


def _durations(durations: list[float], n: int, length: int) -> tuple[np.ndarray | None, str]:
    """Each file's duration as the parameter ``duration`` (N, 1), and the note for ``source``,
    when the files have time columns and their durations differ (module docstring); else (None, '')."""
    if len(durations) != n or max(durations) - min(durations) <= 1e-9 * max(durations):
        return None, ""
    note = (
        f"; durations {min(durations):.4g}-{max(durations):.4g} s, each resampled to {length} steps, "
        f"dt = their mean / {length - 1}"
    )
    return np.asarray(durations, dtype=np.float64)[:, None], note


def _read_csv(file: Path, index: int) -> tuple[list[str], np.ndarray]:
    """Header and values of one CSV file; every problem names the file, line and column."""

    def fail(message: str, field: str = "motor") -> DataError:
        return DataError(message, path=file, field=field, index=index)

    try:
        text = file.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot be read ({first_line(exc)})", path=file, index=index) from None
    reader = csv.reader(io.StringIO(text))
    rows, lines = [], []  # lines: the file's line number of each kept row (blank lines skipped)
    try:
        for r in reader:
            if r and any(cell.strip() for cell in r):
                rows.append(r)
                lines.append(reader.line_num)
    except csv.Error as exc:
        raise fail(f"is not valid CSV (line {reader.line_num}: {first_line(exc)})") from None
    if not rows:
        raise fail("is empty (no header, no rows)")
    header = [c.strip() for c in rows[0]]
    for c, name in enumerate(header):
        if name in header[:c]:
            raise fail(f"column {name!r} appears twice in the header", field="header")
    time_cols = [c for c, name in enumerate(header) if name.lower() in _TIME_COLUMNS]
    if len(time_cols) > 1:
        raise fail(
            f"has {len(time_cols)} time columns ({', '.join(header[c] for c in time_cols)}); keep one", field="header"
        )
    body, lines = rows[1:], lines[1:]
    if not body:
        raise fail("has a header but no rows (a zero-length sequence)")
    values = np.empty((len(body), len(header)))
    for k, (line, row) in enumerate(zip(lines, body)):
        if len(row) != len(header):
            raise fail(f"line {line} has {len(row)} values, the header has {len(header)}")
        for c, cell in enumerate(row):
            is_time = c in time_cols
            field = header[c] if is_time else "motor"
            try:
                v = float(cell)
            except ValueError:
                raise fail(f"line {line}, column {header[c]!r}: {cell.strip()!r} is not a number", field) from None
            if math.isinf(v) and "inf" not in cell.lower():  # e.g. '1e400': a finite number, too large
                limit = "float64" if is_time else "float32"
                raise fail(f"line {line}, column {header[c]!r}: value {cell.strip()} exceeds the {limit} range", field)
            if not is_time and math.isfinite(v) and abs(v) > FLOAT32_MAX:
                raise fail(f"line {line}, column {header[c]!r}: {too_large(v)}", field)
            values[k, c] = v
    if time_cols:
        _check_clock(values[:, time_cols[0]], [row[time_cols[0]] for row in body], lines, header[time_cols[0]], fail)
    return header, values


def _check_clock(t: np.ndarray, cells: list[str], lines: list[int], name: str, fail) -> None:
    """Time stamps ``t`` (read from ``cells`` on ``lines``) must be finite and strictly increase."""
    not_finite = np.flatnonzero(~np.isfinite(t))
    if not_finite.size:
        k = int(not_finite[0])
        raise fail(f"line {lines[k]}: time stamp {cells[k].strip()!r} is not a finite number", name)
    backwards = np.flatnonzero(np.diff(t) <= 0)
    if backwards.size:
        k = int(backwards[0]) + 1
        raise fail(
            f"line {lines[k]}: time {t[k]:g} does not come after {t[k - 1]:g} on line {lines[k - 1]} "
            "(time stamps must strictly increase)",
            name,
        )
