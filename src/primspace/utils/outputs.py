"""Outputs know who wrote them: the mark each command writes into its files, read back,
and the rule by which ``--overwrite`` replaces a file.

A command's mark is ``"primspace <command>"`` (``"primspace show"``). Where it is kept:

- PNG figures: a ``tEXt`` chunk with the key ``primspace`` (:func:`png_metadata`, given
  to matplotlib's ``savefig(metadata=...)``);
- GIF animations: the comment extension, ``primspace <command>`` (:func:`gif_comment`);
- HDF5 data sets: the root attribute ``primspace_writer``
  (``MotionDataset.save(writer=...)``, read by :func:`primspace.utils.outputs.file_writer`).
  A data set without that attribute whose ``source`` is the simulator's is taken as
  ``primspace generate``'s (the generator records its settings there);
- summaries (JSON): their own ``summary_version`` field (``primspace summarize``).

Folders are recognised by their own files instead: a run by its ``config.json``
(:func:`primspace.train.rundir.prepare_run_dir`), a cluster or segment output by its
``result.json`` (:func:`primspace.utils.folders.check_output_directory`), an
experiment by its ``experiment.json``.

:func:`check_replaceable` is the rule every file-writing command applies (through
:func:`output_file`): an existing file is refused without ``--overwrite``, and with it
unless it carries the command's own mark; the one-line error names the file and what it is
(:func:`describe`).

This module sits above the data layer (it reads a data set file's mark through
:mod:`primspace.data.reading`) and above :mod:`primspace.utils.files`, which the data layer
writes through.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path

from primspace.utils.errors import OutputExistsError, UserError
from primspace.utils.files import check_output, check_outside_inputs

__all__ = [
    "MARK_KEY",
    "DATA_SET_MARK",
    "png_metadata",
    "gif_comment",
    "file_writer",
    "describe",
    "check_replaceable",
    "output_file",
]

#: The PNG text key of a figure's mark.
MARK_KEY = "primspace"
#: The root attribute of an HDF5 data set that names the command that wrote it.
DATA_SET_MARK = "primspace_writer"
_PNG, _GIF, _HDF5 = b"\x89PNG\r\n\x1a\n", (b"GIF87a", b"GIF89a"), b"\x89HDF\r\n\x1a\n"
#: ``source`` attributes of data sets the simulator writes (``primspace generate``): files
#: generated before the writer mark (primspace <= 0.5) are recognised by them.
_GENERATED_SOURCES = ("primspace.sim ", "primspace.sim.composite ")
_KINDS = {
    "png": "a PNG image",
    "gif": "a GIF animation",
    "hdf5": "an HDF5 file",
    "json": "a JSON file",
    "zip": "a zip archive (a PyTorch checkpoint is one)",
    "npy": "a NumPy array file",
    "file": "a file",
}


def png_metadata(writer: str | None) -> dict:
    """``savefig(metadata=...)`` for a PNG marked as written by ``writer`` (empty if None)."""
    return {} if writer is None else {MARK_KEY: writer}


def gif_comment(writer: str | None) -> dict:
    """Pillow ``save`` options for a GIF marked as written by ``writer`` (empty if None)."""
    return {} if writer is None else {"comment": writer.encode("utf-8")}


def _kind(path: Path) -> str:
    """What ``path`` holds, from its first bytes: a key of :data:`_KINDS`."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return "file"
    if head == _PNG:
        return "png"
    if head[:6] in _GIF:
        return "gif"
    if head == _HDF5:
        return "hdf5"
    if head[:4] == b"PK\x03\x04":
        return "zip"
    if head[:6] == b"\x93NUMPY":
        return "npy"
    return "json" if head.lstrip()[:1] in (b"{", b"[") else "file"


def _image_mark(path: Path, kind: str) -> str | None:
    from PIL import Image

    try:
        with Image.open(path) as image:
            if kind == "png":
                value = getattr(image, "text", {}).get(MARK_KEY)
            else:
                comment = image.info.get("comment", b"")
                value = comment.decode("utf-8", "replace") if isinstance(comment, bytes) else str(comment)
    except (OSError, ValueError, SyntaxError):  # Pillow's errors for a damaged image
        return None
    return value if isinstance(value, str) and value.startswith(f"{MARK_KEY} ") else None


def _data_set_mark(path: Path) -> str | None:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            mark, source = f.attrs.get(DATA_SET_MARK), f.attrs.get("source", "")
    except Exception:  # noqa: BLE001 - not a file, not HDF5, unreadable: no mark
        return None
    if mark is not None:
        return mark.decode("utf-8", "replace") if isinstance(mark, bytes) else str(mark)
    source = source.decode("utf-8", "replace") if isinstance(source, bytes) else str(source)
    return "primspace generate" if source.startswith(_GENERATED_SOURCES) else None


def _json_mark(path: Path) -> str | None:
    try:
        content = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(content, dict):
        return None
    if "summary_version" in content:
        return "primspace summarize"
    writer = content.get("writer")  # the result.json of cluster, segment and predict say who wrote them
    return writer if isinstance(writer, str) and writer.startswith("primspace ") else None


def file_writer(path: str | os.PathLike) -> str | None:
    """The mark of the command that wrote the file ``path`` (``"primspace show"``), or
    None: no mark, not a file, or unreadable."""
    path = Path(path)
    if not path.is_file():
        return None
    kind = _kind(path)
    if kind in ("png", "gif"):
        return _image_mark(path, kind)
    if kind == "hdf5":
        return _data_set_mark(path)
    return _json_mark(path) if kind == "json" else None


def _run_of(path: Path) -> Path | None:
    """The primspace run folder holding ``path`` (its ``config.json`` names a kind), or None."""
    try:
        config = json.loads((path.parent / "config.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return path.parent if isinstance(config, dict) and {"kind", "model", "train"} <= set(config) else None


def describe(path: str | os.PathLike) -> str:
    """What ``path`` is, in a few words for an error message ("a PNG image written by
    primspace show", "part of the primspace run directory runs/fit", "a file not written
    by a primspace command")."""
    path = Path(path)
    if path.is_dir():
        return "a folder"
    run = _run_of(path)
    if run is not None:
        return f"part of the primspace run directory {run}"
    writer = file_writer(path)
    what = _KINDS[_kind(path)]
    if what == "a file" and path.suffix:
        what = f"a {path.suffix} file"
    return f"{what} written by {writer}" if writer else f"{what} not written by a primspace command"


def check_replaceable(path: str | os.PathLike, writer: str, overwrite: bool, option: str = "--out") -> Path:
    """Refuse an existing ``path`` unless ``overwrite`` and it carries ``writer``'s mark.

    Parameters
    ----------
    path : path-like
        The file a command is about to write.
    writer : str
        The command's mark, ``"primspace <command>"``.
    overwrite : bool
        Whether ``--overwrite`` was given.
    option : str
        The flag that named ``path`` (for the message).

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``overwrite`` is false.
    UserError
        ``path`` exists and is not an earlier output of ``writer``: one line naming it and
        what it is.
    """
    path = Path(path)
    if not os.path.lexists(path):
        return path
    if not overwrite:
        raise OutputExistsError(path)
    if path.is_symlink() or file_writer(path) != writer:
        what = "a symbolic link" if path.is_symlink() else describe(path)
        raise UserError(
            f"{path}: exists and is {what}; --overwrite replaces only an earlier output of {writer}: "
            f"choose another {option}"
        )
    return path


def output_file(
    text: str | os.PathLike,
    *,
    inputs: Iterable = (),
    overwrite: bool = False,
    option: str = "--out",
    writer: str | None = None,
) -> Path:
    """The checked path of a command's file output, as the user typed it.

    Refused, each in one line: an empty name; ``dir/`` (a trailing separator names a
    directory, so no file called ``dir`` is written) or an existing directory; a path that
    is, contains or lies inside one of ``inputs``
    (:func:`~primspace.utils.files.check_outside_inputs`); an existing file unless ``overwrite``
    (:func:`~primspace.utils.files.check_output`); with ``writer`` (the command's mark, e.g.
    ``"primspace show"``), an existing file that is not an earlier output of that command,
    even with ``overwrite`` (:func:`check_replaceable`).
    """
    raw = os.fspath(text)
    if not raw.strip():
        raise UserError(f"{option} is empty")
    if raw.endswith(("/", os.sep)) or Path(raw).is_dir():
        raise UserError(f"{raw}: is a directory; {option} must name a file")
    path = Path(raw)
    check_outside_inputs(path, inputs, option)
    check_output(path, overwrite)
    if writer is not None:
        check_replaceable(path, writer, overwrite, option)
    return path
