"""Import a LeRobot data set directory, format v3.0 or v2.x: parquet tables and videos.

Two layouts, one reader. **v3.0** (LeRobot >= 0.4) keeps many episodes per file::

    meta/info.json        codebase_version "v3.0", fps, chunks_size, features, and the templates
                          data_path  "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
                          video_path "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    meta/episodes/chunk-000/file-000.parquet   one row per episode: episode_index, tasks, length,
                          data/chunk_index, data/file_index, dataset_from_index, dataset_to_index,
                          videos/<camera>/chunk_index, .../file_index, .../from_timestamp, .../to_timestamp
    meta/tasks.parquet    task names and their task_index
    data/chunk-000/file-000.parquet            rows of several episodes: index (the row's place in
                          the data set), episode_index, frame_index, timestamp, task_index, features
    videos/observation.images.top/chunk-000/file-000.mp4   several episodes, one after the other

An episode's rows are those of its data file whose ``index`` lies in
``[dataset_from_index, dataset_to_index)``; its frames lie in its video file between
``from_timestamp`` and ``to_timestamp``. **v2.x** (v2.0, v2.1) keeps one table and one
video per episode, listed in ``meta/episodes.jsonl`` (``{"episode_index": 0, "tasks": [...],
"length": T_0}``; without it, ``0 .. total_episodes - 1``), in the files that the templates
``data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet`` and
``videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4`` name, with
``episode_chunk = episode_index // chunks_size``.

Frames by timestamp, in both: row ``r``'s frame is the decoded frame nearest in time to
``from_timestamp + timestamp_r`` (``from_timestamp`` is 0 in v2.x; without a ``timestamp``
column, ``frame_index / fps``), and it must lie within half a frame period (``0.5 / fps``),
else the import stops naming the file, camera, episode, row and times
(:mod:`~primspace.data.importers.lerobot_video`). So a video with one frame more than its
table has rows imports. Frames come from a ``video`` feature (decoded with PyAV, whose wheel
reads AV1, LeRobot's default codec, H.264 and MPEG-4) or an ``image`` feature (PNG/JPEG
bytes in the table); they are aligned with the resampled joints and fitted to the frame
size as :mod:`primspace.data.importers.frames` says, and only the rows picked are decoded.

Episodes are read in index order, all of them or those ``episodes`` names (``--episodes
0,3,10-20``: :func:`parse_episodes`); an index the data set lacks is refused, naming the
indices it has. Joints are the state features named (default ``observation.state``),
concatenated in order; their names come from the feature's ``names`` when they fit, else
``<key>_<j>``. ``dt`` is ``1 / fps`` per input step; an episode's single task (its
``tasks``; in v3.0 without them, its rows' ``task_index`` in ``meta/tasks.parquet``) becomes
its label. Each sample keeps its origin, ``lerobot:<folder>:episode <index>``
(``source_ids``).

What a data set names stays inside its folder: the templates may use only their version's
fields (``{chunk_index}``, ``{file_index}`` in v3.0; ``{episode_chunk}``,
``{episode_index}`` in v2.x: integers with a width like ``:03d``; in ``video_path`` also
``{video_key}``); an absolute template, or a file that resolves outside the folder (``..``,
a symbolic link), is refused. So are ``fps`` that is not a positive finite rate,
``chunks_size`` that is not a positive integer, an episode index that is not a whole number
or is listed twice, and row or time ranges that do not fit the files.

Needs pyarrow and PyAV, the ``video`` extra: ``pip install 'primspace[video]'``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.importers.common import demonstrations, printable
from primspace.data.importers.frames import DEFAULT_IMAGE_SIZE, AlignedFrames
from primspace.data.importers.lerobot_meta import (
    episode_file,
    episodes_v2,
    episodes_v3,
    feature,
    index_ranges,
    layout,
    parse_episodes,
    read_info,
    read_parquet,
    select_episodes,
    task_names,
)
from primspace.data.importers.lerobot_video import table_images, video_frames
from primspace.utils.errors import DataError, UserError, first_line

__all__ = ["import_lerobot", "is_lerobot_dir", "parse_episodes"]

_ROW_COLUMNS = ("episode_index", "timestamp", "frame_index", "task_index")  # read when there


def import_lerobot(
    path: str | os.PathLike,
    length: int,
    *,
    joints: Sequence[str] = ("observation.state",),
    images: str | None = None,
    image_size=DEFAULT_IMAGE_SIZE,
    image_fit: str = "crop",
    episodes: Sequence[int] | None = None,
) -> MotionDataset:
    """Read joints (and frames) of the episodes of a LeRobot v3.0 or v2.x data set directory.

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
    image_fit : {"crop", "pad", "stretch"}
        How a frame of another aspect ratio is fitted (:mod:`~primspace.data.importers.frames`).
    episodes : sequence of int or str, optional
        The episode indices to read (None: all), or text such as ``"0,3,10-20"``
        (:func:`parse_episodes`); read in the data set's order, each once.

    Raises
    ------
    UserError
        pyarrow or PyAV is not installed.
    DataError
        A missing file, feature or column (naming the file and the features that exist),
        an episode the data set lacks, or bad values or frames (naming the file, the
        feature, the episode's index and the row).
    """
    root = Path(path)
    parquet = _module("pyarrow.parquet", "pyarrow")
    info = read_info(root)
    shape = layout(info, root)
    joints = list(joints) or ["observation.state"]
    for key in joints:
        feature(info, key, root, joint=True)
    kind = feature(info, images, root, joint=False)["dtype"] if images else None
    av = _module("av", "PyAV (av)") if kind == "video" else None
    camera = images if kind == "video" else None
    listed = episodes_v3(root, parquet, camera) if shape["version"] == 3 else episodes_v2(root, info, shape, camera)
    chosen = select_episodes(listed, episodes, root)
    reader = _Reader(root, parquet, shape, joints, images if kind == "image" else None)
    frames = AlignedFrames(length, image_size, image_fit) if images else None
    sequences, tasks = [], []
    for i, episode in enumerate(chosen):
        rows, file = reader.rows(episode, i)
        sequences.append(reader.joints(rows, file, episode, i))
        tasks.append(episode.tasks or reader.row_tasks(rows))
        n = len(sequences[-1])
        if kind == "video":
            video = episode_file(shape, "video_path", episode.video, root)
            times = reader.times(rows, file, episode, i)
            frames.add(
                n, lambda idx, f=video, e=episode, t=times, i=i: video_frames(av, f, images, e, t, idx, shape["fps"], i)
            )
        elif kind == "image":
            frames.add(n, lambda idx, r=rows, f=file, e=episode.index, i=i: table_images(r, images, idx, f, e, i))
    source = f"lerobot:{root.resolve().name} joints={','.join(joints)}"
    if episodes is not None:
        source += f" episodes={index_ranges([e.index for e in chosen], 20, sep=',')}"
    return _dataset(
        root,
        shape["dt"],
        sequences,
        frames,
        tasks,
        length,
        source=source,
        images=images,
        names=_joint_names(info, joints, reader.widths),
        ids=[f"lerobot:{root.resolve().name}:episode {e.index}" for e in chosen],
    )


def _dataset(root, dt_in, sequences, frames, tasks, length, *, source, images, names, ids) -> MotionDataset:
    """The :class:`MotionDataset` of the episodes read (``dt_in``: ``1 / fps``)."""
    labels, label_names = _labels(tasks)
    return demonstrations(
        sequences,
        length,
        frames,
        source=source,
        images=images,
        dt_in=dt_in,
        where=root,
        labels=labels,
        label_names=label_names,
        joint_names=names,
        source_ids=ids,
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


class _Reader:
    """The rows of each episode from the data files (each file read once while its episodes
    come one after another), their joints, times and tasks."""

    def __init__(self, root: Path, parquet, shape: dict, joints: list[str], image_key: str | None) -> None:
        self.root, self.parquet, self.shape, self.keys = root, parquet, shape, joints
        self.columns = joints + ([image_key] if image_key else [])
        self.widths: list[int] = []
        self._file = self._table = self._order = None
        self._tasks: dict | None = None

    def rows(self, episode, sample: int):
        """``(rows, file)``: the episode's rows (a pyarrow table, in ``index`` order) and its data file."""
        file = episode_file(self.shape, "data_path", episode.data, self.root)
        if file != self._file:
            required = self.columns + (["index"] if episode.rows is not None else [])
            try:
                table = read_parquet(self.parquet, file, required, _ROW_COLUMNS, index=sample, what="episode table")
            except DataError as exc:
                raise DataError(
                    f"episode {episode.index}: {exc.reason}", path=exc.path, field=exc.field, index=sample
                ) from None
            self._file, self._table, self._order = file, table, None
        if episode.rows is None:
            return self._table, file
        rows = self._table.take(self._positions(episode, file, sample))
        if "episode_index" in rows.column_names:
            found = _integers(rows, "episode_index", file, episode, sample)
            if (found != episode.index).any():
                r = int(np.flatnonzero(found != episode.index)[0])
                raise DataError(
                    f"episode {episode.index}: row {r} of its rows (index {episode.rows[0] + r}) has "
                    f"episode_index {found[r]}",
                    path=file,
                    field="episode_index",
                    index=sample,
                )
        return rows, file

    def _positions(self, episode, file: Path, sample: int) -> np.ndarray:
        """Where in the data file the rows with ``index`` in the episode's ``[from, to)`` lie, in order."""
        if self._order is None:
            index = _integers(self._table, "index", file, episode, sample)
            order = np.argsort(index, kind="stable")
            self._order = (index[order], order)
        ordered, order = self._order
        low, high = episode.rows
        a, b = np.searchsorted(ordered, [low, high])
        if b - a != high - low or not np.array_equal(ordered[a:b], np.arange(low, high)):
            raise DataError(
                f"episode {episode.index}: its rows, index {low} to {high - 1} (dataset_from_index, dataset_to_index "
                f"in {printable(str(episode.meta.relative_to(self.root)))}), are not each once in the file: "
                f"{b - a} rows there have an index in that range",
                path=file,
                field="index",
                index=sample,
            )
        return order[a:b]

    def joints(self, rows, file: Path, episode, sample: int) -> np.ndarray:
        """The episode's joints, ``(rows, J)``: the state columns concatenated in order."""
        columns = [_column(rows, key, file, episode, sample) for key in self.keys]
        widths = [c.shape[1] for c in columns]
        self.widths = self.widths or widths
        if widths != self.widths:
            raise DataError(
                f"episode {episode.index}: {widths} values per row in {', '.join(self.keys)}; the first "
                f"episode read has {self.widths}",
                path=file,
                field=printable(self.keys[0]),
                index=sample,
            )
        return np.concatenate(columns, axis=1)

    def times(self, rows, file: Path, episode, sample: int) -> np.ndarray:
        """Each row's time in the episode, seconds: ``timestamp``, else ``frame_index / fps``, else ``row / fps``."""
        names = rows.column_names
        key = "timestamp" if "timestamp" in names else "frame_index" if "frame_index" in names else None
        if key is None:
            return np.arange(rows.num_rows) / self.shape["fps"]
        values = _column(rows, key, file, episode, sample)
        if values.shape[1] != 1 or not np.isfinite(values).all():
            bad = 0 if values.shape[1] != 1 else int(np.flatnonzero(~np.isfinite(values[:, 0]))[0])
            raise DataError(
                f"episode {episode.index}: row {bad}: {key} {values[bad].tolist()} is not a time",
                path=file,
                field=key,
                index=sample,
            )
        back = np.flatnonzero(np.diff(values[:, 0]) < 0)
        if back.size:  # frames are taken nearest in time: a clock that runs back would reorder them
            r = int(back[0]) + 1
            raise DataError(
                f"episode {episode.index}: row {r}: {key} {float(values[r, 0]):g} runs back from "
                f"{float(values[r - 1, 0]):g}",
                path=file,
                field=key,
                index=sample,
            )
        return values[:, 0] if key == "timestamp" else values[:, 0] / self.shape["fps"]

    def row_tasks(self, rows) -> tuple:
        """The tasks of rows' ``task_index`` named in ``meta/tasks.parquet`` (v3.0), for an
        episode whose metadata lists no tasks."""
        if self.shape["version"] != 3 or "task_index" not in rows.column_names:
            return ()
        if self._tasks is None:
            self._tasks = task_names(self.root, self.parquet)
        found = {t for t in rows.column("task_index").to_pylist() if t in self._tasks}
        return tuple(self._tasks[t] for t in sorted(found))


def _integers(table, key: str, file: Path, episode, sample: int) -> np.ndarray:
    """A column of whole numbers as an int64 array."""
    import pyarrow

    def fail(why: str) -> DataError:
        return DataError(
            f"episode {episode.index}: the column must hold whole numbers, one per row ({why})",
            path=file,
            field=key,
            index=sample,
        )

    try:
        values = np.asarray(table.column(key).to_numpy())
    except (pyarrow.ArrowException, ValueError, TypeError) as exc:
        raise fail(first_line(exc)) from None
    if values.dtype.kind not in "iu" or values.ndim != 1:
        raise fail(f"found {values.dtype}")
    return values.astype(np.int64)


def _column(table, key: str, file: Path, episode, sample: int) -> np.ndarray:
    """A column as ``(rows, d)`` float64 (list cells, or one number per row)."""
    try:
        values = np.array(table.column(key).to_pylist(), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(
            f"episode {episode.index}: rows are not lists of numbers of one length ({first_line(exc)})",
            path=file,
            field=printable(key),
            index=sample,
        ) from None
    if values.ndim == 1:
        values = values[:, None]
    if values.ndim != 2 or values.shape[0] == 0:
        raise DataError(
            f"episode {episode.index}: must be (rows, d) numbers, got shape {values.shape}",
            path=file,
            field=printable(key),
            index=sample,
        )
    return values


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


def _labels(tasks: list[tuple]):
    """Each episode's one task as its label (names sorted); None unless every episode has one."""
    if not tasks or any(len(t) != 1 for t in tasks):
        return None, None
    names = sorted({str(t[0]) for t in tasks})
    return np.array([names.index(str(t[0])) for t in tasks], dtype=np.int32), names
