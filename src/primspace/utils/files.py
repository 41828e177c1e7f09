"""Safe output: atomic writes, and outputs that never touch a command's inputs.

A command interrupted half-way, or one that fails validation, leaves no partial
output behind: it writes to a temporary file beside the target and renames it into
place; on failure the temporary file is removed and the target is untouched. A
temporary file left by a process that was killed (SIGKILL leaves no chance to clean
up) is removed by the next write of the same target on the same machine: its name
carries the writer's host and process id (``.NAME.<host>-<pid>.<random>.tmp``).

A write that must not replace anything (no ``--overwrite``) publishes without replacing:
the finished temporary is renamed onto the target with ``renameat2(RENAME_NOREPLACE)``
(or, where that is missing, hard-linked to it, ``link`` failing when the target exists;
or renamed over a placeholder created exclusively), so a target that appeared meanwhile
(another writer finishing first) is never replaced: the write fails with
:class:`~primspace.utils.errors.OutputExistsError` instead. Output folders are published alike
(:func:`primspace.utils.folders.atomic_directory`).

Every output is created with the permissions the user's umask allows (as ``open``
would), not ``mkstemp``'s private 0600.

:func:`check_outside_inputs` refuses an output that is, contains or lies inside one of
the command's inputs, so no flag combination can make a command overwrite or delete
what it reads.

This module knows files only, not what is in them: it sits below the data layer, which
writes through it. Which command wrote a file, and the check of a command's file output
that reads it (:func:`primspace.utils.outputs.output_file`), are :mod:`primspace.utils.outputs`'s.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import json
import os
import shutil
import socket
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from primspace.utils.errors import OutputExistsError, UserError

__all__ = [
    "check_output",
    "check_outside_inputs",
    "atomic_path",
    "rename_noreplace",
    "check_writable_directory",
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
        owner = name[len(head) :].split(".", 1)[0]
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
    if Path(os.fspath(where)).name.startswith(temp_prefix(Path(path).name)):
        where = os.fspath(path)  # our temporary is no name the user knows: the output it stands for is
    return UserError(f"{where}: cannot write ({exc.strerror or type(exc).__name__})")


_AT_FDCWD, _RENAME_NOREPLACE = -100, 1
# errors that say "this kernel or file system cannot rename without replacing": fall back
_NOREPLACE_UNSUPPORTED = {errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP, errno.ENOTSUP}


@functools.lru_cache(maxsize=1)
def _renameat2():
    """libc's ``renameat2`` (Linux, glibc >= 2.28), or None."""
    try:
        import ctypes

        function = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError, ImportError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    function.restype = ctypes.c_int
    return function


def rename_noreplace(src: str | os.PathLike, dst: str | os.PathLike) -> None:
    """Rename ``src`` to ``dst`` unless ``dst`` exists; never replace it.

    ``renameat2(RENAME_NOREPLACE)`` where the kernel and file system have it. Otherwise a
    file is hard-linked to ``dst`` (``link`` fails if ``dst`` exists) and ``src``
    unlinked, or, where hard links are not allowed, renamed over a placeholder created
    exclusively (``O_EXCL``); a directory is renamed into a folder made by ``mkdir``
    (which fails if ``dst`` exists), its entries moved one by one.

    Raises
    ------
    FileExistsError
        If ``dst`` exists; ``src`` is left as it was.
    """
    function = _renameat2()
    if function is not None:
        import ctypes

        if function(_AT_FDCWD, os.fsencode(src), _AT_FDCWD, os.fsencode(dst), _RENAME_NOREPLACE) == 0:
            return
        code = ctypes.get_errno()
        if code not in _NOREPLACE_UNSUPPORTED:
            raise OSError(code, os.strerror(code), os.fspath(dst))
    if os.path.isdir(src) and not os.path.islink(src):
        os.mkdir(dst)
        _move_entries(Path(src), Path(dst), last="result.json")  # an output folder's completion mark last
        os.rmdir(src)
        return
    try:
        os.link(src, dst, follow_symlinks=False)
    except FileExistsError:
        raise
    except OSError:  # no hard links here (some network and FAT file systems): claim the name first
        os.close(os.open(dst, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.replace(src, dst)
        return
    os.unlink(src)


def _move_entries(src: Path, dst: Path, last: str | None = None) -> None:
    """Move every entry of ``src`` into ``dst``, none replacing anything (``last`` last)."""
    for name in sorted((p.name for p in src.iterdir()), key=lambda n: (n == last, n)):
        rename_noreplace(src / name, dst / name)


def check_writable_directory(path: str | os.PathLike) -> None:
    """Refuse an existing folder this process cannot create files in, in one line.

    Tried, not asked (``os.access`` answers yes to root whatever the mode, and no to
    some writable network folders): a temporary file is created and removed.
    """
    try:
        fd, name = tempfile.mkstemp(prefix=temp_prefix("probe"), suffix=".tmp", dir=path)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        raise UserError(f"{path}: cannot write into this folder ({exc.strerror or type(exc).__name__})") from None


def _discard(tmp: Path) -> None:
    if tmp.is_dir() and not tmp.is_symlink():
        shutil.rmtree(tmp, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, overwrite: bool = True) -> Iterator[Path]:
    """Yield a temporary path in the target's directory; publish it as ``path`` on success.

    The temporary file (or directory, if the body creates one there) is removed if the
    body raises, so nothing half-written is left. The parent directory is created.

    Parameters
    ----------
    path : path-like
        Final location.
    overwrite : bool, default True
        True: the temporary is renamed over ``path`` (``os.replace``). False: refused
        with :class:`~primspace.utils.errors.OutputExistsError` if ``path`` exists before
        anything is written, and published without replacing
        (:func:`rename_noreplace`): if ``path`` appeared meanwhile (another writer
        finished first), the same error, the temporary removed and ``path`` untouched.
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
        if overwrite:
            os.replace(tmp, path)
        else:
            try:
                rename_noreplace(tmp, path)
            except FileExistsError:
                raise OutputExistsError(path) from None
    except BaseException as exc:
        full = disk_full(path.parent) if isinstance(exc, Exception) and not isinstance(exc, UserError) else None
        _discard(tmp)
        if full is not None:  # torch says it as 'unexpected pos', h5py in pages of its own
            raise UserError(f"{path}: cannot write: {full}; nothing was written") from None
        raise


#: A disk with less free space than this after a failed write is taken to be why it failed.
FULL_MARGIN = 1 << 20


def check_free_space(path: str | os.PathLike, need: int) -> None:
    """One UserError before writing ``path`` when its disk has fewer than ``need`` bytes free
    (an HDF5 writer that runs out of space mid-file fills stderr and may crash the process)."""
    directory = Path(path).parent
    try:
        free = shutil.disk_usage(directory if directory.exists() else Path.cwd()).free
    except OSError:
        return
    if free < need:
        raise UserError(
            f"{path}: cannot write: it needs up to {need} bytes and the disk of {directory} has {free} free"
        )


def disk_full(directory: str | os.PathLike) -> str | None:
    """``"no space left on DIR (N bytes free)"`` when the file system holding ``directory``
    has less than :data:`FULL_MARGIN` bytes free, else None (or when it cannot be asked)."""
    try:
        free = shutil.disk_usage(directory).free
    except OSError:
        return None
    return f"no space left on the disk of {os.fspath(directory)} ({free} bytes free)" if free < FULL_MARGIN else None


def atomic_write_text(path: str | os.PathLike, text: str, overwrite: bool = True) -> None:
    """Write ``text`` to ``path`` atomically (replacing it unless ``overwrite`` is false:
    see :func:`atomic_path`)."""
    with atomic_path(path, overwrite) as tmp:
        tmp.write_text(text, encoding="utf-8")


def atomic_write_json(path: str | os.PathLike, obj: Any, overwrite: bool = True) -> None:
    """Write ``obj`` as indented JSON to ``path`` atomically (as :func:`atomic_write_text`)."""
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n", overwrite)


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
