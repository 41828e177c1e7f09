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
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Sequence

import h5py
import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import demonstrations, natural_key
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames, check_frames
from primspace.errors import DataError, first_line

__all__ = ["import_robomimic", "looks_like_robomimic"]

_DEMO = re.compile(r"demo_\d+")


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
        dt_in = _control_dt(f)
    return demonstrations(
        sequences, length, frames, source=f"robomimic:{path.name} joints={','.join(joints)}", images=images,
        dt_in=dt_in, where=path, joint_names=names,
    )


def looks_like_robomimic(path: str | os.PathLike) -> bool:
    """Whether ``path`` is an HDF5 file with ``data/demo_N`` groups (for guessing the format)."""
    try:
        with h5py.File(path, "r") as f:
            group = f.get("data")
            return isinstance(group, h5py.Group) and any(_DEMO.fullmatch(k) for k in group)
    except (OSError, ValueError):
        return False


def _open(path: Path) -> h5py.File:
    if not path.is_file():
        raise DataError("no such file", path=path)
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise DataError(f"not a readable HDF5 file ({first_line(exc)})", path=path) from None


def _demos(f: h5py.File, path: Path) -> list[str]:
    """The ``demo_N`` groups under ``data``, in natural numeric order."""
    group = f.get("data")
    if not isinstance(group, h5py.Group):
        top = ", ".join(sorted(f.keys())) or "nothing"
        raise DataError(f"no 'data' group (a robomimic file holds data/demo_N/obs/<key>); it has: {top}", path=path)
    demos = sorted((k for k in group if _DEMO.fullmatch(k)), key=lambda k: natural_key(k, "demo"))
    if not demos:
        raise DataError(f"'data' holds no demo_N groups; it has: {', '.join(sorted(group)) or 'nothing'}", path=path)
    return demos


def _keys(f: h5py.File, demo: str) -> str:
    """The keys under ``data/<demo>/obs``, for error messages."""
    obs = f["data"][demo].get("obs")
    return ", ".join(sorted(obs)) if isinstance(obs, h5py.Group) and len(obs) else "no keys"


def _dataset(f: h5py.File, demo: str, key: str, path: Path, index: int) -> h5py.Dataset:
    """``data/<demo>/obs/<key>``; a missing one names the file, the demo and the keys there."""
    obs = f["data"][demo].get("obs")
    if not isinstance(obs, h5py.Group):
        there = ", ".join(sorted(f["data"][demo])) or "nothing"
        raise DataError(f"data/{demo} has no 'obs' group; it has: {there}", path=path, field=key, index=index)
    node = obs.get(key)
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
    try:
        return np.asarray(node[selection])
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot be read, the file may be truncated ({first_line(exc)})", path=path, field=key,
                        index=index) from None


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


def _control_dt(f: h5py.File) -> float:
    """1 / control_freq from ``data``'s ``env_args`` JSON attribute, else 1.0 (unknown)."""
    try:
        args = json.loads(f["data"].attrs["env_args"])
        freq = float(args["env_kwargs"]["control_freq"])
    except (KeyError, TypeError, ValueError, json.JSONDecodeError):
        return 1.0
    return 1.0 / freq if np.isfinite(freq) and freq > 0 else 1.0
