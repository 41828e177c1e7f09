"""Import a robomimic-style HDF5 file: ``data/demo_N``, joints and camera frames.

The layout (robomimic's, as its data set conversion scripts write it)::

    data/                       attrs: env_args (JSON, optional: control_freq sets dt)
        demo_0/obs/robot0_joint_pos        (T_0, 7)  float
        demo_0/obs/robot0_gripper_qpos     (T_0, 2)  float
        demo_0/obs/agentview_image         (T_0, H, W, 3) uint8
        demo_0/actions                     (T_0, 7)  float   (demo level: also states, rewards, dones)
        demo_1/...
    mask/                       (optional) filter keys: the demos of each split
        train                              (n,) byte strings, e.g. b"demo_0"
        valid

Demonstrations are read in natural numeric order (``demo_0, demo_1, ..., demo_10``);
with ``filter_key`` only those that ``mask/<filter_key>`` names, still in natural numeric
order whatever the mask's order (robomimic's ``--filter-key train``). A missing filter key
is refused naming the filter keys there are; so is a mask that names a demo not in
``data`` or one twice, or names none.

Keys
----
A joint or image key is looked up in ``data/demo_N/obs/<key>`` first, then at demo level,
``data/demo_N/<key>`` (``actions``, ``states``, ``rewards``, ``dones``): so ``--joints
actions`` reads the actions and can be mixed with observation keys. Where both exist, the
observation wins. A key with a ``/`` is a path inside ``data/demo_N`` and is read there
only: ``obs/<key>``, ``next_obs/<key>``, ``./actions`` (the demo-level one, even where
``obs`` holds an ``actions`` too); ``..``, an empty component or a leading ``/`` are
refused.

The joint keys are concatenated along the last axis in the order given; a key of shape
``(T_i,)`` is one joint. Joint names are the key (one column) or ``<key>_<j>`` (a leading
``./`` dropped). Frames (one image key, optional) are aligned with the resampled joints,
fitted (``image_fit``) and resized as :mod:`primspace.data.importers.frames` says: output
step ``k`` gets the recorded frame nearest to its normalised time; only those frames are
read from the file. Each sample's ``source_ids`` entry is
``robomimic:<file name>:data/demo_N``.

Only this file is read: an external link (h5py follows them by default), a dataset whose
data lie in other files (external storage, a virtual dataset) and a soft link that leaves
its ``data/demo_N`` group are refused, naming the link; the mask's datasets are held to
the same rules (a soft link may point anywhere inside the file). So are two demo names with
the same number (``demo_1``, ``demo_01``), an empty demonstration, and a ``control_freq``
that is not a rate (:func:`~primspace.data.importers.common.rate_dt`).
"""

from __future__ import annotations

import json
import os
import posixpath
import re
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import check_fits_memory, demonstrations, natural_key, printable, rate_dt
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames, as_image_fit, check_frames
from primspace.utils.errors import DataError, first_line

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
    image_fit: str = "crop",
    filter_key: str | None = None,
) -> MotionDataset:
    """Read joints (and frames) of every ``data/demo_N`` of a robomimic-style HDF5 file.

    Parameters
    ----------
    path : path-like
        The HDF5 file.
    length : int
        T, the steps to resample each demonstration to.
    joints : list of str
        Keys, concatenated in this order (e.g. ``robot0_joint_pos``, ``robot0_gripper_qpos``,
        ``actions``): under ``obs``, else at demo level; a key with ``/`` is a path inside
        the demo (module docstring, *Keys*).
    images : str, optional
        The key of the frames (e.g. ``agentview_image``), looked up as the joint keys are;
        None: joints only.
    image_size : (H, W)
        Size of the stored frames.
    image_fit : {"crop", "pad", "stretch"}
        How a frame of another aspect ratio is fitted (:mod:`~primspace.data.importers.frames`).
    filter_key : str, optional
        Read only the demos that ``mask/<filter_key>`` names (e.g. ``train``, ``valid``).

    Raises
    ------
    DataError
        A missing file, group, key or filter key (naming the file, the demo and the keys that
        exist), or bad values or frames (naming the file, the key and the demonstration's index).
    """
    path = Path(path)
    image_fit = as_image_fit(image_fit)
    joints = [_check_key(key, path) for key in joints]
    if images:
        _check_key(images, path)
    with _open(path) as f:
        demos = _demos(f, path)
        if filter_key is not None:
            demos = _filtered(f, demos, filter_key, path)
        if not joints:
            raise DataError(
                f"no joint keys given (--joints, joints=); data/{demos[0]}/obs has: {_keys(f, demos[0])}", path=path
            )
        sequences, names = _all_joint_values(f, demos, joints, path)
        frames = None
        if images:
            frames = AlignedFrames(length, image_size, image_fit)
            for i, demo in enumerate(demos):
                dataset, _ = _dataset(f, demo, images, path, i)
                check_frames(dataset, len(sequences[i]), path=path, field=images, index=i)
                frames.add(len(sequences[i]), lambda idx, d=dataset, i=i: _read_frames(d, idx, path, images, i))
            frames.collect()  # while the file is open
        dt_in = _control_dt(f, path)
    split = "" if filter_key is None else f" filter_key={printable(filter_key)}"
    return demonstrations(
        sequences,
        length,
        frames,
        source=f"robomimic:{path.name} joints={','.join(joints)}{split}",
        images=images,
        dt_in=dt_in,
        where=path,
        joint_names=names,
        source_ids=[f"robomimic:{printable(path.name)}:data/{demo}" for demo in demos],
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
            raise DataError(
                f"data/{a} and data/{b} have the same number {natural_key(a, 'demo')}; "
                "which comes first is ambiguous, keep one name per demonstration",
                path=path,
            )
    return demos


def _names(group: h5py.Group, path: Path, where: str, **located) -> list[str]:
    """The names in ``group`` (at ``where`` in the file), sorted; a name that is not UTF-8 escaped."""
    try:
        names = list(group)
    except _DAMAGED as exc:
        raise DataError(
            f"{where} cannot be listed, the file is damaged ({first_line(exc)})", path=path, **located
        ) from None
    return sorted(printable(n if isinstance(n, str) else bytes(n).decode("utf-8", "backslashreplace")) for n in names)


def _get(
    group: h5py.Group,
    name: str,
    path: Path,
    where: str,
    demo: str | None = None,
    *,
    field=None,
    index=None,
    hops: int = 0,
):
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
        raise DataError(
            f"{where} cannot be read, the file is damaged ({first_line(exc)})", path=path, field=field, index=index
        ) from None


def _keys(f: h5py.File, demo: str) -> str:
    """The keys under ``data/<demo>/obs``, for error messages (links checked: :func:`_get`)."""
    path = Path(f.filename)
    group = _get(f["data"], demo, path, f"data/{demo}", demo)
    obs = _get(group, "obs", path, f"data/{demo}/obs", demo) if isinstance(group, h5py.Group) else None
    names = _names(obs, path, f"data/{demo}/obs") if isinstance(obs, h5py.Group) else []
    return ", ".join(names) or "no keys"


def _check_key(key: str, path: Path) -> str:
    """``key`` if it names something inside a demo (module docstring, *Keys*); DataError otherwise."""
    parts, _ = _key_parts(key)
    if not parts or any(p in ("", ".", "..") for p in parts):
        raise DataError(
            "a key is a name, or a path inside data/demo_N (obs/<key>, ./actions) without '..', "
            "'.', an empty part or a leading '/'",
            path=path,
            field=printable(key),
        )
    return key


def _key_parts(key: str) -> tuple[list[str], bool]:
    """The components of ``key`` and whether it is a path (holds a ``/``) rather than a plain name."""
    if "/" not in key:
        return [key], False
    return (key[2:] if key.startswith("./") else key).split("/"), True


def _dataset(f: h5py.File, demo: str, key: str, path: Path, index: int) -> tuple[h5py.Dataset, str]:
    """The dataset of ``key`` in ``data/<demo>``: ``obs/<key>``, else ``<key>`` at demo level, or
    the path ``key`` (module docstring, *Keys*); and where it lies. A missing one names the
    file, the demo and the keys there."""
    located = dict(field=key, index=index)
    group = _get(f["data"], demo, path, f"data/{demo}", demo, **located)
    if not isinstance(group, h5py.Group):
        raise DataError(f"data/{demo} is not a group", path=path, **located)
    parts, is_path = _key_parts(key)
    if is_path:
        node, where = _walk(group, parts, demo, path, located)
    else:
        obs = _get(group, "obs", path, f"data/{demo}/obs", demo, **located)
        where = f"data/{demo}/obs/{key}"
        node = _get(obs, key, path, where, demo, **located) if isinstance(obs, h5py.Group) else None
        if node is None:
            node = _get(group, key, path, f"data/{demo}/{key}", demo, **located)
            if node is None:
                raise DataError(_missing(group, obs, demo, key, path, located), path=path, **located)
            where = f"data/{demo}/{key}"
    if not isinstance(node, h5py.Dataset):
        raise DataError(f"{where} is not an array; keys there: {_keys(f, demo)}", path=path, **located)
    return node, where


def _missing(group: h5py.Group, obs, demo: str, key: str, path: Path, located: dict) -> str:
    """Why a plain ``key`` is in neither ``data/<demo>/obs`` nor ``data/<demo>``: the keys of both."""
    level = ", ".join(n for n in _names(group, path, f"data/{demo}", **located) if n != "obs") or "nothing else"
    if not isinstance(obs, h5py.Group):
        return f"data/{demo} has no 'obs' group and no {printable(key)}; it has: {level}"
    there = ", ".join(_names(obs, path, f"data/{demo}/obs", **located)) or "no keys"
    return f"data/{demo}/obs/{printable(key)} is missing; keys there: {there}; at demo level (data/{demo}): {level}"


def _walk(group: h5py.Group, parts: list[str], demo: str, path: Path, located: dict):
    """The node at ``parts`` inside ``group`` (``data/<demo>``), each component checked by
    :func:`_get`, and its path; a missing one is refused naming what its group holds."""
    where = f"data/{demo}"
    for part in parts:
        if not isinstance(group, h5py.Group):
            raise DataError(f"{where} is not a group", path=path, **located)
        node = _get(group, part, path, f"{where}/{part}", demo, **located)
        if node is None:
            there = ", ".join(_names(group, path, where, **located)) or "nothing"
            raise DataError(f"{where}/{printable(part)} is missing; {where} has: {there}", path=path, **located)
        group, where = node, f"{where}/{part}"
    return group, where


def _all_joint_values(f: h5py.File, demos: list[str], keys: list[str], path: Path) -> tuple[list, list[str]]:
    """Each demo's joint keys concatenated, ``(T_i, J)``, and the joint names: ``<key>`` for a
    one-column key, ``<key>_<j>`` otherwise (a key's columns must agree across demos)."""
    sequences, widths = [], None
    for i, demo in enumerate(demos):
        values, own = _joint_values(f, demo, keys, path, i)
        if widths is not None and own != widths:
            k = next(j for j in range(len(keys)) if own[j] != widths[j])
            raise DataError(
                f"{keys[k]} has {own[k]} columns in data/{demo}, {widths[k]} in data/{demos[0]}",
                path=path,
                field=keys[k],
                index=i,
            )
        widths = widths or own
        sequences.append(values)
    names = []
    for key, width in zip(keys, widths):
        name = key[2:] if key.startswith("./") else key
        names.extend([name] if width == 1 else [f"{name}_{j}" for j in range(width)])
    return sequences, names


def _joint_values(f: h5py.File, demo: str, keys: list[str], path: Path, index: int) -> tuple[np.ndarray, list[int]]:
    """The joint keys of one demo, concatenated: ``(T_i, J)``; and each key's columns."""
    columns, steps = [], None
    for key in keys:
        node, where = _dataset(f, demo, key, path, index)
        if node.ndim not in (1, 2) or node.dtype.kind not in "fiu":
            raise DataError(
                f"{where} must be (T_i,) or (T_i, d) numbers, got {node.dtype} {node.shape}",
                path=path,
                field=key,
                index=index,
            )
        if node.shape[0] == 0:
            raise DataError(f"{where} is empty (0 steps)", path=path, field=key, index=index)
        value = _read(node, path, key, index)
        value = value[:, None] if value.ndim == 1 else value
        if steps is not None and value.shape[0] != steps[1]:
            raise DataError(
                f"{where} has {value.shape[0]} steps, {steps[0]} has {steps[1]}",
                path=path,
                field=key,
                index=index,
            )
        steps = steps or (key, value.shape[0])
        columns.append(value)
    return np.concatenate(columns, axis=1), [c.shape[1] for c in columns]


def _filtered(f: h5py.File, demos: list[str], filter_key: str, path: Path) -> list[str]:
    """The demos that ``mask/<filter_key>`` names, in natural numeric order (module docstring)."""
    field = f"mask/{printable(filter_key)}"
    if not filter_key or "/" in filter_key or filter_key in (".", ".."):
        raise DataError("a filter key is one name under mask/ (e.g. train, valid)", path=path, field=field)
    mask = _get(f, "mask", path, "mask", field=field)
    if not isinstance(mask, h5py.Group):
        raise DataError(
            f"no filter key {printable(filter_key)!r}: the file has no 'mask' group (robomimic's "
            "filter keys are mask/<name>, lists of demo names)",
            path=path,
            field=field,
        )
    node = _get(mask, filter_key, path, field, field=field)
    if node is None:
        there = ", ".join(_names(mask, path, "mask", field=field)) or "none"
        raise DataError(f"no filter key {printable(filter_key)!r}; filter keys there: {there}", path=path, field=field)
    named = _mask_names(node, path, field)
    if not named:
        raise DataError(f"{field} names no demonstrations", path=path, field=field)
    known, seen = set(demos), set()
    for name in named:
        if name not in known:
            raise DataError(
                f"{field} names {name}, which is not among data's {len(demos)} demo_N groups ({_span(demos)})",
                path=path,
                field=field,
            )
        if name in seen:
            raise DataError(f"{field} names {name} twice", path=path, field=field)
        seen.add(name)
    return [demo for demo in demos if demo in seen]


def _mask_names(node, path: Path, field: str) -> list[str]:
    """The demo names of a mask dataset: 1-D strings (robomimic writes bytes, ``b"demo_0"``)."""
    strings = isinstance(node, h5py.Dataset) and (node.dtype.kind == "S" or h5py.check_string_dtype(node.dtype))
    if not strings or node.ndim != 1:
        got = f"{node.dtype} {node.shape}" if isinstance(node, h5py.Dataset) else "a group"
        raise DataError(
            f"{field} must be a 1-D array of demo names (strings such as b'demo_0'), got {got}", path=path, field=field
        )
    values = _read(node, path, field, None).tolist()
    return [printable(v.decode("utf-8", "backslashreplace") if isinstance(v, bytes) else str(v)) for v in values]


def _span(demos: list[str]) -> str:
    """``demo_0, demo_1, demo_2`` or ``demo_0 .. demo_9`` (for messages)."""
    return ", ".join(demos) if len(demos) <= 4 else f"{demos[0]} .. {demos[-1]}"


def _read(node: h5py.Dataset, path: Path, key: str, index: int, selection=()) -> np.ndarray:
    """``node[selection]`` (all of it by default), once its size is known to fit in memory."""
    rows = node.shape[0] if isinstance(selection, tuple) else len(selection)
    nbytes = rows * int(np.prod(node.shape[1:], dtype=np.float64)) * node.dtype.itemsize
    check_fits_memory(nbytes, f"{node.name.lstrip('/')} {node.shape} {node.dtype}", path=path, field=key, index=index)
    try:
        return np.asarray(node[selection])
    except (OSError, ValueError, RuntimeError) as exc:
        raise DataError(
            f"cannot be read, the file may be truncated ({first_line(exc)})", path=path, field=key, index=index
        ) from None
    except MemoryError:
        raise DataError(
            f"{node.name.lstrip('/')} {node.shape} is too large to read into memory", path=path, field=key, index=index
        ) from None


def _read_frames(node: h5py.Dataset, indices: np.ndarray, path: Path, key: str, index: int) -> np.ndarray:
    """The frames at ``indices`` (sorted, distinct): only those are read."""
    return _read(node, path, key, index, indices)


def _control_dt(f: h5py.File, path: Path) -> float:
    """1 / control_freq from ``data``'s ``env_args`` JSON attribute, else 1.0 (unknown); a
    ``control_freq`` that is there but not a rate is refused (:func:`rate_dt`)."""
    try:
        args = json.loads(f["data"].attrs["env_args"])
        freq = args["env_kwargs"]["control_freq"]
    except (KeyError, TypeError, ValueError, OSError):  # ValueError: JSONDecodeError, UnicodeDecodeError
        return 1.0
    return rate_dt(freq, path=path, field="control_freq", where="(data's env_args attribute, env_kwargs)")
