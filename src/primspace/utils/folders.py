"""A command's output folder: what it writes, how an earlier output of it is recognised, and how
a new one is published whole.

``primspace cluster``, ``segment``, ``predict`` and ``act`` write folders. Each names its
:class:`OutputKind` (the command, the files it writes, the keys its ``result.json`` always
holds); :func:`check_output_directory` is the rule for an existing folder and
:func:`atomic_directory` builds the output beside it and publishes it
(:func:`primspace.utils.files.atomic_directory`), so a failure leaves nothing half-written.
An existing empty folder is written into in place; a non-empty one is refused unless
``overwrite``, and even then unless it is an earlier output of the same command: then only
that command's files are replaced, and any other file in it is left alone.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from primspace.utils import files
from primspace.utils.errors import OutputExistsError, UserError
from primspace.utils.files import atomic_write_json
from primspace.utils.outputs import describe

__all__ = ["OutputKind", "atomic_directory", "check_output_directory", "is_output_of", "write_json", "to_jsonable"]


@dataclass(frozen=True)
class OutputKind:
    """A command's output directory: the command, the files it writes, and the keys its
    ``result.json`` always holds (how an earlier output of it is recognised)."""

    command: str
    files: tuple[str, ...]
    result_keys: frozenset


def check_output_directory(path: str | os.PathLike, overwrite: bool, kind: OutputKind) -> Path:
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


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, overwrite: bool, kind: OutputKind) -> Iterator[Path]:
    """Yield a temporary directory beside ``path``; on success its files land in ``path``.

    :func:`primspace.utils.files.atomic_directory` with this module's rules
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
