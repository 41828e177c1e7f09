"""Safe output: atomic writes, and outputs that never touch a command's inputs.

A command interrupted half-way, or one that fails validation, leaves no partial
output behind: it writes to a temporary file beside the target and renames it into
place; on failure the temporary file is removed and the target is untouched. A
temporary file left by a process that was killed (SIGKILL leaves no chance to clean
up) is removed by the next write of the same target on the same machine: its name
carries the writer's host and process id (``.NAME.<host>-<pid>.<random>.tmp``).

Every output is created with the permissions the user's umask allows (as ``open``
would), not ``mkstemp``'s private 0600.

:func:`check_outside_inputs` refuses an output that is, contains or lies inside one of
the command's inputs, so no flag combination can make a command overwrite or delete
what it reads.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import tempfile
from pathlib import Path
from typing import Any, Iterable, Iterator

from primspace.errors import OutputExistsError, UserError

__all__ = [
    "check_output",
    "output_file",
    "check_outside_inputs",
    "atomic_path",
    "atomic_write_text",
    "atomic_write_json",
    "temp_prefix",
    "remove_stale_temporaries",
    "umask_mode",
    "exclusive_lock",
    "os_error",
]


def check_output(path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Refuse an existing output unless ``overwrite``, and a directory where a file is
    to be written; return the path.

    Raises
    ------
    OutputExistsError
        If ``path`` exists and ``overwrite`` is false.
    UserError
        If ``path`` is an existing directory.
    """
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{path}: is a directory; --out must name a file")
    if path.exists() and not overwrite:
        raise OutputExistsError(path)
    return path


def output_file(
    text: str | os.PathLike, *, inputs: Iterable = (), overwrite: bool = False, option: str = "--out"
) -> Path:
    """The checked path of a command's file output, as the user typed it.

    Refused, each in one line: an empty name; ``dir/`` (a trailing separator names a
    directory, so no file called ``dir`` is written) or an existing directory; a path that
    is, contains or lies inside one of ``inputs`` (:func:`check_outside_inputs`); an
    existing file unless ``overwrite`` (:func:`check_output`).
    """
    raw = os.fspath(text)
    if not raw.strip():
        raise UserError(f"{option} is empty")
    if raw.endswith(("/", os.sep)) or Path(raw).is_dir():
        raise UserError(f"{raw}: is a directory; {option} must name a file")
    path = Path(raw)
    check_outside_inputs(path, inputs, option)
    return check_output(path, overwrite)


def _within(inner: Path, outer: Path) -> bool:
    return inner == outer or outer in inner.parents


def check_outside_inputs(out: str | os.PathLike, inputs: Iterable, option: str = "--out") -> None:
    """Refuse an output that is, contains, or lies inside one of ``inputs``.

    Paths are compared resolved (symlinks followed, ``..`` collapsed), so a symlink
    named as output that points at an input is refused too. ``None`` inputs are skipped.

    Raises
    ------
    UserError
        Naming the output and the input it would overwrite or delete.
    """
    target = Path(os.path.realpath(out))
    for given in inputs:
        if given is None:
            continue
        source = Path(os.path.realpath(given))
        if target == source:
            raise UserError(f"{out}: {option} is the input {given}; choose another {option}")
        if _within(source, target):
            raise UserError(f"{out}: {option} contains the input {given}; choose another {option}")
        if _within(target, source):
            raise UserError(f"{out}: {option} lies inside the input {given}; choose another {option}")


def umask_mode(base: int = 0o666) -> int:
    """``base`` with the process umask applied: the mode ``open`` would create."""
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


def temp_prefix(name: str) -> str:
    """``.NAME.<host>-<pid>.``: the prefix of this process's temporaries for ``NAME``."""
    host = socket.gethostname().replace(".", "_").replace("-", "_") or "host"
    return f".{name}.{host}-{os.getpid()}."


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(path: str | os.PathLike) -> list[Path]:
    """Remove temporaries of ``path`` left by killed processes on this machine.

    Only names of the form ``.NAME.<host>-<pid>.*.tmp`` (or ``.old``) whose host is
    this one and whose process is gone are removed; a running writer's temporaries and
    another machine's are left alone. Returns the paths removed.
    """
    path = Path(path)
    if not path.parent.is_dir():
        return []
    host = socket.gethostname().replace(".", "_").replace("-", "_") or "host"
    removed = []
    head = f".{path.name}."
    for entry in path.parent.iterdir():
        name = entry.name
        if not name.startswith(head) or not name.endswith((".tmp", ".old")):
            continue
        owner = name[len(head):].split(".", 1)[0]
        who, _, pid = owner.rpartition("-")
        if who != host or not pid.isdigit() or _pid_alive(int(pid)):
            continue
        with contextlib.suppress(OSError):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
            removed.append(entry)
    return removed


def os_error(exc: OSError, path: str | os.PathLike) -> UserError:
    """A one-line :class:`UserError` for a file-system failure on ``path``."""
    where = exc.filename if getattr(exc, "filename", None) else os.fspath(path)
    return UserError(f"{where}: cannot write ({exc.strerror or type(exc).__name__})")


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
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(path)
        fd, tmp_name = tempfile.mkstemp(prefix=temp_prefix(path.name), suffix=".tmp", dir=path.parent)
        os.fchmod(fd, umask_mode())
        os.close(fd)
    except OSError as exc:
        raise os_error(exc, path) from None
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


@contextlib.contextmanager
def exclusive_lock(path: str | os.PathLike) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (created if missing) for the block: processes
    sharing one piece of work (two grid points resuming the same fit) take turns. POSIX
    ``flock``: released when the block ends or the process dies."""
    import fcntl

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
