"""Import a LeRobot data set directory (format v2.x): parquet tables and per-episode videos.

The layout (LeRobot's v2.0 / v2.1, one parquet file and one video per episode and camera)::

    meta/info.json       codebase_version "v2.x", fps, chunks_size, data_path, video_path,
                         features {"observation.state": {"dtype": "float32", "shape": [J],
                         "names": [...]}, "observation.images.top": {"dtype": "video", ...}}
    meta/episodes.jsonl  one line per episode: {"episode_index": 0, "tasks": [...], "length": T_0}
    data/chunk-000/episode_000000.parquet                    one row per frame
    videos/chunk-000/observation.images.top/episode_000000.mp4

Episode ``e`` lies in chunk ``e // chunks_size``; its files are ``info.json``'s
``data_path`` and ``video_path`` templates filled in. Episodes are read in index order
(those listed in ``episodes.jsonl``, else ``0 .. total_episodes - 1``). Joints are the
state columns named (default ``observation.state``), concatenated in order; their names
come from the feature's ``names`` when they fit, else ``<key>_<j>``. Frames come from a
``video`` feature (decoded with PyAV) or an ``image`` feature (PNG/JPEG bytes in the
table, decoded with Pillow). LeRobot records one frame per row at ``fps``, so the ``i``-th
decoded frame is row ``i``'s (a count that differs is refused); frames are then aligned
with the resampled joints and resized as :mod:`primspace.data.importers.frames` says.
``dt`` is ``1 / fps`` per input step; an episode's single task (``episodes.jsonl``)
becomes its label.

What a data set names stays inside its folder: the templates may use only the fields
``{episode_chunk}``, ``{episode_index}`` (integers, with a width like ``:03d``) and, in
``video_path``, ``{video_key}``; an absolute template, or a file that resolves outside the
folder (``..``, a symbolic link), is refused. So are ``fps`` that is not a positive finite
rate, ``chunks_size`` that is not a positive integer and an ``episode_index`` that is not a
whole number or is listed twice.

Needs pyarrow and PyAV, the ``video`` extra: ``pip install 'primspace[video]'``.
Version 3 data sets (many episodes per file) are refused with a message.
"""

from __future__ import annotations

import io
import json
import os
import re
import string
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Sequence

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import demonstrations, printable, rate_dt, shown
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames
from primspace.errors import DataError, UserError, first_line

__all__ = ["import_lerobot", "is_lerobot_dir"]

_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
_VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
_NOT_JOINTS = ("video", "image", "string")
# the fields each template may use; the integer ones take a width only (":03d")
_TEMPLATE_FIELDS = {
    "data_path": ("episode_chunk", "episode_index"),
    "video_path": ("episode_chunk", "episode_index", "video_key"),
}
_DEFAULTS = {"data_path": _DATA_PATH, "video_path": _VIDEO_PATH}
_INT_SPEC = re.compile(r"(0?[1-9][0-9]?)?d?")
_MAX_EPISODES = 1_000_000  # total_episodes beyond this is damage, not a data set


def import_lerobot(
    path: str | os.PathLike,
    length: int,
    *,
    joints: Sequence[str] = ("observation.state",),
    images: str | None = None,
    image_size=DEFAULT_IMAGE_SIZE,
) -> MotionDataset:
    """Read joints (and frames) of every episode of a LeRobot v2.x data set directory.

    Parameters
    ----------
    path : path-like
        The data set's directory (holding ``meta/info.json``).
    length : int
        T, the steps to resample each episode to.
    joints : list of str
        State features, concatenated in this order.
    images : str, optional
        The camera feature (e.g. ``observation.images.top``); None: joints only.
    image_size : (H, W)
        Size of the stored frames.

    Raises
    ------
    UserError
        pyarrow or PyAV is not installed.
    DataError
        A missing file, feature or column (naming the file and the features that exist),
        or bad values or frames (naming the file, the feature and the episode's index).
    """
    root = Path(path)
    parquet = _module("pyarrow.parquet", "pyarrow")
    info = _read_info(root)
    layout = _layout(info, root)
    joints = list(joints) or ["observation.state"]
    for key in joints:
        _feature(info, key, root, joint=True)
    kind = _feature(info, images, root, joint=False)["dtype"] if images else None
    av = _module("av", "PyAV (av)") if kind == "video" else None
    episodes = _episodes(root, info)
    sequences, widths, frames = [], [], AlignedFrames(length, image_size) if images else None
    for i, (episode, _) in enumerate(episodes):
        file = _episode_path(layout, "data_path", episode, root)
        table = _table(parquet, file, joints + ([images] if kind == "image" else []), i)
        columns = [_column(table, key, file, i) for key in joints]
        widths = widths or [c.shape[1] for c in columns]
        sequences.append(np.concatenate(columns, axis=1))
        rows = len(sequences[-1])
        if kind == "video":
            video = _episode_path(layout, "video_path", episode, root, video_key=images)
            frames.add(rows, lambda idx, f=video, n=rows, i=i: _decode_video(av, f, idx, n, images, i))
        elif kind == "image":
            frames.add(rows, lambda idx, t=table, f=file, i=i: _decode_images(t, images, idx, f, i))
    names = _joint_names(info, joints, widths)
    return _dataset(root, layout["dt"], sequences, frames, episodes, length, joints=joints, names=names,
                    images=images)


def _dataset(root, dt_in, sequences, frames, episodes, length, *, joints, names, images) -> MotionDataset:
    """The :class:`MotionDataset` of the episodes read (``dt_in``: ``1 / fps``)."""
    try:
        labels, label_names = _labels(episodes)
    except DataError as exc:
        raise exc.located(path=root) from None
    return demonstrations(
        sequences, length, frames, source=f"lerobot:{root.resolve().name} joints={','.join(joints)}", images=images,
        dt_in=dt_in, where=root, labels=labels, label_names=label_names, joint_names=names,
    )


def is_lerobot_dir(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a directory holding ``meta/info.json`` (for guessing the format)."""
    return (Path(path) / "meta" / "info.json").is_file()


def _module(name: str, package: str):
    """Import ``name``, or say how to install it (one line)."""
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError:
        raise UserError(
            f"reading a LeRobot data set needs {package}, which is not installed: pip install 'primspace[video]'"
        ) from None


def _read_info(root: Path) -> dict:
    file = root / "meta" / "info.json"
    if not root.is_dir():
        raise DataError("not a LeRobot data set directory (no such directory)", path=root)
    if not file.is_file():
        raise DataError("not a LeRobot data set directory (no meta/info.json)", path=root)
    try:
        info = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:  # ValueError: UnicodeDecodeError, JSONDecodeError
        raise DataError(f"cannot be read as JSON ({first_line(exc)})", path=file) from None
    if not isinstance(info, dict) or not isinstance(info.get("features"), dict):
        raise DataError("holds no 'features' object", path=file)
    version = str(info.get("codebase_version", ""))
    if not version.startswith("v2"):
        raise DataError(
            f"codebase_version {version or 'missing'}: only LeRobot v2.x data sets (one parquet file "
            "and one video per episode) are read", path=file, field="codebase_version",
        )
    return info


def _feature(info: dict, key: str, root: Path, *, joint: bool) -> dict:
    """The feature ``key`` of ``info.json``: state values (``joint``) or frames."""
    features = info["features"]
    file = root / "meta" / "info.json"
    if key not in features or not isinstance(features[key], dict):
        raise DataError(f"no feature '{printable(key)}'; features: {', '.join(map(printable, features))}", path=file,
                        field=printable(key))
    dtype = str(features[key].get("dtype"))
    if joint and dtype in _NOT_JOINTS:
        raise DataError(f"is a {printable(dtype)} feature, not joint values", path=file, field=printable(key))
    if not joint and dtype not in ("video", "image"):
        cameras = [k for k, v in features.items() if isinstance(v, dict) and v.get("dtype") in ("video", "image")]
        raise DataError(
            f"is a {printable(dtype)} feature, not camera frames; camera features: "
            f"{', '.join(map(printable, cameras)) or 'none'}", path=file, field=printable(key),
        )
    return features[key]


def _layout(info: dict, root: Path) -> dict:
    """``info.json``'s ``fps`` (as ``dt``, seconds per step), ``chunks_size`` and path templates, checked."""
    file = root / "meta" / "info.json"
    if "fps" not in info:
        raise DataError("missing: a LeRobot data set gives its frames per second", path=file, field="fps")
    chunks = info.get("chunks_size")
    chunks = 1000 if chunks is None else chunks  # LeRobot's default
    if isinstance(chunks, bool) or not isinstance(chunks, int) or chunks < 1:
        raise DataError(f"chunks_size {shown(chunks)} must be a positive whole number (episodes per chunk folder)",
                        path=file, field="chunks_size")
    return {"dt": rate_dt(info["fps"], path=file, field="fps"), "chunks": chunks,
            **{key: _template(info, key, file) for key in _TEMPLATE_FIELDS}}


def _template(info: dict, key: str, file: Path) -> str:
    """The path template ``key`` (LeRobot's default when absent): relative, plain integer fields."""
    value = info.get(key)
    if value is None or value == "":
        return _DEFAULTS[key]
    if not isinstance(value, str):
        raise DataError(f"must be a string (a path template), got {shown(value)}", path=file, field=key)

    def fail(why: str) -> DataError:
        return DataError(f"template {shown(value, 300)} {why}", path=file, field=key)

    if PurePosixPath(value).is_absolute() or PureWindowsPath(value).is_absolute() or PureWindowsPath(value).drive:
        raise fail("is an absolute path; the files of a data set must lie inside its folder")
    try:
        parts = list(string.Formatter().parse(value))
    except ValueError as exc:
        raise fail(f"cannot be parsed ({first_line(exc)})") from None
    allowed = _TEMPLATE_FIELDS[key]
    for _, name, spec, conversion in parts:
        if name is None:
            continue
        integer = name in allowed and name != "video_key"
        if name not in allowed or conversion or not (_INT_SPEC.fullmatch(spec) if integer else spec == ""):
            text = "{" + name + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "") + "}"
            fields = ", ".join("{" + a + "}" for a in allowed)
            raise fail(f"uses {text}; a template may use only {fields}, the integers with a width like :03d")
    return value


def _episode_path(layout: dict, key: str, episode: int, root: Path, **more) -> Path:
    """The file of ``episode`` that template ``key`` names: inside ``root``, symbolic links resolved."""
    template = layout[key]
    relative = template.format(episode_chunk=episode // layout["chunks"], episode_index=episode, **more)
    path = root / relative
    resolved = path.resolve()
    if not resolved.is_relative_to(root.resolve()):
        raise DataError(
            f"template {shown(template, 300)} gives {printable(relative)}, which lies outside the data set folder "
            f"{root} (it resolves to {printable(str(resolved))})", path=root / "meta" / "info.json", field=key,
        )
    return path


def _episodes(root: Path, info: dict) -> list[tuple[int, list]]:
    """``(episode_index, tasks)`` of each episode, in index order; each index once."""
    file = root / "meta" / "episodes.jsonl"
    if not file.is_file():
        total = info.get("total_episodes")
        if isinstance(total, bool) or not isinstance(total, int) or not 1 <= total <= _MAX_EPISODES:
            raise DataError(f"no meta/episodes.jsonl, and total_episodes {shown(total)} in meta/info.json is not "
                            f"a whole number from 1 to {_MAX_EPISODES:,}", path=root)
        return [(e, []) for e in range(total)]
    try:
        lines = file.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot be read ({first_line(exc)})", path=file) from None
    episodes, first = [], {}
    for number, line in enumerate(lines, start=1):
        if line.strip():
            index, tasks = _episode_record(line, number, file)
            if index in first:
                raise DataError(f"line {number}: episode_index {index} is listed twice (first on line "
                                f"{first[index]})", path=file, field="episode_index")
            first[index] = number
            episodes.append((index, tasks))
    if not episodes:
        raise DataError("lists no episodes", path=file)
    return sorted(episodes)


def _episode_record(line: str, number: int, file: Path) -> tuple[int, list]:
    """``(episode_index, tasks)`` of line ``number`` of ``episodes.jsonl``."""
    try:
        record = json.loads(line)
    except ValueError as exc:
        raise DataError(f"line {number}: not an episode record ({first_line(exc)})", path=file) from None
    if not isinstance(record, dict) or "episode_index" not in record:
        raise DataError(f"line {number}: not an episode record (a JSON object with an episode_index)", path=file)
    index, tasks = record["episode_index"], record.get("tasks") or []
    if isinstance(index, bool) or not isinstance(index, int) or index < 0:
        raise DataError(f"line {number}: episode_index {shown(index)} is not a whole number >= 0", path=file,
                        field="episode_index")
    if not isinstance(tasks, list):
        raise DataError(f"line {number}: tasks {shown(tasks)} is not a list of task names", path=file, field="tasks")
    return index, tasks


def _table(parquet, file: Path, columns: list[str], index: int):
    """The episode's table, with the ``columns`` checked."""
    if not file.is_file():
        raise DataError("no such file (episode table)", path=file, index=index)
    import pyarrow

    try:
        table = parquet.read_table(file)
        names = table.column_names  # decoded here: a damaged name is a UnicodeDecodeError
    except (OSError, ValueError, pyarrow.ArrowException) as exc:  # most of pyarrow's subclass the first two
        raise DataError(f"not a readable parquet file ({first_line(exc)})", path=file, index=index) from None
    for key in columns:
        if key not in names:
            columns_there = ", ".join(map(printable, names))
            raise DataError(f"no column '{printable(key)}'; columns: {columns_there}", path=file,
                            field=printable(key), index=index)
    return table


def _column(table, key: str, file: Path, index: int) -> np.ndarray:
    """A state column as ``(rows, d)`` float64 (list cells, or one number per row)."""
    try:
        values = np.array(table.column(key).to_pylist(), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"rows are not lists of numbers of one length ({first_line(exc)})", path=file, field=key,
                        index=index) from None
    if values.ndim == 1:
        values = values[:, None]
    if values.ndim != 2 or values.shape[0] == 0:
        raise DataError(f"must be (rows, d) numbers, got shape {values.shape}", path=file, field=key, index=index)
    return values


def _decode_video(av, file: Path, wanted: np.ndarray, n_rows: int, key: str, index: int) -> np.ndarray:
    """Decode the whole video (to count its frames); keep the frames at ``wanted``."""
    if not file.is_file():
        raise DataError("no such file (episode video)", path=file, field=key, index=index)
    keep, picked, count = set(int(w) for w in wanted), {}, 0
    try:
        with av.open(str(file)) as container:
            if not container.streams.video:
                raise DataError("holds no video stream", path=file, field=key, index=index)
            for frame in container.decode(video=0):
                if count in keep:
                    picked[count] = frame.to_ndarray(format="rgb24")
                count += 1
    except (av.error.FFmpegError, OSError, ValueError) as exc:
        raise DataError(f"cannot be decoded ({first_line(exc)})", path=file, field=key, index=index) from None
    if count != n_rows:
        raise DataError(
            f"{count} frames for {n_rows} rows of the episode's table (one frame per row is needed)",
            path=file, field=key, index=index,
        )
    return np.stack([picked[int(w)] for w in wanted])


def _decode_images(table, key: str, wanted: np.ndarray, file: Path, index: int) -> np.ndarray:
    """Frames of an ``image`` feature: encoded bytes in the table, decoded with Pillow."""
    from PIL import Image, UnidentifiedImageError

    cells = table.column(key).to_pylist()
    out = []
    for w in wanted:
        cell = cells[int(w)]
        data = cell.get("bytes") if isinstance(cell, dict) else cell
        try:
            with Image.open(io.BytesIO(data)) as image:
                out.append(np.asarray(image.convert("RGB")))
        except (TypeError, OSError, UnidentifiedImageError) as exc:
            raise DataError(f"row {int(w)}: not an encoded image ({first_line(exc)})", path=file, field=key,
                            index=index) from None
    if len({a.shape for a in out}) > 1:
        raise DataError("frames of different sizes in one episode", path=file, field=key, index=index)
    return np.stack(out)


def _joint_names(info: dict, joints: list[str], widths: list[int]) -> list[str]:
    """Names from each feature's ``names`` when they fit its width, else ``<key>_<j>``;
    prefixed with the key (``<key>.<name>``) if two features share a name."""
    names, given_names = [], []
    for key, width in zip(joints, widths):
        given = info["features"][key].get("names")
        if isinstance(given, dict) and len(given) == 1:  # {"motors": [...]}
            given = next(iter(given.values()))
        fits = isinstance(given, list) and len(given) == width and all(isinstance(g, str) for g in given)
        own = list(given) if fits else [key] if width == 1 else [f"{key}_{j}" for j in range(width)]
        names.extend(own)
        given_names.extend(f"{key}.{g}" if fits else g for g in own)
    return names if len(set(names)) == len(names) else given_names


def _labels(episodes: list[tuple[int, list]]):
    """Each episode's one task as its label (names sorted); None unless every episode has one."""
    if not episodes or any(len(tasks) != 1 for _, tasks in episodes):
        return None, None
    names = sorted({str(tasks[0]) for _, tasks in episodes})
    return np.array([names.index(str(tasks[0])) for _, tasks in episodes], dtype=np.int32), names
