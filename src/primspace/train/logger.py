"""A standard logger beside ``metrics.jsonl``: each epoch's metrics as TensorBoard event files.

``fit(..., log_to=("tensorboard", DIR))``, ``infer(..., log_to=...)``, ``AutoDecoder(log_to=...)``
and ``primspace train | infer --log-to tensorboard DIR`` write the line that goes into
``metrics.jsonl`` (the one :class:`~primspace.train.loop.Session` logs, in memory too) through
TensorBoard's maintained writer (:class:`torch.utils.tensorboard.SummaryWriter`): every numeric
value as a scalar at ``global_step=epoch``, tagged by its key (``loss``, ``motor``, ``vision``,
``seconds``, ``samples_per_s``; a nested dict as ``outer/inner``); ``epoch`` itself is the step,
and values that are not numbers (``vision`` without images: null) are skipped. The event files
are flushed before every checkpoint, so they hold at least every epoch a resume keeps.

TensorBoard shows each folder of event files as one run: give each run its own ``DIR`` (e.g.
``tb/fit`` and ``tb/infer`` under one ``tensorboard --logdir tb``). A session writes a new event
file that starts with TensorBoard's restart marker (``purge_step``) at the first epoch it logs:
a resume from the checkpoint of epoch e marks e + 1, so the epochs a killed run logged after its
last checkpoint (and logs again when resumed) are shown once; a new run (or an overwrite) marks
0 and supersedes what the folder showed. TensorBoard reads a folder's event files in name order,
and names start with the second of their creation: a writer never starts in the same second as
the newest file already there (it waits for the next one), so the marker always comes after them.
"""

from __future__ import annotations

import numbers
import os
import time
from pathlib import Path

from primspace.utils.errors import UserError
from primspace.utils.files import check_writable_directory, os_error

__all__ = ["LOG_TARGETS", "INSTALL_HINT", "log_dir", "check_log_to", "scalars", "TensorBoardLogger", "open_logger"]

#: What ``log_to`` / ``--log-to`` can name (the first element of the pair).
LOG_TARGETS = ("tensorboard",)
INSTALL_HINT = "pip install 'primspace[tensorboard]'"
_EVENTS_PREFIX = "events.out.tfevents."


def log_dir(log_to, option: str = "log_to") -> Path | None:
    """The folder of ``log_to`` (``("tensorboard", DIR)``), or None when it is None; one
    :class:`UserError` for anything else."""
    if log_to is None:
        return None
    if isinstance(log_to, (str, bytes, os.PathLike)) or not hasattr(log_to, "__len__") or len(log_to) != 2:
        raise UserError(f"{option} must be a pair ('tensorboard', DIR), got {log_to!r}")
    target, folder = log_to
    target = getattr(target, "value", target)  # the command line's enum
    if target not in LOG_TARGETS or not isinstance(folder, (str, os.PathLike)) or not os.fspath(folder):
        raise UserError(f"{option} must be a pair ('tensorboard', DIR), got {log_to!r}")
    return Path(folder)


def check_log_to(log_to, inputs: tuple = (), option: str = "log_to") -> Path | None:
    """Refuse, before anything is trained, a ``log_to`` that cannot be written.

    Refused: a malformed pair; a missing ``tensorboard`` package; a ``DIR`` that is an
    existing file (not a folder), is one of ``inputs`` or lies inside one (an input folder,
    e.g. the run given to ``weights_from``); a folder this process cannot write into. An
    existing folder is fine: TensorBoard only adds new event files to it. Returns the folder.
    """
    folder = log_dir(log_to, option)
    if folder is None:
        return None
    _summary_writer(option)
    where = f"{option} tensorboard DIR"
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{folder}: {where} is a file, not a folder; give a folder for TensorBoard's event files")
    target = Path(os.path.realpath(folder))
    for given in inputs:
        if given is not None:
            source = Path(os.path.realpath(given))
            if target == source or target.is_relative_to(source):
                how = "is" if target == source else "lies inside"
                raise UserError(f"{folder}: {where} {how} the input {given}; choose another folder")
    if folder.is_dir():
        check_writable_directory(folder)
    return folder


def scalars(line: dict, prefix: str = "") -> dict[str, float]:
    """The numeric values of a metrics line by tag: nested dicts as ``outer/inner``; the
    top-level ``epoch`` (the step), booleans, None and other non-numbers left out."""
    out: dict[str, float] = {}
    for key, value in line.items():
        tag = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(scalars(value, f"{tag}/"))
        elif isinstance(value, numbers.Real) and not isinstance(value, bool) and tag != "epoch":
            out[tag] = float(value)
    return out


class TensorBoardLogger:
    """Metrics lines (``metrics.jsonl``'s) as TensorBoard scalars in ``folder``, step = ``line["epoch"]``.

    ``purge_step``: the first epoch this logger writes; TensorBoard then hides what earlier
    event files in ``folder`` hold from that step on (module docstring).
    """

    def __init__(self, folder: str | os.PathLike, purge_step: int = 0) -> None:
        writer = _summary_writer()
        self.folder = Path(folder)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise os_error(exc, self.folder) from None
        _wait_for_a_new_second(self.folder)
        self._writer = writer(log_dir=str(self.folder), purge_step=int(purge_step))

    def log(self, line: dict) -> None:
        """Write one epoch's metrics."""
        step = int(line["epoch"])
        for tag, value in scalars(line).items():
            self._writer.add_scalar(tag, value, global_step=step)

    def flush(self) -> None:
        self._writer.flush()

    def close(self) -> None:
        self._writer.close()


def open_logger(log_to, purge_step: int) -> TensorBoardLogger | None:
    """The logger ``log_to`` names (None: none), its first epoch ``purge_step``."""
    folder = log_dir(log_to)
    return None if folder is None else TensorBoardLogger(folder, purge_step)


def _summary_writer(option: str = "log_to"):
    """TensorBoard's writer class, or one line saying how to install it."""
    try:
        import tensorboard  # noqa: F401  (torch's writer is a front end to this package)
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        raise UserError(f"{option} tensorboard needs the tensorboard package: {INSTALL_HINT}") from None
    return SummaryWriter


def _wait_for_a_new_second(folder: Path) -> None:
    """Return in a second later than the newest event file's in ``folder`` (its name starts
    with the second it was created in); a newer one (another clock) is not waited for."""
    newest = max(
        (
            int(part)
            for part in (p.name[len(_EVENTS_PREFIX) :].split(".", 1)[0] for p in folder.glob(_EVENTS_PREFIX + "*"))
            if part.isdigit()
        ),
        default=-1,
    )
    now = time.time()
    if int(now) == newest:
        time.sleep(newest + 1 - now + 0.01)
