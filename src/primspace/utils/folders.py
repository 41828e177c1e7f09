"""A command's output folder: what it writes, how an earlier output of it is recognised, and how
a new one is published whole, by one process at a time.

``primspace cluster``, ``segment``, ``predict`` and ``act`` write folders. Each names its
:class:`OutputKind` (the command, the files it writes, the keys its ``result.json`` always
holds); :func:`check_output_directory` is the rule for an existing folder and
:func:`atomic_directory` builds the output beside it and publishes it, so a failure leaves
nothing half-written. An existing empty folder is written into in place; a non-empty one is
refused unless ``overwrite``, and even then unless it is an earlier output of the same
command: then only that command's files are replaced, and any other file in it is left alone.

The writer holds the folder's lock (:class:`FolderLock`, ``flock`` on its :data:`LOCK_NAME`
file, released by the kernel however the process ends) from its check to its end: a second
writer is refused at once with one line. Publishing into an existing folder first marks it
unfinished (:data:`INCOMPLETE_NAME`, naming the command) and removes the earlier
``result.json`` (the mark of a complete output), then moves the files in, ``result.json``
last, and removes the mark: a publication cut short (a kill) never leaves a folder that
looks complete with files of two outputs, and an unfinished output of the same command is
written again, with or without ``overwrite``.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from primspace.utils import files
from primspace.utils.errors import OutputExistsError, UserError
from primspace.utils.files import atomic_write_json
from primspace.utils.outputs import describe

__all__ = [
    "lock_exclusively",
    "OutputKind",
    "FolderLock",
    "LOCK_NAME",
    "INCOMPLETE_NAME",
    "atomic_directory",
    "check_output_directory",
    "is_output_of",
    "write_json",
    "to_jsonable",
]

#: The file a folder's writer holds locked (as a run directory's writer does), removed when it ends.
LOCK_NAME = ".writer.lock"
#: Written into a folder before an output's first file lands there, removed after its result.json:
#: it names the command whose publication a kill cut short.
INCOMPLETE_NAME = ".incomplete"
_BOOKKEEPING = frozenset({LOCK_NAME, INCOMPLETE_NAME})
_LAST = "result.json"


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
    command; return the path. A folder holding an unfinished output of ``kind``'s command
    (its publication cut short) is accepted with or without ``overwrite``."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise UserError(f"{path}: exists and is not a directory")
        if _entries(path) and not _unfinished(path, kind):
            if not overwrite:
                raise OutputExistsError(path)
            if not is_output_of(path, kind):
                raise UserError(
                    f"{path}: exists and is not a {kind.command} output ({_result_of(path)}); "
                    f"--overwrite only replaces an earlier {kind.command} output: choose another --out"
                )
    return path


def _entries(path: Path) -> list[Path]:
    """What ``path`` holds, its writer's bookkeeping (lock, unfinished mark and its temporary) aside."""
    mark_temporary = f".{INCOMPLETE_NAME}."
    return [p for p in path.iterdir() if p.name not in _BOOKKEEPING and not p.name.startswith(mark_temporary)]


def _incomplete_mark(path: Path) -> str | None:
    """The command named by ``path``'s unfinished mark, or None."""
    try:
        return (Path(path) / INCOMPLETE_NAME).read_text(encoding="utf-8").strip() or None
    except (OSError, UnicodeDecodeError):
        return None


def _unfinished(path: Path, kind: OutputKind) -> bool:
    """Whether ``path`` holds an output of ``kind``'s command whose publication was cut short."""
    return _incomplete_mark(path) == kind.command and not is_output_of(path, kind)


def _result_of(path: Path) -> str:
    """What ``path``'s result.json is, for a refusal: none, or the mark of the command that wrote it."""
    result = Path(path) / "result.json"
    if result.is_file():
        return f"its result.json is {describe(result)}"
    mark = _incomplete_mark(path)
    return f"it holds an unfinished {mark} output" if mark else "it holds no result.json"


def is_output_of(path: Path, kind: OutputKind) -> bool:
    """Whether ``path`` holds a ``result.json`` written by ``kind``'s command."""
    try:
        result = json.loads((Path(path) / "result.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return False
    return isinstance(result, dict) and kind.result_keys <= set(result)


def _same_file(handle, path: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(handle.fileno()), os.stat(path))
    except OSError:
        return False


def lock_exclusively(handle, path: Path, what: str, hint: str) -> None:
    """``flock`` the open lock file ``handle`` exclusively without waiting; when another process
    holds it, close ``handle`` and raise one UserError naming ``path``, the holder's process id as the
    lock file records it, ``what`` it writes and the ``hint``. Other OSErrors pass."""
    import fcntl

    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip()
        handle.close()
        who = f" (pid {holder})" if holder.isdigit() else ""
        raise UserError(f"{path}: another primspace process{who} is writing this {what}; {hint}") from None


class FolderLock:
    """The exclusive lock of the one process writing ``folder``: ``flock`` on its
    :data:`LOCK_NAME` file, which holds the writer's process id and is removed on release."""

    def __init__(self, folder: str | os.PathLike) -> None:
        self.folder, self.handle = Path(folder), None

    def acquire(self) -> FolderLock:
        """Take the lock (a no-op when held); one UserError when another process holds it
        or the folder is not writable."""
        import errno

        for _ in range(100):
            if self.handle is not None:
                break
            try:
                handle = open(self.folder / LOCK_NAME, "a+", encoding="utf-8")
            except OSError as exc:
                raise UserError(
                    f"{self.folder}: cannot write into this folder ({exc.strerror or type(exc).__name__})"
                ) from None
            try:
                lock_exclusively(handle, self.folder, "folder", "wait for it to end or choose another --out")
            except OSError as exc:  # a file system without flock: written unlocked, as before locks
                if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
                    handle.close()
                    raise UserError(f"{self.folder}: cannot lock this folder ({exc.strerror})") from None
            if not _same_file(handle, self.folder / LOCK_NAME):  # its holder removed it as we opened it
                handle.close()
                continue
            handle.seek(0)
            handle.truncate()
            handle.write(str(os.getpid()))
            handle.flush()
            self.handle = handle
        if self.handle is None:
            raise UserError(f"{self.folder}: its lock file keeps being replaced; is another program writing here?")
        return self

    def release(self) -> None:
        """Remove the lock file and let go of the lock."""
        if self.handle is not None:
            if _same_file(self.handle, self.folder / LOCK_NAME):
                with contextlib.suppress(OSError):
                    os.unlink(self.folder / LOCK_NAME)
            self.handle.close()
            self.handle = None


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, overwrite: bool, kind: OutputKind) -> Iterator[Path]:
    """Yield a temporary directory beside ``path``, holding ``path``'s lock; on success its
    files land in ``path``.

    :func:`check_output_directory` runs first and again (locked) when publishing. A new
    ``path`` is the temporary directory renamed without replacing anything
    (:func:`primspace.utils.files.rename_noreplace`; one that another writer published
    meanwhile is refused, never written over); an existing empty one is written into in
    place, each file moved in without replacing; an earlier output of ``kind``'s command
    (``overwrite``), or an unfinished one, gets its ``result.json`` removed first, each new
    file renamed over the old one and the earlier run's other outputs (``kind.files``, e.g.
    a sweep not asked for this time) removed; any other file in it is left alone. On failure
    the temporary directory is removed and ``path`` is untouched.
    """
    path = Path(path)
    check = functools.partial(check_output_directory, overwrite=overwrite, kind=kind)
    check(path)
    existed, lock = path.is_dir(), FolderLock(path)
    try:
        if existed:
            lock.acquire()
            check(path)  # again: now no other primspace process writes it
        path.parent.mkdir(parents=True, exist_ok=True)
        files.remove_stale_temporaries(path)
        tmp = Path(tempfile.mkdtemp(prefix=files.temp_prefix(path.name), suffix=".tmp", dir=path.parent))
        os.chmod(tmp, files.umask_mode(0o777))
    except OSError as exc:
        lock.release()
        raise files.os_error(exc, path) from None
    except BaseException:
        lock.release()
        raise
    try:
        if not existed:
            lock.folder = tmp  # renamed into place with it
            lock.acquire()
        yield tmp
        _publish(tmp, path, lock, existed, check, kind)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        lock.release()


def _publish(tmp: Path, path: Path, lock: FolderLock, existed: bool, check, kind: OutputKind) -> None:
    """The publishing step of :func:`atomic_directory`: ``tmp`` renamed to a new ``path``,
    or its files moved into the existing, locked one."""
    check(path)
    if not existed:
        if not path.exists():
            try:
                files.rename_noreplace(tmp, path)
                lock.folder = path
                return
            except FileExistsError:
                pass
        lock.release()  # the folder appeared meanwhile: lock it, then refuse unless it is empty
        lock.folder = path
        lock.acquire()
        check(path)
        if _entries(path):  # what check let pass: an output of the command, with overwrite
            raise UserError(f"{path}: another process wrote this folder meanwhile; nothing was written")
    _fill(tmp, path, kind)


def _fill(tmp: Path, path: Path, kind: OutputKind) -> None:
    """Move ``tmp``'s files into the existing ``path`` under the unfinished mark, result.json last."""
    written = sorted((p.name for p in tmp.iterdir()), key=lambda n: (n == _LAST, n))
    earlier = bool(_entries(path))  # an earlier or unfinished output of the command (checked)
    files.atomic_write_text(path / INCOMPLETE_NAME, kind.command)
    if earlier:
        with contextlib.suppress(FileNotFoundError):
            (path / _LAST).unlink()  # from now on the folder does not look complete
        for name in kind.files:
            if name not in written:
                with contextlib.suppress(FileNotFoundError):
                    (path / name).unlink()
        for name in written:
            os.replace(tmp / name, path / name)
    else:
        moved = []
        try:
            for name in written:
                files.rename_noreplace(tmp / name, path / name)
                moved.append(path / name)
        except FileExistsError:  # a file of another writer landed first: take back ours, keep theirs
            for mine in moved:
                _discard(mine)
            with contextlib.suppress(FileNotFoundError):
                (path / INCOMPLETE_NAME).unlink()
            raise OutputExistsError(path) from None
    (path / INCOMPLETE_NAME).unlink()
    tmp.rmdir()


def _discard(entry: Path) -> None:
    if entry.is_dir() and not entry.is_symlink():
        shutil.rmtree(entry, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            entry.unlink()


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
