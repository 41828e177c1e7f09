"""Atomic output: write to a temporary file beside the target, then rename.

A command interrupted half-way, or one that fails validation, leaves no partial
output behind: the temporary file is removed and the target is untouched.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator

from primspace.errors import OutputExistsError

__all__ = ["check_output", "atomic_path", "atomic_write_text", "atomic_write_json"]


def check_output(path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Refuse an existing output unless ``overwrite``; return the path.

    Raises
    ------
    OutputExistsError
        If ``path`` exists and ``overwrite`` is false.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(path)
    return path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, overwrite: bool = True) -> Iterator[Path]:
    """Yield a temporary path in the target's directory; rename it over ``path`` on success.

    The temporary file (or directory, if the body creates one there) is removed if the
    body raises, so nothing half-written is left. The parent directory is created.

    Parameters
    ----------
    path : path-like
        Final location.
    overwrite : bool, default True
        If false and ``path`` exists, raise :class:`~primspace.errors.OutputExistsError`
        before anything is written.
    """
    path = check_output(path, overwrite)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (replacing it)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def atomic_write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as indented JSON to ``path`` atomically (replacing it)."""
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")
