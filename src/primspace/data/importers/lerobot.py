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

Needs pyarrow and PyAV, the ``video`` extra: ``pip install 'primspace[video]'``.
Version 3 data sets (many episodes per file) are refused with a message.
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import demonstrations
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames
from primspace.errors import DataError, UserError, first_line

__all__ = ["import_lerobot", "is_lerobot_dir"]

_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
_VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
_NOT_JOINTS = ("video", "image", "string")


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
    joints = list(joints) or ["observation.state"]
    for key in joints:
        _feature(info, key, root, joint=True)
    kind = _feature(info, images, root, joint=False)["dtype"] if images else None
    av = _module("av", "PyAV (av)") if kind == "video" else None
    episodes = _episodes(root, info)
    sequences, widths, frames = [], [], AlignedFrames(length, image_size) if images else None
    for i, (episode, _) in enumerate(episodes):
        file = root / _episode_path(info, "data_path", _DATA_PATH, episode, root)
        table = _table(parquet, file, joints + ([images] if kind == "image" else []), i)
        columns = [_column(table, key, file, i) for key in joints]
        widths = widths or [c.shape[1] for c in columns]
        sequences.append(np.concatenate(columns, axis=1))
        rows = len(sequences[-1])
        if kind == "video":
            video = root / _episode_path(info, "video_path", _VIDEO_PATH, episode, root, video_key=images)
            frames.add(rows, lambda idx, f=video, n=rows, i=i: _decode_video(av, f, idx, n, images, i))
        elif kind == "image":
            frames.add(rows, lambda idx, t=table, f=file, i=i: _decode_images(t, images, idx, f, i))
    names = _joint_names(info, joints, widths)
    return _dataset(root, info, sequences, frames, episodes, length, joints=joints, names=names, images=images)


def _dataset(root, info, sequences, frames, episodes, length, *, joints, names, images) -> MotionDataset:
    """The :class:`MotionDataset` of the episodes read."""
    fps = info.get("fps")
    dt_in = 1.0 / float(fps) if isinstance(fps, (int, float)) and fps > 0 else 1.0
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
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
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
        raise DataError(f"no feature '{key}'; features: {', '.join(features)}", path=file, field=key)
    dtype = str(features[key].get("dtype"))
    if joint and dtype in _NOT_JOINTS:
        raise DataError(f"is a {dtype} feature, not joint values", path=file, field=key)
    if not joint and dtype not in ("video", "image"):
        cameras = [k for k, v in features.items() if isinstance(v, dict) and v.get("dtype") in ("video", "image")]
        raise DataError(
            f"is a {dtype} feature, not camera frames; camera features: {', '.join(cameras) or 'none'}",
            path=file, field=key,
        )
    return features[key]


def _episodes(root: Path, info: dict) -> list[tuple[int, list]]:
    """``(episode_index, tasks)`` of each episode, in index order."""
    file = root / "meta" / "episodes.jsonl"
    if not file.is_file():
        total = info.get("total_episodes")
        if not isinstance(total, int) or total < 1:
            raise DataError("no meta/episodes.jsonl and no positive 'total_episodes' in meta/info.json", path=root)
        return [(e, []) for e in range(total)]
    episodes, number = [], 0
    try:
        for number, line in enumerate(file.read_text(encoding="utf-8").splitlines(), start=1):
            if line.strip():
                record = json.loads(line)
                episodes.append((int(record["episode_index"]), list(record.get("tasks") or [])))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise DataError(f"line {number}: not an episode record ({first_line(exc)})", path=file) from None
    if not episodes:
        raise DataError("lists no episodes", path=file)
    return sorted(episodes)


def _episode_path(info: dict, template_key: str, default: str, episode: int, root: Path, **more) -> str:
    chunk = episode // int(info.get("chunks_size") or 1000)
    try:
        return str(info.get(template_key) or default).format(episode_chunk=chunk, episode_index=episode, **more)
    except (KeyError, IndexError, ValueError) as exc:
        raise DataError(f"cannot fill in the template ({first_line(exc)})", path=root / "meta" / "info.json",
                        field=template_key) from None


def _table(parquet, file: Path, columns: list[str], index: int):
    """The episode's table, with the ``columns`` checked."""
    if not file.is_file():
        raise DataError("no such file (episode table)", path=file, index=index)
    try:
        table = parquet.read_table(file)
    except (OSError, ValueError) as exc:  # pyarrow's errors subclass these
        raise DataError(f"not a readable parquet file ({first_line(exc)})", path=file, index=index) from None
    for key in columns:
        if key not in table.column_names:
            raise DataError(f"no column '{key}'; columns: {', '.join(table.column_names)}", path=file, field=key,
                            index=index)
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
