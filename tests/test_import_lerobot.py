"""Importing LeRobot data sets, v3.0 and v2.x, with one reader (issue 26, items 1 and 8).

Every data set is written here in its layout, with real video encoded by PyAV (MPEG-4,
H.264 and AV1). Each recorded frame tells where it came from after lossy coding and
resizing: its left half has a grey level for the episode, its right half one for the row
(:func:`coded_frames`, :func:`identify`), so a test can check that the frame of the right
episode and row was taken, by timestamp.
"""

from __future__ import annotations

import json
import shutil
import sys

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset, import_lerobot, resample
from primspace.data.importers import frame_steps
from primspace.data.importers.lerobot import parse_episodes
from primspace.utils.errors import DataError, UserError

FPS = 10
H, W = 48, 64  # frames: sides that every encoder takes (AV1 wants multiples of 8)
CAMERA = "observation.images.top"
V3_DATA = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
V3_VIDEO = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
V2_DATA = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V2_VIDEO = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"


# ------------------------------------------------------------------ identifiable frames


def _levels(episode: int, row: int) -> tuple[int, int]:
    return 30 + 40 * (episode % 5), 20 + 9 * (row % 24)


def coded_frames(episode: int, n: int, h: int = H, w: int = W) -> np.ndarray:
    """``n`` frames of ``episode``: left half the episode's grey level, right half the row's."""
    frames = np.empty((n, h, w, 3), dtype=np.uint8)
    for row in range(n):
        left, right = _levels(episode, row)
        frames[row, :, : w // 2], frames[row, :, w // 2 :] = left, right
    return frames


def identify(frame: np.ndarray, tol: float = 3.0) -> tuple[int, int]:
    """``(episode, row)`` that a stored frame shows (the means of its outer quarters)."""
    w = frame.shape[1]
    left, right = float(frame[:, : w // 4].mean()), float(frame[:, w - w // 4 :].mean())
    episode = min(range(5), key=lambda e: abs(_levels(e, 0)[0] - left))
    row = min(range(24), key=lambda r: abs(_levels(0, r)[1] - right))
    assert abs(_levels(episode, row)[0] - left) <= tol and abs(_levels(episode, row)[1] - right) <= tol, (left, right)
    return episode, row


def state_of(episode: int, n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)[:, None]
    return (3.0 * episode + np.sin(2.0 * s + np.arange(3)[None, :]) + s).astype(np.float32)


def can_encode(codec: str) -> None:
    import av

    try:
        av.codec.Codec(codec, "w")
    except Exception:  # an encoder this PyAV wheel lacks (the import itself only decodes)
        pytest.skip(f"this PyAV build cannot encode {codec}")


def write_video(path, frames: np.ndarray, codec: str = "mpeg4", gop: int | None = None) -> None:
    import av

    path.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), "w") as container:
        stream = container.add_stream(codec, rate=FPS)
        stream.width, stream.height, stream.pix_fmt = frames.shape[2], frames.shape[1], "yuv420p"
        if codec == "mpeg4":
            stream.bit_rate = 4_000_000
        if gop:
            stream.codec_context.gop_size = gop  # key frames every few frames: seeking is exercised
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def _features(names=("shoulder", "elbow", "wrist")) -> dict:
    return {
        "observation.state": {"dtype": "float32", "shape": [3], "names": list(names)},
        "action": {"dtype": "float32", "shape": [3], "names": None},
        CAMERA: {
            "dtype": "video",
            "shape": [H, W, 3],
            "names": ["height", "width", "channels"],
            "info": {"video.fps": FPS, "video.codec": "av1", "video.pix_fmt": "yuv420p"},
        },
        "timestamp": {"dtype": "float32", "shape": [1], "names": None},
        "frame_index": {"dtype": "int64", "shape": [1], "names": None},
        "episode_index": {"dtype": "int64", "shape": [1], "names": None},
        "index": {"dtype": "int64", "shape": [1], "names": None},
        "task_index": {"dtype": "int64", "shape": [1], "names": None},
    }


def _rows(episode: int, n: int, first: int, task: int, times=None) -> dict:
    import pyarrow as pa

    state = state_of(episode, n)
    times = np.arange(n, dtype=np.float32) / FPS if times is None else np.asarray(times, dtype=np.float32)
    return {
        "observation.state": pa.array(list(state), type=pa.list_(pa.float32())),
        "action": pa.array(list(-state), type=pa.list_(pa.float32())),
        "timestamp": pa.array(times),
        "frame_index": pa.array(np.arange(n)),
        "episode_index": pa.array(np.full(n, episode)),
        "index": pa.array(np.arange(first, first + n)),
        "task_index": pa.array(np.full(n, task)),
    }


# ---------------------------------------------------------------------- v3.0 writer


def write_tasks(path, names) -> None:
    """meta/tasks.parquet as LeRobot writes it (``pd.DataFrame({"task_index": ...}, index=tasks)``):
    the task names are the pandas index, stored as ``__index_level_0__`` with pandas' metadata."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    pandas = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [],
        "creator": {"library": "pyarrow"},
        "pandas_version": "2.2.3",
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": None,
                "field_name": "__index_level_0__",
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
    }
    table = pa.table({"task_index": pa.array(range(len(names)), pa.int64()), "__index_level_0__": list(names)})
    pq.write_table(table.replace_schema_metadata({b"pandas": json.dumps(pandas).encode()}), path)


def write_v3(
    root,
    lengths=(6, 9, 5, 7),
    tasks=("push", "lift", "push", "lift"),
    data_files=((0, 0), (0, 0), (0, 1), (1, 0)),
    video_files=((0, 0), (0, 0), (0, 0), (0, 1)),
    codec="mpeg4",
    times=None,
    video_extra=0,
    gop=None,
    meta_split=2,
) -> list[np.ndarray]:
    """A LeRobot v3.0 directory: episode ``e`` in data file ``data_files[e]`` and video file
    ``video_files[e]`` (``(chunk, file)``); ``times[e]`` replaces its timestamps; each video
    file gets ``video_extra`` frames more at its end; meta/episodes split into two files
    after ``meta_split`` episodes. Returns the state of each episode."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = sorted(set(tasks))
    info = {
        "codebase_version": "v3.0",
        "robot_type": "so100",
        "fps": FPS,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "total_episodes": len(lengths),
        "total_frames": int(sum(lengths)),
        "total_tasks": len(names),
        "data_path": V3_DATA,
        "video_path": V3_VIDEO,
        "features": _features(),
    }
    (root / "meta").mkdir(parents=True)
    (root / "meta" / "info.json").write_text(json.dumps(info))
    write_tasks(root / "meta" / "tasks.parquet", names)
    tables, videos, records, first = {}, {}, [], 0
    for e, n in enumerate(lengths):
        rows = _rows(e, n, first, names.index(tasks[e]), None if times is None else times.get(e))
        tables.setdefault(data_files[e], []).append(pa.table(rows))
        done = videos.setdefault(video_files[e], [])
        start = sum(len(f) for f in done) / FPS
        done.append(coded_frames(e, n))
        records.append(
            {
                "episode_index": e,
                "tasks": [tasks[e]],
                "length": n,
                "data/chunk_index": data_files[e][0],
                "data/file_index": data_files[e][1],
                "dataset_from_index": first,
                "dataset_to_index": first + n,
                f"videos/{CAMERA}/chunk_index": video_files[e][0],
                f"videos/{CAMERA}/file_index": video_files[e][1],
                f"videos/{CAMERA}/from_timestamp": start,
                f"videos/{CAMERA}/to_timestamp": start + n / FPS,
                "stats/observation.state/mean": [0.0, 0.0, 0.0],
            }
        )
        first += n
    for (chunk, file), parts in tables.items():
        path = root / V3_DATA.format(chunk_index=chunk, file_index=file)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.concat_tables(parts), path)
    for (chunk, file), parts in videos.items():
        extra = [coded_frames(4, video_extra)] if video_extra else []
        path = root / V3_VIDEO.format(video_key=CAMERA, chunk_index=chunk, file_index=file)
        write_video(path, np.concatenate(parts + extra), codec=codec, gop=gop)
    for k, part in enumerate((records[:meta_split], records[meta_split:])):
        if part:
            path = root / "meta" / "episodes" / "chunk-000" / f"file-{k:03d}.parquet"
            path.parent.mkdir(parents=True, exist_ok=True)
            pq.write_table(pa.Table.from_pylist(part), path)
    return [state_of(e, n) for e, n in enumerate(lengths)]


def edit_episodes(root, column: str, values: dict) -> None:
    """Set ``column`` of the episodes ``values`` names in meta/episodes (``None`` as a key: drop it)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    for path in sorted((root / "meta" / "episodes").glob("*/*.parquet")):
        rows = pq.read_table(path).to_pylist()
        for row in rows:
            if None in values:
                row.pop(column)
            elif row["episode_index"] in values:
                row[column] = values[row["episode_index"]]
        pq.write_table(pa.Table.from_pylist(rows), path)


# ---------------------------------------------------------------------- v2.x writer


def write_v2(
    root,
    lengths=(12, 20, 9),
    tasks=("push", "lift", "push"),
    video_lengths=None,
    codec="mpeg4",
    names=("shoulder", "elbow", "wrist"),
) -> list[np.ndarray]:
    """A LeRobot v2.1 directory (one table and one video per episode, with the meta files LeRobot's
    v2.1 -> v3.0 converter reads: tasks.jsonl, episodes_stats.jsonl); returns each episode's state."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    task_names = sorted(set(tasks))
    info = {
        "codebase_version": "v2.1",
        "fps": FPS,
        "chunks_size": 2,
        "total_episodes": len(lengths),
        "total_chunks": (len(lengths) + 1) // 2,
        "total_videos": len(lengths),
        "total_frames": int(sum(lengths)),
        "total_tasks": len(task_names),
        "data_path": V2_DATA,
        "video_path": V2_VIDEO,
        "features": _features(names),
    }
    (root / "meta").mkdir(parents=True)
    (root / "meta" / "info.json").write_text(json.dumps(info))
    lines = [json.dumps({"episode_index": e, "tasks": [tasks[e]], "length": t}) for e, t in enumerate(lengths)]
    (root / "meta" / "episodes.jsonl").write_text("\n".join(lines) + "\n")
    (root / "meta" / "tasks.jsonl").write_text(
        "".join(json.dumps({"task_index": i, "task": t}) + "\n" for i, t in enumerate(task_names))
    )
    stats = [
        {
            "episode_index": e,
            "stats": {
                "observation.state": {
                    "min": s.min(0).tolist(),
                    "max": s.max(0).tolist(),
                    "mean": s.mean(0).tolist(),
                    "std": s.std(0).tolist(),
                    "count": [len(s)],
                }
            },
        }
        for e, s in enumerate(state_of(e, n) for e, n in enumerate(lengths))
    ]
    (root / "meta" / "episodes_stats.jsonl").write_text("".join(json.dumps(x) + "\n" for x in stats))
    first = 0
    for e, n in enumerate(lengths):
        data = root / V2_DATA.format(episode_chunk=e // 2, episode_index=e)
        data.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table(_rows(e, n, first, task_names.index(tasks[e]))), data)
        first += n
        video = root / V2_VIDEO.format(episode_chunk=e // 2, video_key=CAMERA, episode_index=e)
        write_video(video, coded_frames(e, n if video_lengths is None else video_lengths[e]), codec=codec)
    return [state_of(e, n) for e, n in enumerate(lengths)]


def check_import(ds, states, length, episodes=None, size=(24, 32)) -> None:
    """Joints resampled, and each stored frame the recorded frame of its episode and row that the rule picks."""
    episodes = list(range(len(states))) if episodes is None else episodes
    assert ds.motor.shape == (len(episodes), length, 3)
    assert ds.images.shape == (len(episodes), length, *size, 3)
    for i, e in enumerate(episodes):
        np.testing.assert_allclose(ds.motor[i], resample(states[e].astype(np.float64), length), rtol=1e-5, atol=1e-5)
        assert [identify(f) for f in ds.images[i]] == [(e, int(r)) for r in frame_steps(len(states[e]), length)]


# ---------------------------------------------------------------------------- v3.0


@pytest.mark.parametrize("codec", ["libx264", "libsvtav1"])  # H.264; AV1, LeRobot's default codec
def test_v3_episodes_share_files_and_spread_over_two_data_files(tmp_path, codec):
    """Four episodes: two data files in two chunks (and a third file), two videos holding
    three and one episodes, meta/episodes in two files; frames picked by timestamp."""
    can_encode(codec)
    states = write_v3(tmp_path / "pick", codec=codec, gop=3)
    ds = import_lerobot(tmp_path / "pick", 11, images=CAMERA, image_size=(24, 32))
    check_import(ds, states, 11)
    assert ds.joint_names == ["shoulder", "elbow", "wrist"]
    assert ds.label_names == ["lift", "push"] and ds.labels.tolist() == [1, 0, 1, 0]
    assert list(ds.source_ids) == [f"lerobot:pick:episode {e}" for e in range(4)]
    np.testing.assert_allclose(ds.dt, 0.1 * np.mean([5, 8, 4, 6]) / 10)
    assert ds.source.startswith("lerobot:pick joints=observation.state images=observation.images.top")
    assert "48x64 -> 24x32" in ds.source


def test_v3_joints_only_needs_no_video(tmp_path, monkeypatch):
    states = write_v3(tmp_path / "ds")
    shutil.rmtree(tmp_path / "ds" / "videos")
    monkeypatch.setitem(sys.modules, "av", None)  # PyAV is not needed without frames
    ds = import_lerobot(tmp_path / "ds", 6, joints=["action", "observation.state"])
    assert ds.images is None and ds.motor.shape == (4, 6, 6)
    assert ds.joint_names == ["action_0", "action_1", "action_2", "shoulder", "elbow", "wrist"]
    np.testing.assert_allclose(ds.motor[2, :, :3], resample(-states[2].astype(np.float64), 6), rtol=1e-5, atol=1e-5)


def test_v3_rows_are_found_by_index_in_any_order(tmp_path):
    """The rows of a data file shuffled: each episode's rows are those of its index range, in order."""
    import pyarrow.parquet as pq

    states = write_v3(tmp_path / "ds")
    file = tmp_path / "ds" / V3_DATA.format(chunk_index=0, file_index=0)
    table = pq.read_table(file)
    pq.write_table(table.take(np.random.default_rng(0).permutation(table.num_rows)), file)
    check_import(import_lerobot(tmp_path / "ds", 7, images=CAMERA, image_size=(24, 32)), states, 7)


def test_v3_row_range_that_the_data_file_lacks_is_refused(tmp_path):
    write_v3(tmp_path / "ds")
    edit_episodes(tmp_path / "ds", "dataset_to_index", {1: 16})  # episode 1 has rows 6..14
    with pytest.raises(DataError) as err:
        import_lerobot(tmp_path / "ds", 7)
    assert str(err.value) == (
        f"{tmp_path / 'ds' / 'data/chunk-000/file-000.parquet'}, field 'index', sample 1: episode 1: its rows, "
        "index 6 to 15 (dataset_from_index, dataset_to_index in meta/episodes/chunk-000/file-000.parquet), are "
        "not each once in the file: 9 rows there have an index in that range"
    )


def test_v3_timestamps_jittering_within_half_a_period_import(tmp_path):
    """Timestamps off by up to 0.4 frame periods still name their own frame."""
    jitter = np.array([0.0, 0.04, -0.03, 0.035, -0.04, 0.02, 0.03, -0.01, 0.0])
    states = write_v3(tmp_path / "ds", times={1: np.arange(9) / FPS + jitter})
    check_import(import_lerobot(tmp_path / "ds", 9, images=CAMERA, image_size=(24, 32)), states, 9)


def test_v3_timestamps_drifting_beyond_half_a_period_are_refused(tmp_path):
    """Episode 1's clock runs 10% fast: by row 8 it wants a time past its last frame."""
    write_v3(tmp_path / "ds", times={1: np.arange(9) * 1.1 / FPS})
    with pytest.raises(DataError) as err:
        import_lerobot(tmp_path / "ds", 9, images=CAMERA)
    video = tmp_path / "ds" / V3_VIDEO.format(video_key=CAMERA, chunk_index=0, file_index=0)
    assert str(err.value) == (
        f"{video}, field '{CAMERA}', sample 1: episode 1: row 8: the frame at from_timestamp 0.6 s + timestamp "
        "0.88 s = 1.48 s is wanted; the nearest frame of the episode is at 1.4 s, 0.08 s away, more than half a "
        "frame period (0.05 s at 10 fps)"
    )


def test_v3_timestamps_that_run_back_are_refused(tmp_path):
    """Issue 38, item 7: a clock running backwards was accepted (frames are taken nearest in time; the
    joints, without frames, are taken in row order and do not read it)."""
    times = np.arange(9) / FPS
    times[4] = times[2]  # row 4 goes back to row 2's time
    write_v3(tmp_path / "ds", times={1: times})
    with pytest.raises(
        DataError, match=r"field 'timestamp', sample 1: episode 1: row 4: timestamp 0\.2 runs back from 0\.3"
    ):
        import_lerobot(tmp_path / "ds", 9, images=CAMERA)


def test_v3_frames_outside_the_episode_span_are_not_taken(tmp_path):
    """to_timestamp one frame early: the last row's frame would be the next episode's first."""
    write_v3(tmp_path / "ds")
    edit_episodes(tmp_path / "ds", f"videos/{CAMERA}/to_timestamp", {0: 0.5})
    with pytest.raises(
        DataError,
        match=r"sample 0: episode 0: row 5: the frame at timestamp 0.5 s is wanted; the "
        r"nearest frame of the episode is at 0.4 s",
    ):
        import_lerobot(tmp_path / "ds", 9, images=CAMERA)


def test_v3_labels_from_task_index_when_episodes_list_no_tasks(tmp_path):
    write_v3(tmp_path / "ds", tasks=("wipe", "pour", "wipe", "wipe"))
    edit_episodes(tmp_path / "ds", "tasks", {None: None})
    ds = import_lerobot(tmp_path / "ds", 5)
    assert ds.label_names == ["pour", "wipe"] and ds.labels.tolist() == [1, 0, 1, 1]


def test_v3_image_feature_in_the_data_table(tmp_path):
    """An ``image`` feature: PNG bytes in the rows of a file of several episodes (lossless)."""
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq
    from PIL import Image

    states = write_v3(tmp_path / "ds")
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    info["features"]["observation.images.wrist"] = {"dtype": "image", "shape": [H, W, 3], "names": None}
    (tmp_path / "ds" / "meta" / "info.json").write_text(json.dumps(info))
    for file in sorted((tmp_path / "ds" / "data").rglob("*.parquet")):
        table = pq.read_table(file)
        pngs = []
        for e, r in zip(table.column("episode_index").to_pylist(), table.column("frame_index").to_pylist()):
            buffer = io.BytesIO()
            Image.fromarray(coded_frames(e, r + 1)[r]).save(buffer, format="PNG")
            pngs.append({"bytes": buffer.getvalue(), "path": None})
        pq.write_table(table.append_column("observation.images.wrist", pa.array(pngs)), file)
    ds = import_lerobot(tmp_path / "ds", 8, images="observation.images.wrist", image_size=(24, 32))
    check_import(ds, states, 8)


# ---------------------------------------------------------------------------- v2.x


def test_v2_h264_video_with_one_frame_more_than_rows_imports(tmp_path):
    can_encode("libx264")
    states = write_v2(tmp_path / "ds", video_lengths=(13, 21, 10), codec="libx264")
    ds = import_lerobot(tmp_path / "ds", 15, images=CAMERA, image_size=(24, 32))
    check_import(ds, states, 15)
    assert ds.label_names == ["lift", "push"] and ds.labels.tolist() == [1, 0, 1]
    assert list(ds.source_ids) == ["lerobot:ds:episode 0", "lerobot:ds:episode 1", "lerobot:ds:episode 2"]
    np.testing.assert_allclose(ds.dt, 0.1 * np.mean([11, 19, 8]) / 14)


def test_v2_video_that_ends_a_frame_early_is_refused(tmp_path):
    write_v2(tmp_path / "ds", video_lengths=(12, 19, 9))
    with pytest.raises(DataError) as err:
        import_lerobot(tmp_path / "ds", 6, images=CAMERA)
    video = tmp_path / "ds" / V2_VIDEO.format(episode_chunk=0, video_key=CAMERA, episode_index=1)
    assert str(err.value) == (
        f"{video}, field '{CAMERA}', sample 1: episode 1: row 19: the frame at timestamp 1.9 s is wanted; the "
        "nearest frame of the episode is at 1.8 s, 0.1 s away, more than half a frame period (0.05 s at 10 fps)"
    )


def test_v2_rows_without_timestamps_use_frame_index(tmp_path):
    import pyarrow.parquet as pq

    states = write_v2(tmp_path / "ds", lengths=(7, 8), tasks=("a", "b"))
    for file in (tmp_path / "ds" / "data").rglob("*.parquet"):
        pq.write_table(pq.read_table(file).drop_columns(["timestamp"]), file)
    check_import(import_lerobot(tmp_path / "ds", 5, images=CAMERA, image_size=(24, 32)), states, 5)


def test_v2_image_feature_stored_in_the_table(tmp_path):
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq
    from PIL import Image

    states = write_v2(tmp_path / "ds", lengths=(7, 11), tasks=("a", "b"))
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    info["features"]["observation.images.wrist"] = {"dtype": "image", "shape": [H, W, 3], "names": None}
    (tmp_path / "ds" / "meta" / "info.json").write_text(json.dumps(info))
    for e, t in enumerate((7, 11)):
        file = tmp_path / "ds" / V2_DATA.format(episode_chunk=0, episode_index=e)
        pngs = []
        for frame in coded_frames(e, t):
            buffer = io.BytesIO()
            Image.fromarray(frame).save(buffer, format="PNG")
            pngs.append({"bytes": buffer.getvalue(), "path": None})
        pq.write_table(pq.read_table(file).append_column("observation.images.wrist", pa.array(pngs)), file)
    check_import(import_lerobot(tmp_path / "ds", 9, images="observation.images.wrist", image_size=(24, 32)), states, 9)


# ------------------------------------------------------------------ episode selection


def test_parse_episodes():
    assert parse_episodes("0,3,10-12") == [0, 3, 10, 11, 12]
    assert parse_episodes(" 5 , 1-2, 2 ") == [1, 2, 5]
    for text, fragment in [
        ("", "'' is not an episode index"),
        ("1,,2", "'' is not"),
        ("a-3", "'a-3' is not"),
        ("-1", "'-1' is not"),
        ("1.5", "'1.5' is not"),
        ("20-10", "runs backwards"),
        ("0-99999999", "more than 1,000,000 episodes"),
        ("²", "is not"),
    ]:
        with pytest.raises(UserError, match=fragment):
            parse_episodes(text)


@pytest.mark.parametrize("version", ["v2", "v3"])
def test_episodes_selects_in_the_data_sets_order_each_once(tmp_path, version):
    states = (write_v3 if version == "v3" else write_v2)(tmp_path / "ds")
    ds = import_lerobot(tmp_path / "ds", 7, images=CAMERA, image_size=(24, 32), episodes=[2, 0, 2])
    check_import(ds, states, 7, episodes=[0, 2])
    assert list(ds.source_ids) == ["lerobot:ds:episode 0", "lerobot:ds:episode 2"]
    assert "episodes=0,2" in ds.source
    assert list(import_lerobot(tmp_path / "ds", 7, episodes="1-2").source_ids) == [
        "lerobot:ds:episode 1",
        "lerobot:ds:episode 2",
    ]
    with pytest.raises(DataError, match=r"ds, field 'episodes': episode 7 is not in the data set; its episodes: 0-"):
        import_lerobot(tmp_path / "ds", 7, episodes=[1, 7])
    with pytest.raises(UserError, match="none selected"):
        import_lerobot(tmp_path / "ds", 7, episodes=[])


# ------------------------------------------------------------- refusals, command line


def test_missing_video_file_is_one_line(run_cli, tmp_path):
    write_v3(tmp_path / "ds")
    video = tmp_path / "ds" / V3_VIDEO.format(video_key=CAMERA, chunk_index=0, file_index=1)
    video.unlink()
    out = tmp_path / "o.h5"
    res = run_cli("import", tmp_path / "ds", "--format", "lerobot", "--images", CAMERA, "-T", "9", "--out", out)
    assert_user_error(res, str(video), f"field '{CAMERA}'", "sample 3", "episode 3: no such file (episode video)")
    assert not out.exists()


def test_missing_data_file_names_the_episode(tmp_path):
    write_v3(tmp_path / "ds")
    (tmp_path / "ds" / V3_DATA.format(chunk_index=0, file_index=1)).unlink()
    with pytest.raises(DataError, match=r"file-001.parquet, sample 2: episode 2: no such file \(episode table\)"):
        import_lerobot(tmp_path / "ds", 9)


def test_v3_video_template_escaping_the_folder_is_refused(run_cli, tmp_path):
    write_v3(tmp_path / "ds")
    shutil.copytree(tmp_path / "ds" / "videos", tmp_path / "v" / "videos")
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    info["video_path"] = "../v/" + V3_VIDEO
    (tmp_path / "ds" / "meta" / "info.json").write_text(json.dumps(info))
    res = run_cli("import", tmp_path / "ds", "--images", CAMERA, "-T", "9", "--out", tmp_path / "o.h5")
    assert_user_error(res, "meta/info.json", "field 'video_path'", "../v/videos", "outside the data set folder")


def test_errors_name_the_file_and_the_feature(tmp_path):
    write_v3(tmp_path / "ds", lengths=(5, 6), tasks=("a", "b"), data_files=((0, 0),) * 2, video_files=((0, 0),) * 2)
    with pytest.raises(
        DataError,
        match=r"no feature 'observation.images.wrist'; features: observation.state, action, "
        r"observation.images.top, timestamp",
    ):
        import_lerobot(tmp_path / "ds", 6, images="observation.images.wrist")
    with pytest.raises(
        DataError,
        match=r"field 'action': is a float32 feature, not camera frames; camera features: "
        r"observation.images.top",
    ):
        import_lerobot(tmp_path / "ds", 6, images="action")
    edit_episodes(tmp_path / "ds", f"videos/{CAMERA}/from_timestamp", {None: None})
    with pytest.raises(
        DataError,
        match=rf"file-000.parquet, field 'videos/{CAMERA}/from_timestamp': no column "
        rf"'videos/{CAMERA}/from_timestamp'; columns: episode_index, ",
    ):
        import_lerobot(tmp_path / "ds", 6, images=CAMERA)
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    (tmp_path / "ds" / "meta" / "info.json").write_text(json.dumps(dict(info, codebase_version="v4.0")))
    with pytest.raises(DataError, match=r"codebase_version \"v4.0\": only LeRobot v2.x and v3.0 data sets are read"):
        import_lerobot(tmp_path / "ds", 6)


def test_without_the_video_extra_says_how_to_install_it(tmp_path, monkeypatch, run_cli):
    write_v3(tmp_path / "ds", lengths=(5,), tasks=("t",), data_files=((0, 0),), video_files=((0, 0),))
    monkeypatch.setitem(sys.modules, "av", None)  # import av now raises ImportError
    with pytest.raises(UserError, match=r"needs PyAV \(av\), which is not installed: pip install 'primspace\[video\]'"):
        import_lerobot(tmp_path / "ds", 6, images=CAMERA)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    res = run_cli("import", tmp_path / "ds", "--format", "lerobot", "-T", "6", "--out", tmp_path / "o.h5")
    assert_user_error(res, "needs pyarrow", "pip install 'primspace[video]'")
    assert not (tmp_path / "o.h5").exists()


@pytest.mark.parametrize("version", ["v2", "v3"])
def test_cli_import_guesses_lerobot_and_keeps_the_episodes(run_cli, tmp_path, version):
    (write_v3 if version == "v3" else write_v2)(tmp_path / "ds")
    out = tmp_path / "le.h5"
    res = run_cli("import", tmp_path / "ds", "--images", CAMERA, "--image-size", "16x24", "-T", "21", "--out", out)
    assert res.code == 0, res.err
    ds = MotionDataset.load(out)
    assert ds.images.shape[1:] == (21, 16, 24, 3)
    assert list(ds.source_ids) == [f"lerobot:ds:episode {e}" for e in range(len(ds))]
