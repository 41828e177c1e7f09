"""Import a robomimic-style HDF5 file: ``data/demo_N/obs/<key>``, joints and camera frames.

The layout (robomimic's, as its data set conversion scripts write it)::

    data/                       attrs: env_args (JSON, optional: control_freq sets dt)
        demo_0/obs/robot0_joint_pos        (T_0, 7)  float
        demo_0/obs/robot0_gripper_qpos     (T_0, 2)  float
        demo_0/obs/agentview_image         (T_0, H, W, 3) uint8
        demo_1/...

Demonstrations are read in natural numeric order (``demo_0, demo_1, ..., demo_10``).
The joint keys are concatenated along the last axis in the order given; a key of shape
``(T_i,)`` is one joint. Joint names are the key (one column) or ``<key>_<j>``. Frames
(one image key, optional) are aligned with the resampled joints and resized as
:mod:`primspace.data.importers.frames` says: output step ``k`` gets the recorded frame
nearest to its normalised time; only those frames are read from the file. Other groups
(``actions``, ``next_obs``, ``states``, ``mask``) are not read.

Only this file is read: an external link (h5py follows them by default), a dataset whose
data lie in other files (external storage, a virtual dataset) and a soft link that leaves
its ``data/demo_N`` group are refused, naming the link. So are two demo names with the
same number (``demo_1``, ``demo_01``), an empty demonstration, and a ``control_freq`` that
is not a rate (:func:`~primspace.data.importers.common.rate_dt`).
"""

from __future__ import annotations

import json
import os
import posixpath
import re
from pathlib import Path
from typing import Sequence

import h5py
import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import check_fits_memory, demonstrations, natural_key, printable, rate_dt
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames, check_frames
from primspace.errors import DataError, first_line

__all__ = ["import_robomimic", "looks_like_robomimic"]

_DEMO = re.compile(r"demo_\d+")
_DAMAGED = (RuntimeError, OSError, KeyError)  # what h5py raises where a file's structure is damaged
_MAX_HOPS = 16  # soft links followed in a row at most (HDF5's own limit)


def import_robomimic(
    path: str | os.PathLike,
    length: int,
    *,
    joints: Sequence[str],
    images: str | None = None,
    image_size=DEFAULT_IMAGE_SIZE,
) -> MotionDataset:
    """Read joints (and frames) of every ``data/demo_N`` of a robomimic-style HDF5 file.

    Parameters
    ----------
    path : path-like
        The HDF5 file.
    length : int
        T, the steps to resample each demonstration to.
    joints : list of str
        Keys under ``obs``, concatenated in this order (e.g. ``robot0_joint_pos``,
        ``robot0_gripper_qpos``).
    images : str, optional
        The key of the frames under ``obs`` (e.g. ``agentview_image``); None: joints only.
    image_size : (H, W)
        Size of the stored frames.

    Raises
    ------
    DataError
        A missing file, group or key (naming the file, the demo and the keys that exist),
        or bad values or frames (naming the file, the key and the demonstration's index).
    """
    path = Path(path)
    with _open(path) as f:
        demos = _demos(f, path)
        joints = list(joints)
        if not joints:
            raise DataError(
                f"no joint keys given (--joints, joints=); data/{demos[0]}/obs has: {_keys(f, demos[0])}", path=path
            )
        sequences = [_joint_values(f, demo, joints, path, i) for i, demo in enumerate(demos)]
        names = _joint_names(f, demos[0], joints)
        frames = None
        if images:
            frames = AlignedFrames(length, image_size)
            for i, demo in enumerate(demos):
                dataset = _dataset(f, demo, images, path, i)
                check_frames(dataset, len(sequences[i]), path=path, field=images, index=i)
                frames.add(len(sequences[i]), lambda idx, d=dataset, i=i: _read_frames(d, idx, path, images, i))
        dt_in = _control_dt(f, path)
    return demonstrations(
        sequences, length, frames, source=f"robomimic:{path.name} joints={','.join(joints)}", images=images,
        dt_in=dt_in, where=path, joint_names=names,
    )


def looks_like_robomimic(path: str | os.PathLike) -> bool:
    """Whether ``path`` is an HDF5 file with ``data/demo_N`` groups (for guessing the format)."""
    try:
        with h5py.File(path, "r") as f:
            if isinstance(f.get("data", getlink=True), h5py.ExternalLink):
                return True  # never opened here; the importer refuses it with a message
            group = f.get("data")
            return isinstance(group, h5py.Group) and any(isinstance(k, str) and _DEMO.fullmatch(k) for k in group)
    except (OSError, ValueError):
        return False
    except RuntimeError:  # an HDF5 file whose structure is damaged: the importer says where
        return True


def _open(path: Path) -> h5py.File:
    if not path.is_file():
        raise DataError("no such file", path=path)
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise DataError(f"not a readable HDF5 file ({first_line(exc)})", path=path) from None


def _demos(f: h5py.File, path: Path) -> list[str]:
    """The ``demo_N`` groups under ``data``, in natural numeric order (each number once)."""
    group = _get(f, "data", path, "data")
    if not isinstance(group, h5py.Group):
        top = ", ".join(_names(f, path, "/")) or "nothing"
        raise DataError(f"no 'data' group (a robomimic file holds data/demo_N/obs/<key>); it has: {top}", path=path)
    names = _names(group, path, "data")
    demos = sorted((k for k in names if _DEMO.fullmatch(k)), key=lambda k: (natural_key(k, "demo"), k))
    if not demos:
        raise DataError(f"'data' holds no demo_N groups; it has: {', '.join(names) or 'nothing'}", path=path)
    for a, b in zip(demos, demos[1:]):
        if natural_key(a, "demo") == natural_key(b, "demo"):
            raise DataError(f"data/{a} and data/{b} have the same number {natural_key(a, 'demo')}; "
                            "which comes first is ambiguous, keep one name per demonstration", path=path)
    return demos


def _names(group: h5py.Group, path: Path, where: str, **located) -> list[str]:
    """The names in ``group`` (at ``where`` in the file), sorted; a name that is not UTF-8 escaped."""
    try:
        names = list(group)
    except _DAMAGED as exc:
        raise DataError(f"{where} cannot be listed, the file is damaged ({first_line(exc)})", path=path,
                        **located) from None
    return sorted(printable(n if isinstance(n, str) else bytes(n).decode("utf-8", "backslashreplace")) for n in names)


def _get(group: h5py.Group, name: str, path: Path, where: str, demo: str | None = None, *, field=None, index=None,
         hops: int = 0):
    """``group[name]`` (None if absent; ``where``: its path in the file), refusing what reads beyond
    this file or ``data/<demo>``: an external link, a soft link out of the demo (a soft link is
    followed one component at a time, each checked so), a dataset stored in other files."""

    def fail(why: str) -> DataError:
        return DataError(f"{where} {why}; only this file's own data are read", path=path, field=field, index=index)

    try:
        link = group.get(name, getlink=True)
        if link is None:
            return None
        if isinstance(link, h5py.ExternalLink):
            raise fail(f"is an external link to {link.filename}:{link.path}")
        if isinstance(link, h5py.SoftLink):
            target = posixpath.normpath(posixpath.join("/" + posixpath.dirname(where), link.path))
            if demo is not None and not (target + "/").startswith(f"/data/{demo}/"):
                raise fail(f"is a soft link to {link.path}, outside data/{demo}")
            if hops >= _MAX_HOPS:
                raise fail(f"is a chain of more than {_MAX_HOPS} soft links")
            parts, node = [p for p in target.split("/") if p], group.file
            for k, part in enumerate(parts):  # each component checked as a link of its own
                if not isinstance(node, h5py.Group):
                    return None
                node = _get(node, part, path, "/".join(parts[: k + 1]), demo, field=field, index=index, hops=hops + 1)
            return node
        if not isinstance(link, h5py.HardLink):
            raise fail(f"is a link of another kind ({type(link).__name__})")
        node = group.get(name)
        if isinstance(node, h5py.Dataset) and node.is_virtual:
            files = sorted({source.file_name for source in node.virtual_sources()})
            raise fail(f"is a virtual dataset (its data lie in {', '.join(files)})")
        if isinstance(node, h5py.Dataset) and node.external:
            raise fail(f"is stored outside the file (in {', '.join(sorted({str(e[0]) for e in node.external}))})")
        return node
    except _DAMAGED as exc:
        raise DataError(f"{where} cannot be read, the file is damaged ({first_line(exc)})", path=path, field=field,
                        index=index) from None


def _keys(f: h5py.File, demo: str) -> str:
    """The keys under ``data/<demo>/obs``, for error messages (links checked: :func:`_get`)."""
    path = Path(f.filename)
    group = _get(f["data"], demo, path, f"data/{demo}", demo)
    obs = _get(group, "obs", path, f"data/{demo}/obs", demo) if isinstance(group, h5py.Group) else None
    names = _names(obs, path, f"data/{demo}/obs") if isinstance(obs, h5py.Group) else []
    return ", ".join(names) or "no keys"


def _dataset(f: h5py.File, demo: str, key: str, path: Path, index: int) -> h5py.Dataset:
    """``data/<demo>/obs/<key>``; a missing one names the file, the demo and the keys there."""
    group = _get(f["data"], demo, path, f"data/{demo}", demo, field=key, index=index)
    if not isinstance(group, h5py.Group):
        raise DataError(f"data/{demo} is not a group", path=path, field=key, index=index)
    obs = _get(group, "obs", path, f"data/{demo}/obs", demo, field=key, index=index)
    if not isinstance(obs, h5py.Group):
        there = ", ".join(_names(group, path, f"data/{demo}", field=key, index=index)) or "nothing"
        raise DataError(f"data/{demo} has no 'obs' group; it has: {there}", path=path, field=key, index=index)
    node = _get(obs, key, path, f"data/{demo}/obs/{key}", demo, field=key, index=index)
    if not isinstance(node, h5py.Dataset):
        what = "is not an array" if node is not None else "is missing"
        raise DataError(f"data/{demo}/obs/{key} {what}; keys there: {_keys(f, demo)}", path=path, field=key, index=index)
    return node


def _joint_values(f: h5py.File, demo: str, keys: list[str], path: Path, index: int) -> np.ndarray:
    """The joint keys of one demo, concatenated: ``(T_i, J)``."""
    columns, steps = [], None
    for key in keys:
        node = _dataset(f, demo, key, path, index)
        if node.ndim not in (1, 2) or node.dtype.kind not in "fiu":
            raise DataError(
                f"data/{demo}/obs/{key} must be (T_i,) or (T_i, d) numbers, got {node.dtype} {node.shape}",
                path=path, field=key, index=index,
            )
        if node.shape[0] == 0:
            raise DataError(f"data/{demo}/obs/{key} is empty (0 steps)", path=path, field=key, index=index)
        value = _read(node, path, key, index)
        value = value[:, None] if value.ndim == 1 else value
        if steps is not None and value.shape[0] != steps[1]:
            raise DataError(
                f"data/{demo}/obs/{key} has {value.shape[0]} steps, {steps[0]} has {steps[1]}",
                path=path, field=key, index=index,
            )
        steps = steps or (key, value.shape[0])
        columns.append(value)
    return np.concatenate(columns, axis=1)


def _read(node: h5py.Dataset, path: Path, key: str, index: int, selection=()) -> np.ndarray:
    """``node[selection]`` (all of it by default), once its size is known to fit in memory."""
    rows = node.shape[0] if isinstance(selection, tuple) else len(selection)
    nbytes = rows * int(np.prod(node.shape[1:], dtype=np.float64)) * node.dtype.itemsize
    check_fits_memory(nbytes, f"{node.name.lstrip('/')} {node.shape} {node.dtype}", path=path, field=key, index=index)
    try:
        return np.asarray(node[selection])
    except (OSError, ValueError, RuntimeError) as exc:
        raise DataError(f"cannot be read, the file may be truncated ({first_line(exc)})", path=path, field=key,
                        index=index) from None
    except MemoryError:
        raise DataError(f"{node.name.lstrip('/')} {node.shape} is too large to read into memory", path=path,
                        field=key, index=index) from None


def _read_frames(node: h5py.Dataset, indices: np.ndarray, path: Path, key: str, index: int) -> np.ndarray:
    """The frames at ``indices`` (sorted, distinct): only those are read."""
    return _read(node, path, key, index, indices)


def _joint_names(f: h5py.File, demo: str, keys: list[str]) -> list[str]:
    """``<key>`` for a one-column key, ``<key>_<j>`` otherwise (the widths of ``demo``)."""
    names = []
    for key in keys:
        node = f["data"][demo]["obs"][key]
        width = 1 if node.ndim == 1 else int(node.shape[1])
        names.extend([key] if width == 1 else [f"{key}_{j}" for j in range(width)])
    return names


def _control_dt(f: h5py.File, path: Path) -> float:
    """1 / control_freq from ``data``'s ``env_args`` JSON attribute, else 1.0 (unknown); a
    ``control_freq`` that is there but not a rate is refused (:func:`rate_dt`)."""
    try:
        args = json.loads(f["data"].attrs["env_args"])
        freq = args["env_kwargs"]["control_freq"]
    except (KeyError, TypeError, ValueError, OSError):  # ValueError: JSONDecodeError, UnicodeDecodeError
        return 1.0
    return rate_dt(freq, path=path, field="control_freq", where="(data's env_args attribute, env_kwargs)")
