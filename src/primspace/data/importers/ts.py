"""Import UEA/UCR time-series files (``.ts``, the format sktime and aeon bundle their data sets in).

A ``.ts`` file holds comment lines (``#``), a header of ``@`` tags and, after ``@data``,
one series per line: each channel's values separated by commas, the channels separated by
``:``, then the series' class label when the header says ``@classLabel true NAME ...``
(or its numeric target with ``@targetLabel true``)::

    @problemName BasicMotions
    @univariate false
    @dimensions 6
    @classLabel true Standing Running Walking Badminton
    @data
    0.07,0.3,...:-0.2,0.1,...: ... :Standing

What becomes of it: each series is one demonstration, its channels the joints
(``channel_0``, ``channel_1``, ...; a univariate file has one), resampled to ``length``
steps (:func:`primspace.data.resample`; series of different lengths are allowed); values
stay as recorded, scaled to [-1, 1] at training time like every importer's. The class
labels become the data set's labels, named in the order ``@classLabel`` lists them; a
regression file's target is kept as the parameter ``target``. Several files (a problem's
``_TRAIN.ts`` and ``_TEST.ts``) are read in the order given and concatenated; a folder
stands for its ``*.ts`` files in name order. They must agree in channels, in labelling and
in the classes they declare. ``dt`` is 1 per recorded step (the format has no clock).
Each sample's ``source_ids`` entry is ``ts:<file name>:<i>`` (its place in that file).

Refused, naming the file and line: time-stamped series (``@timeStamps true``), missing
values (``?``, ``NaN``), a value that is not a finite number, a line with another number
of channels than the header declares, channels of different lengths within one series, a
label ``@classLabel`` does not list, a file without ``@data`` or without series.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import printable, resample_located, resampled_dt
from primspace.utils.errors import DataError, first_line

__all__ = ["TsFile", "read_ts", "ts_files", "import_ts"]

_TRUE, _FALSE = "true", "false"


class TsFile(NamedTuple):
    """One ``.ts`` file as read (:func:`read_ts`)."""

    series: list[np.ndarray]  # one (T_i, channels) float64 array per series
    labels: list[str] | None  # each series' class label, as written; None without @classLabel true
    class_names: list[str] | None  # the classes @classLabel declares, in its order
    targets: list[float] | None  # each series' target with @targetLabel true, else None
    problem: str | None  # @problemName


def read_ts(path: str | os.PathLike) -> TsFile:
    """Read one ``.ts`` file (module docstring).

    Raises
    ------
    DataError
        Naming the file and the line (and what is wrong there).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot be read as a .ts text file ({first_line(exc)})", path=path) from None
    header: dict[str, tuple[int, list[str]]] = {}
    series, labels, targets = [], [], []
    reader = None
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if reader is not None:
            values, last = reader.row(line, number)
            series.append(values)
            if reader.labelled:
                labels.append(last)
            elif reader.target:
                targets.append(last)
            continue
        if not line.startswith("@"):
            raise DataError(f"line {number}: expected an @tag or @data before the series, got {_cut(line)}", path=path)
        tag, *words = line.split()
        if tag.lower() == "@data":
            reader = _Rows(path, header)
        else:
            header[tag.lower()] = (number, words)
    if reader is None:
        raise DataError("has no @data line (not a .ts file?)", path=path)
    if not series:
        raise DataError("has no series after @data", path=path)
    problem = " ".join(header.get("@problemname", (0, []))[1]) or None
    return TsFile(
        series,
        labels if reader.labelled else None,
        reader.class_names,
        [float(t) for t in targets] if reader.target else None,
        problem,
    )


class _Rows:
    """The data lines of one file, read against its header."""

    def __init__(self, path: Path, header: dict[str, tuple[int, list[str]]]) -> None:
        self.path = path
        line, words = header.get("@timestamps", (0, [_FALSE]))
        if _flag(words, path, line, "@timeStamps"):
            raise DataError(
                f"line {line}: @timeStamps true: time-stamped series are not read; give values only", path=path
            )
        line, words = header.get("@classlabel", (0, [_FALSE]))
        self.labelled = _flag(words, path, line, "@classLabel")
        self.class_names = words[1:] if self.labelled else None
        if self.labelled and not self.class_names:
            raise DataError(f"line {line}: @classLabel true names no classes", path=path)
        line, words = header.get("@targetlabel", (0, [_FALSE]))
        self.target = _flag(words, path, line, "@targetLabel") and not self.labelled
        self.channels = _declared_channels(header, path)

    def row(self, line: str, number: int) -> tuple[np.ndarray, str | None]:
        """One series ``(T, channels)`` and its label (or target) as written."""
        fields = line.split(":")
        last = None
        if self.labelled or self.target:
            last = fields.pop().strip()
            if self.labelled and last not in self.class_names:
                raise DataError(
                    f"line {number}: label {_cut(last)} is not among the classes @classLabel declares "
                    f"({', '.join(self.class_names)})",
                    path=self.path,
                    field="labels",
                )
            if self.target:
                _number(last, self.path, number, "the target")
        if self.channels is None:
            self.channels = len(fields)  # the first series says how many, when the header does not
        if len(fields) != self.channels:
            raise DataError(
                f"line {number}: {len(fields)} channel(s), the file has {self.channels}"
                + (" and a label after the last ':'" if self.labelled else ""),
                path=self.path,
                field="motor",
            )
        channels = []
        for c, field in enumerate(fields):
            values = [_number(v, self.path, number, f"channel {c} value {k}") for k, v in enumerate(field.split(","))]
            if channels and len(values) != len(channels[0]):
                raise DataError(
                    f"line {number}: channel {c} has {len(values)} values, channel 0 {len(channels[0])}",
                    path=self.path,
                    field="motor",
                )
            channels.append(values)
        return np.array(channels, dtype=np.float64).T, last


def _declared_channels(header: dict, path: Path) -> int | None:
    """The channels the header declares (``@dimensions``, or 1 with ``@univariate true``), else None."""
    for tag in ("@dimensions", "@dimension"):
        if tag in header:
            line, words = header[tag]
            if len(words) != 1 or not words[0].isdigit() or int(words[0]) < 1:
                raise DataError(
                    f"line {line}: {tag} must be a whole number of channels, got {' '.join(words)!r}", path=path
                )
            return int(words[0])
    line, words = header.get("@univariate", (0, [_FALSE]))
    return 1 if _flag(words, path, line, "@univariate") else None


def _flag(words: list[str], path: Path, line: int, tag: str) -> bool:
    value = words[0].lower() if words else ""
    if value not in (_TRUE, _FALSE):
        raise DataError(f"line {line}: {tag} must be true or false, got {' '.join(words)!r}", path=path)
    return value == _TRUE


def _number(text: str, path: Path, line: int, what: str) -> float:
    value = text.strip()
    if value == "?":
        raise DataError(f"line {line}: {what} is missing ('?'); missing values are not read", path=path, field="motor")
    try:
        number = float(value)
    except ValueError:
        raise DataError(f"line {line}: {what} {_cut(value)} is not a number", path=path, field="motor") from None
    if not math.isfinite(number):
        raise DataError(f"line {line}: {what} is {value}, not a finite number", path=path, field="motor")
    return number


def _cut(text: str, limit: int = 40) -> str:
    text = printable(text)
    return repr(text if len(text) <= limit else text[: limit - 3] + "...")


def ts_files(sources: str | os.PathLike | Sequence) -> list[Path]:
    """The ``.ts`` files of ``sources`` (a file, a folder, or several of them), in order: a
    folder's ``*.ts`` files sorted by name.

    Raises
    ------
    DataError
        A source that does not exist, or a folder without ``.ts`` files.
    """
    items = [sources] if isinstance(sources, (str, os.PathLike)) else list(sources)
    files: list[Path] = []
    for item in map(Path, items):
        if item.is_dir():
            found = sorted(p for p in item.glob("*.ts") if p.is_file())
            if not found:
                raise DataError("holds no .ts files", path=item)
            files += found
        elif item.is_file():
            files.append(item)
        else:
            raise DataError("no such file or folder", path=item)
    if not files:
        raise DataError("no .ts files given")
    return files


def import_ts(sources: str | os.PathLike | Sequence, length: int) -> MotionDataset:
    """Read ``.ts`` files (a file, a folder, or several) into one data set (module docstring).

    Parameters
    ----------
    sources : path-like or sequence of path-likes
        Files in the order to concatenate them (e.g. ``X_TRAIN.ts``, ``X_TEST.ts``), or folders.
    length : int
        T, the steps to resample each series to.

    Raises
    ------
    DataError
        Naming the file, and the line where it is in one.
    """
    files = ts_files(sources)
    read = [read_ts(f) for f in files]
    first, first_file = read[0], files[0]
    for file, part in zip(files[1:], read[1:]):
        _check_agrees(file, part, first_file, first)
    sequences = [s for part in read for s in part.series]
    ids = [f"ts:{printable(f.name)}:{i}" for f, part in zip(files, read) for i in range(len(part.series))]
    where = files[0] if len(files) == 1 else files[0].parent
    labels = None
    if first.class_names is not None:
        labels = np.array([first.class_names.index(lab) for part in read for lab in part.labels], dtype=np.int32)
    targets = None if first.targets is None else np.array([t for part in read for t in part.targets])[:, None]
    try:
        motor = resample_located(sequences, length)
    except DataError as exc:
        at = exc.index if exc.index is not None else 0
        raise exc.located(path=files[_file_of(read, at)]) from None
    try:
        return MotionDataset(
            motor=motor,
            labels=labels,
            label_names=first.class_names,
            joint_names=[f"channel_{c}" for c in range(motor.shape[2])],
            params=targets,
            param_names=None if targets is None else ["target"],
            dt=resampled_dt(1.0, [len(s) for s in sequences], length),
            source="ts:" + "+".join(printable(f.name) for f in files),
            source_ids=ids,
        )
    except DataError as exc:
        raise exc.located(path=where) from None


def _file_of(read: list[TsFile], index: int) -> int:
    """The file that holds concatenated series ``index``."""
    for k, part in enumerate(read):
        if index < len(part.series):
            return k
        index -= len(part.series)
    return len(read) - 1


def _check_agrees(file: Path, part: TsFile, first_file: Path, first: TsFile) -> None:
    """Files read together must have the same channels, labelling and classes."""
    channels, first_channels = part.series[0].shape[1], first.series[0].shape[1]
    if channels != first_channels:
        raise DataError(f"has {channels} channel(s), {first_file.name} {first_channels}", path=file, field="motor")
    if (part.class_names is None) != (first.class_names is None) or (part.targets is None) != (first.targets is None):
        raise DataError(f"is labelled differently from {first_file.name} (@classLabel, @targetLabel)", path=file)
    if part.class_names is not None and sorted(part.class_names) != sorted(first.class_names):
        raise DataError(
            f"declares classes {', '.join(part.class_names)}; {first_file.name} declares "
            f"{', '.join(first.class_names)}",
            path=file,
            field="labels",
        )
