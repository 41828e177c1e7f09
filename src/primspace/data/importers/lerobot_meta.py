"""The metadata of a LeRobot data set: ``meta/info.json``, the path templates, the episodes.

Two front ends give the reader (:mod:`primspace.data.importers.lerobot`) the same list of
:class:`Episode` records: :func:`episodes_v2` reads ``meta/episodes.jsonl`` (v2.x, one
table and one video per episode), :func:`episodes_v3` the tables under ``meta/episodes``
(v3.0, many episodes per file, located by chunk and file index, rows by ``index`` range,
video by ``from_timestamp``). Every file a template names is checked to lie inside the
data set's folder (symbolic links resolved) before it is read.
"""

from __future__ import annotations

import json
import math
import re
import string
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np

from primspace.data.importers.common import printable, rate_dt, shown
from primspace.utils.errors import DataError, UserError, first_line

__all__ = [
    "Episode",
    "read_info",
    "layout",
    "feature",
    "episode_file",
    "episodes_v2",
    "episodes_v3",
    "task_names",
    "select_episodes",
    "parse_episodes",
    "index_ranges",
    "read_parquet",
    "inside",
]

_NOT_JOINTS = ("video", "image", "string")
# per version: each template's default and the fields it may use (the integers take a width only, ":03d")
_TEMPLATES = {
    2: {
        "data_path": (
            "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
            ("episode_chunk", "episode_index"),
        ),
        "video_path": (
            "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4",
            ("episode_chunk", "episode_index", "video_key"),
        ),
    },
    3: {
        "data_path": ("data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet", ("chunk_index", "file_index")),
        "video_path": (
            "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4",
            ("chunk_index", "file_index", "video_key"),
        ),
    },
}
_INT_SPEC = re.compile(r"(0?[1-9][0-9]?)?d?")
_MAX_EPISODES = 1_000_000  # more episodes than this is damage (or a typo), not a data set
_MAX_INDEX = 10**12  # a chunk, file or row index beyond this is damage
# the columns of meta/episodes (v3.0) a reader needs; per camera, videos/<key>/ + these
_V3_COLUMNS = ("episode_index", "data/chunk_index", "data/file_index", "dataset_from_index", "dataset_to_index")
_V3_VIDEO = ("chunk_index", "file_index", "from_timestamp", "to_timestamp")


@dataclass(frozen=True)
class Episode:
    """One episode, as the metadata of either version describes it.

    ``data`` and ``video`` are the fields of the ``data_path`` / ``video_path`` templates;
    ``rows`` the ``[from, to)`` range of the data file's ``index`` column (v3.0; None: the
    whole file); ``start``, ``end`` the episode's span in its video file in seconds (v3.0's
    ``from_timestamp``, ``to_timestamp``; v2.x: 0 and None, the whole video). ``row`` is
    where the metadata lists it (a line of episodes.jsonl, a row of meta/episodes), ``meta``
    that file.
    """

    index: int
    tasks: tuple
    data: dict
    video: dict | None = None
    rows: tuple[int, int] | None = None
    start: float = 0.0
    end: float | None = None
    meta: Path | None = None


def read_info(root: Path) -> dict:
    """``meta/info.json``, with its ``codebase_version`` checked (v2.x or v3.0)."""
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
    version = info.get("codebase_version")
    if not (isinstance(version, str) and (version.startswith("v2.") or version == "v3.0")):
        raise DataError(
            f"codebase_version {shown(version) if version is not None else 'missing'}: only LeRobot "
            "v2.x and v3.0 data sets are read",
            path=file,
            field="codebase_version",
        )
    return info


def layout(info: dict, root: Path) -> dict:
    """The version (2 or 3), ``fps`` and ``dt`` (seconds per step), ``chunks_size`` and the
    path templates of ``info.json``, checked."""
    file = root / "meta" / "info.json"
    if "fps" not in info:
        raise DataError("missing: a LeRobot data set gives its frames per second", path=file, field="fps")
    chunks = info.get("chunks_size")
    chunks = 1000 if chunks is None else chunks  # LeRobot's default
    if isinstance(chunks, bool) or not isinstance(chunks, int) or chunks < 1:
        raise DataError(
            f"chunks_size {shown(chunks)} must be a positive whole number (files per chunk folder)",
            path=file,
            field="chunks_size",
        )
    version = 3 if info["codebase_version"] == "v3.0" else 2
    dt = rate_dt(info["fps"], path=file, field="fps")
    return {
        "version": version,
        "dt": dt,
        "fps": 1.0 / dt,
        "chunks": chunks,
        **{key: _template(info, key, file, version) for key in ("data_path", "video_path")},
    }


def _template(info: dict, key: str, file: Path, version: int) -> str:
    """The path template ``key`` (LeRobot's default when absent): relative, plain integer fields."""
    default, allowed = _TEMPLATES[version][key]
    value = info.get(key)
    if value is None or value == "":
        return default
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
    for _, name, spec, conversion in parts:
        if name is None:
            continue
        integer = name in allowed and name != "video_key"
        if name not in allowed or conversion or not (_INT_SPEC.fullmatch(spec) if integer else spec == ""):
            text = "{" + name + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "") + "}"
            fields = ", ".join("{" + a + "}" for a in allowed)
            raise fail(f"uses {text}; a v{version} template may use only {fields}, the integers with a width like :03d")
    return value


def feature(info: dict, key: str, root: Path, *, joint: bool) -> dict:
    """The feature ``key`` of ``info.json``: state values (``joint``) or frames."""
    features = info["features"]
    file = root / "meta" / "info.json"
    if key not in features or not isinstance(features[key], dict):
        raise DataError(
            f"no feature '{printable(key)}'; features: {', '.join(map(printable, features))}",
            path=file,
            field=printable(key),
        )
    dtype = str(features[key].get("dtype"))
    if joint and dtype in _NOT_JOINTS:
        raise DataError(f"is a {printable(dtype)} feature, not joint values", path=file, field=printable(key))
    if not joint and dtype not in ("video", "image"):
        cameras = [k for k, v in features.items() if isinstance(v, dict) and v.get("dtype") in ("video", "image")]
        raise DataError(
            f"is a {printable(dtype)} feature, not camera frames; camera features: "
            f"{', '.join(map(printable, cameras)) or 'none'}",
            path=file,
            field=printable(key),
        )
    return features[key]


def inside(root: Path, path: Path, *, what: str, field: str, source: Path | None = None) -> Path:
    """``path`` if it resolves (symbolic links followed) inside ``root``; else a :class:`DataError`
    located at ``source`` (default ``meta/info.json``) and ``field``, saying that ``what`` gives it."""
    resolved = path.resolve()
    if not resolved.is_relative_to(root.resolve()):
        shown_path = path.relative_to(root) if path.is_relative_to(root) else path
        raise DataError(
            f"{what} gives {printable(str(shown_path))}, which lies outside the data set folder {root} "
            f"(it resolves to {printable(str(resolved))})",
            path=source or root / "meta" / "info.json",
            field=field,
        )
    return path


def episode_file(layout_: dict, key: str, fields: dict, root: Path) -> Path:
    """The file that template ``key`` (``data_path``, ``video_path``) names for ``fields``:
    inside ``root``, symbolic links resolved."""
    template = layout_[key]
    relative = template.format(**fields)
    return inside(root, root / relative, what=f"template {shown(template, 300)}", field=key)


# ------------------------------------------------------------------------------- v2.x


def episodes_v2(root: Path, info: dict, layout_: dict, camera: str | None) -> list[Episode]:
    """The episodes of ``meta/episodes.jsonl`` (else ``0 .. total_episodes - 1``), in index order."""
    file = root / "meta" / "episodes.jsonl"
    if not file.is_file():
        total = info.get("total_episodes")
        if isinstance(total, bool) or not isinstance(total, int) or not 1 <= total <= _MAX_EPISODES:
            raise DataError(
                f"no meta/episodes.jsonl, and total_episodes {shown(total)} in meta/info.json is not "
                f"a whole number from 1 to {_MAX_EPISODES:,}",
                path=root,
            )
        records = [(e, [], None) for e in range(total)]
    else:
        records = _jsonl_records(file)
    episodes = []
    for index, tasks, meta in records:
        data = {"episode_chunk": index // layout_["chunks"], "episode_index": index}
        video = None if camera is None else dict(data, video_key=camera)
        episodes.append(Episode(index, tuple(tasks), data, video, meta=meta))
    return episodes


def _jsonl_records(file: Path) -> list[tuple[int, list, Path]]:
    """``(episode_index, tasks, file)`` of each line of ``episodes.jsonl``, in index order; each index once."""
    try:
        lines = file.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot be read ({first_line(exc)})", path=file) from None
    records, first = [], {}
    for number, line in enumerate(lines, start=1):
        if line.strip():
            index, tasks = _jsonl_record(line, number, file)
            if index in first:
                raise DataError(
                    f"line {number}: episode_index {index} is listed twice (first on line {first[index]})",
                    path=file,
                    field="episode_index",
                )
            first[index] = number
            records.append((index, tasks, file))
    if not records:
        raise DataError("lists no episodes", path=file)
    return sorted(records, key=lambda r: r[0])


def _jsonl_record(line: str, number: int, file: Path) -> tuple[int, list]:
    """``(episode_index, tasks)`` of line ``number`` of ``episodes.jsonl``."""
    try:
        record = json.loads(line)
    except ValueError as exc:
        raise DataError(f"line {number}: not an episode record ({first_line(exc)})", path=file) from None
    if not isinstance(record, dict) or "episode_index" not in record:
        raise DataError(f"line {number}: not an episode record (a JSON object with an episode_index)", path=file)
    index, tasks = record["episode_index"], record.get("tasks") or []
    if isinstance(index, bool) or not isinstance(index, int) or index < 0:
        raise DataError(
            f"line {number}: episode_index {shown(index)} is not a whole number >= 0", path=file, field="episode_index"
        )
    if not isinstance(tasks, list):
        raise DataError(f"line {number}: tasks {shown(tasks)} is not a list of task names", path=file, field="tasks")
    return index, tasks


# ------------------------------------------------------------------------------- v3.0


def read_parquet(parquet, file: Path, required, optional=(), *, index=None, what="table"):
    """The columns ``required`` (all) and ``optional`` (those there) of a parquet file.

    Raises
    ------
    DataError
        No such file, not a readable parquet file, or a required column missing (naming
        the columns there, the first 12).
    """
    import pyarrow

    if not file.is_file():
        raise DataError(f"no such file ({what})", path=file, index=index)
    try:
        names = parquet.read_schema(file).names  # decoded here: a damaged name is a UnicodeDecodeError
        for key in required:
            if key not in names:
                there = [printable(n) for n in names if not n.startswith("stats/")]
                listing = ", ".join(there[:12]) + (", ..." if len(there) > 12 else "")
                raise DataError(
                    f"no column '{printable(key)}'; columns: {listing}", path=file, field=printable(key), index=index
                )
        columns = list(dict.fromkeys([*required, *(k for k in optional if k in names)]))
        return parquet.read_table(file, columns=columns)
    except DataError:
        raise
    except (OSError, ValueError, pyarrow.ArrowException) as exc:  # ValueError: a name that is not UTF-8
        raise DataError(f"not a readable parquet file ({first_line(exc)})", path=file, index=index) from None


def episodes_v3(root: Path, parquet, camera: str | None) -> list[Episode]:
    """The episodes of the tables ``meta/episodes/chunk-*/file-*.parquet``, in index order; each index once."""
    folder = root / "meta" / "episodes"
    files = sorted(folder.glob("*/*.parquet")) if folder.is_dir() else []
    if not files:
        raise DataError(
            "no meta/episodes/chunk-*/file-*.parquet: a LeRobot v3.0 data set lists its episodes there", path=root
        )
    episodes, first = [], {}
    for file in files:
        inside(root, file, what="the folder meta/episodes", field="episodes", source=file)
        for episode in _episodes_file(parquet, file, camera):
            if episode.index in first:
                was = first[episode.index].meta
                where = "this file" if was == file else printable(str(was.relative_to(root)))
                raise DataError(
                    f"episode_index {episode.index} is listed twice (also in {where})", path=file, field="episode_index"
                )
            first[episode.index] = episode
            episodes.append(episode)
    if not episodes:
        raise DataError("the tables there list no episodes", path=folder)
    return sorted(episodes, key=lambda e: e.index)


def _episodes_file(parquet, file: Path, video_key: str | None) -> list[Episode]:
    """The episodes one ``meta/episodes`` table lists (``video_key``: the camera whose video is read)."""
    import pyarrow

    video = [f"videos/{video_key}/{c}" for c in _V3_VIDEO] if video_key else []
    table = read_parquet(parquet, file, [*_V3_COLUMNS, *video], ["tasks"], what="episode metadata")
    try:
        columns = {name: table.column(name).to_pylist() for name in table.column_names}
    except (pyarrow.ArrowException, ValueError, TypeError) as exc:
        raise DataError(f"not a readable parquet file ({first_line(exc)})", path=file) from None
    episodes = []
    for row in range(table.num_rows):

        def value(name: str, time: bool = False, row=row):
            return _number(columns[name][row], time, file, name, row)

        index, rows = value("episode_index"), (value("dataset_from_index"), value("dataset_to_index"))
        data = {"chunk_index": value("data/chunk_index"), "file_index": value("data/file_index")}
        _after(rows, ("dataset_from_index", "dataset_to_index"), file, row)
        where, start, end = None, 0.0, None
        if video_key:
            key = f"videos/{video_key}/"
            where = {
                "video_key": video_key,
                "chunk_index": value(key + "chunk_index"),
                "file_index": value(key + "file_index"),
            }
            start, end = value(key + "from_timestamp", True), value(key + "to_timestamp", True)
            _after((start, end), (key + "from_timestamp", key + "to_timestamp"), file, row)
        tasks = _tasks(columns["tasks"][row] if "tasks" in columns else None, file, row)
        episodes.append(
            Episode(index, tasks, data, where, rows, float(start), None if end is None else float(end), meta=file)
        )
    return episodes


def _number(value, time: bool, file: Path, name: str, row: int):
    """A whole number >= 0 (an index), or a time in seconds >= 0 (``time``), read from row ``row``."""
    number = isinstance(value, int) and not isinstance(value, bool)
    if time and isinstance(value, float):
        number = math.isfinite(value)
    if not number or not 0 <= value <= _MAX_INDEX:
        what = "a time in seconds >= 0" if time else "a whole number >= 0"
        raise DataError(f"row {row}: {printable(name)} {shown(value)} is not {what}", path=file, field=printable(name))
    return value


def _after(pair, names, file: Path, row: int) -> None:
    """Refuse a range whose end does not come after its start."""
    if pair[1] <= pair[0]:
        raise DataError(
            f"row {row}: {printable(names[1])} {pair[1]} does not come after {printable(names[0])} "
            f"{pair[0]} (an episode has at least one frame)",
            path=file,
            field=printable(names[1]),
        )


def _tasks(tasks, file: Path, row: int) -> tuple:
    """A row's ``tasks``: a list of task names (None: none)."""
    if tasks is None:
        return ()
    if not isinstance(tasks, list):
        raise DataError(f"row {row}: tasks {shown(tasks)} is not a list of task names", path=file, field="tasks")
    return tuple(str(t) for t in tasks)


def task_names(root: Path, parquet) -> dict[int, str]:
    """``meta/tasks.parquet`` (v3.0) as ``{task_index: task}``; empty when there is no such file."""
    import pyarrow

    file = root / "meta" / "tasks.parquet"
    if not file.is_file():
        return {}
    inside(root, file, what="meta/tasks.parquet", field="tasks", source=file)
    table = read_parquet(parquet, file, ["task_index"], ["task", "__index_level_0__"], what="task names")
    name = next((n for n in ("task", "__index_level_0__") if n in table.column_names), None)
    if name is None:
        raise DataError("no column 'task' (the task names)", path=file, field="task")
    try:
        pairs = zip(table.column("task_index").to_pylist(), table.column(name).to_pylist())
        return {_number(i, False, file, "task_index", row): str(task) for row, (i, task) in enumerate(pairs)}
    except (pyarrow.ArrowException, TypeError) as exc:
        raise DataError(f"not a readable parquet file ({first_line(exc)})", path=file) from None


# -------------------------------------------------------------------- episode selection


def parse_episodes(text: str) -> list[int]:
    """The episode indices of ``--episodes`` text such as ``0,3,10-20``: sorted, each once.

    Raises
    ------
    UserError
        Text that is not comma-separated indices and ``a-b`` ranges (``b >= a``), or more
        than a million episodes.
    """
    chosen: set[int] = set()
    for part in str(text).split(","):
        match = re.fullmatch(r"\s*([0-9]{1,12})\s*(?:-\s*([0-9]{1,12})\s*)?", part)
        if match is None:
            raise UserError(
                f"--episodes {text}: {part.strip()!r} is not an episode index or a range a-b (e.g. 0,3,10-20)"
            )
        first = int(match[1])
        last = first if match[2] is None else int(match[2])
        if last < first:
            raise UserError(f"--episodes {text}: the range {first}-{last} runs backwards (write {last}-{first})")
        if last - first + len(chosen) >= _MAX_EPISODES:
            raise UserError(f"--episodes {text}: more than {_MAX_EPISODES:,} episodes")
        chosen.update(range(first, last + 1))
    return sorted(chosen)


def index_ranges(indices, limit: int = 8, sep: str = ", ") -> str:
    """Sorted indices as ranges, ``0-9, 12, 15-19`` (the first ``limit`` ranges, joined by ``sep``)."""
    runs: list[list[int]] = []
    for i in sorted(indices):
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    text = [str(a) if a == b else f"{a}-{b}" for a, b in runs[:limit]]
    return sep.join(text) + (f"{sep}..." if len(runs) > limit else "")


def select_episodes(episodes: list[Episode], wanted, root: Path) -> list[Episode]:
    """The episodes whose indices are ``wanted`` (None: all; text: :func:`parse_episodes`), in the
    data set's order, each once; an index the data set lacks is refused, naming those it has."""
    if wanted is None:
        return episodes
    if isinstance(wanted, str):
        wanted = parse_episodes(wanted)
    chosen = set()
    for w in wanted:
        if isinstance(w, bool) or not isinstance(w, (int, np.integer)) or w < 0:
            raise UserError(f"episodes: {w!r} is not an episode index (a whole number >= 0)")
        chosen.add(int(w))
    if not chosen:
        raise UserError("episodes: none selected (give at least one episode index)")
    have = {e.index for e in episodes}
    missing = sorted(chosen - have)
    if missing:
        raise DataError(
            f"episode {index_ranges(missing, 3)} {'is' if len(missing) == 1 else 'are'} not in the data "
            f"set; its episodes: {index_ranges(have)}",
            path=root,
            field="episodes",
        )
    return [e for e in episodes if e.index in chosen]
