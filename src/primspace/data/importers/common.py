"""Helpers shared by the importers: checked resampling, labels, names, the resampled ``dt``."""

from __future__ import annotations

import json
import math
import os

import numpy as np

from primspace.data.resample import resample
from primspace.data.values import as_float32
from primspace.utils.errors import DataError

__all__ = [
    "resample_located",
    "parse_labels",
    "opt_names",
    "resampled_dt",
    "natural_key",
    "rate_dt",
    "shown",
    "printable",
    "check_fits_memory",
    "MIN_RATE",
    "MAX_RATE",
]

#: The rates (steps per second: LeRobot's ``fps``, robomimic's ``control_freq``) an importer
#: accepts: a step of 1 microsecond to about 11.6 days. Outside, a rate is a typo or damage.
MIN_RATE, MAX_RATE = 1e-6, 1e6


def resample_located(sequences: list, length: int) -> np.ndarray:
    """Check each sequence (numbers, rank, not empty, fits float32), then resample to ``length``.

    Raises
    ------
    DataError
        Naming field ``motor`` and the sample index (the caller adds the file).
    """
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


def parse_labels(labels, label_names, n: int):
    """``labels`` (ints, -1 unknown, or strings) and their names, for ``n`` sequences.

    Returns
    -------
    (labels or None, label names or None)
        String labels become indices into ``label_names`` (default: the sorted strings).
    """
    if labels is None:
        return None, opt_names(label_names)
    labels = np.asarray(labels).reshape(-1) if np.ndim(labels) else np.asarray(labels)
    if labels.ndim != 1 or labels.shape[0] != n:
        raise DataError(f"{labels.size} labels for {n} sequences", field="labels")
    if labels.dtype.kind in "US":
        names = opt_names(label_names) or sorted(set(labels.astype(str)))
        ids = []
        for i, lab in enumerate(labels.astype(str)):
            if lab not in names:
                raise DataError(f"label {lab!r} is not among label_names", field="labels", index=i)
            ids.append(names.index(lab))
        return np.array(ids, dtype=np.int32), names
    if labels.dtype.kind not in "iu":
        raise DataError(f"must be integers or strings, got {labels.dtype}", field="labels")
    return labels, opt_names(label_names)  # MotionDataset checks the range, then casts to int32


def opt_names(names) -> list[str] | None:
    """Names as a list of str (None stays None)."""
    if names is None:
        return None
    return [str(s) for s in np.asarray(names).reshape(-1)]


def resampled_dt(dt_in: float, lengths: list[int], length: int) -> float:
    """Seconds per output step, keeping each demonstration's duration on average."""
    if not np.isfinite(dt_in) or dt_in <= 0:
        raise DataError(f"must be a positive number, got {dt_in}", field="dt")
    return float(dt_in * np.mean([max(t - 1, 1) for t in lengths]) / (length - 1))


def printable(name) -> str:
    """A name read from a file (a key, a feature, a column) as one line of text: control
    characters such as a newline escaped (``a\\nb``), so an error message stays one line."""
    name = name if isinstance(name, str) else str(name)
    return name if name.isprintable() else name.encode("unicode_escape").decode("ascii")


def shown(value, limit: int = 60) -> str:
    """``value`` as it is written in a JSON file (``"fast"``, ``NaN``, ``true``), for messages
    (cut at ``limit`` characters)."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):  # not JSON, or an int too long to print
        text = f"<a {type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def rate_dt(rate, *, path, field: str, where: str = "") -> float:
    """Seconds per step, ``1 / rate``, of a rate read from a file (``fps``, ``control_freq``).

    Parameters
    ----------
    rate : object
        The value as read (from JSON): a number of steps per second.
    path : path-like
        The file it was read from.
    field : str
        Its name, e.g. ``fps``.
    where : str, optional
        Where in the file, for the message (e.g. ``in data's env_args attribute``).

    Raises
    ------
    DataError
        Naming the file, the field and the value: not a number, not finite, not positive,
        or outside ``[MIN_RATE, MAX_RATE]`` (a ``dt`` of ``1 / rate`` seconds that no
        recording has, e.g. ``inf`` for ``1e-320``).
    """
    place = f" {where}" if where else ""
    if isinstance(rate, bool) or not isinstance(rate, (int, float)):
        raise DataError(f"{field} {shown(rate)}{place} must be a number of steps per second", path=path, field=field)
    if isinstance(rate, float) and not math.isfinite(rate) or rate <= 0:
        raise DataError(
            f"{field} {shown(rate)}{place} must be a positive finite number of steps per second", path=path, field=field
        )
    if not MIN_RATE <= rate <= MAX_RATE:
        dt = 1.0 / rate if isinstance(rate, float) or rate < 10**300 else 0.0
        raise DataError(
            f"{field} {shown(rate)}{place} gives dt = 1/{field} = {dt:g} s; a rate must lie between "
            f"{MIN_RATE:g} and {MAX_RATE:g} steps per second",
            path=path,
            field=field,
        )
    return 1.0 / float(rate)


def memory_bytes() -> int | None:
    """This machine's physical memory in bytes (None where the system does not say)."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def check_fits_memory(nbytes: int, what: str, **located) -> None:
    """Refuse to read ``nbytes`` (``what``: the array, its shape) when that is more than half
    this machine's memory: a small damaged or crafted file can declare an array of terabytes
    (HDF5 stores no chunk that was never written), and reading it would end in a memory error.

    Raises
    ------
    DataError
        Located by ``located`` (``path``, ``field``, ``index``).
    """
    total = memory_bytes()
    if total is not None and nbytes > total // 2:
        raise DataError(
            f"{what} is {nbytes / 2**30:.3g} GiB, more than half this machine's memory "
            f"({total / 2**30:.3g} GiB); it cannot be read",
            **located,
        )


def natural_key(name: str, prefix: str) -> int:
    """The number of ``prefix_<n>`` (``demo_10`` -> 10), for natural numeric order."""
    return int(name[len(prefix) + 1 :])


def demonstrations(
    sequences: list, length: int, frames, *, source: str, images: str | None, dt_in: float, where, **fields
):
    """The :class:`~primspace.data.MotionDataset` of imported demonstrations: joints resampled to
    ``length`` steps, frames (an :class:`~primspace.data.importers.frames.AlignedFrames` or None)
    stacked, the source text naming the image key and the frames' sizes; a :class:`DataError`
    is located at ``where`` (the file or directory read). ``fields``: labels, names ..."""
    from primspace.data.dataset import MotionDataset

    try:
        motor = resample_located(sequences, length)
        if frames is not None:
            source += f" images={images}; {frames.collect().describe()}"
        return MotionDataset(
            motor=motor,
            images=None if frames is None else frames.stack(),
            dt=resampled_dt(dt_in, [len(seq) for seq in sequences], length),
            source=source,
            **fields,
        )
    except DataError as exc:
        raise exc.located(path=where) from None
