"""Frames streamed from the data file (issue 28, item 1): the same training bit for bit as
with every frame in memory, with 0 and 2 loader workers; the automatic choice; the
command line's options."""

import numpy as np
import pytest
import torch

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.train import TrainConfig, evaluate, fit, infer, streaming
from primspace.train.streaming import FrameReader, frames_bytes, should_stream
from primspace.utils.errors import DataError, UserError
from test_train import primitives
from test_vision_frames import SMALL

CPU = torch.device("cpu")


pytestmark = pytest.mark.usefixtures("one_thread_each")  # one thread per test (tests/conftest.py): bit-for-bit sums


@pytest.fixture(scope="module")
def data_file(tmp_path_factory):
    data = primitives(3, seed=0, T=12, images=True)  # 9 sequences of 12 steps, 8x8 frames
    lengths = np.array([12, 9, 12, 7, 12, 12, 10, 12, 12])  # padding: masks stay in memory
    data = MotionDataset(
        data.motor,
        images=data.images,
        labels=data.labels,
        lengths=lengths,
        step_labels=np.where(np.arange(12) < lengths[:, None], data.labels[:, None], -1),
        step_segments=np.where(np.arange(12) < lengths[:, None], 0, -1),
    )
    path = tmp_path_factory.mktemp("data") / "frames.h5"
    data.save(path)
    return path


def same_state(a: dict, b: dict) -> bool:
    """Two checkpoint dicts hold the same tensors, bit for bit (RNG states and config aside)."""

    def flat(x, key=""):
        if isinstance(x, dict):
            return [kv for k, v in x.items() if k not in ("rng", "config") for kv in flat(v, f"{key}/{k}")]
        if isinstance(x, (list, tuple)):
            return [kv for i, v in enumerate(x) for kv in flat(v, f"{key}/{i}")]
        return [(key, x)]

    fa, fb = flat(a), flat(b)
    assert [k for k, _ in fa] == [k for k, _ in fb]
    return all(torch.equal(x, y) if isinstance(x, torch.Tensor) else x == y for (_, x), (_, y) in zip(fa, fb))


def numbers(history):
    return [{k: v for k, v in h.items() if k not in ("seconds", "samples_per_s")} for h in history]


@pytest.mark.slow
@pytest.mark.parametrize("workers, frames", [(0, None), (2, 3)])
def test_streaming_trains_the_same_numbers_as_frames_in_memory(data_file, workers, frames, monkeypatch):
    """θ, codes, both optimisers' states and the history, bit for bit; with K drawn frames
    per sequence the draws are the in-memory path's. Workers read a batch in chunks (one per worker: 2 and 2 here)."""
    monkeypatch.setattr(streaming, "CHUNK", 1)
    ds = MotionDataset.load(data_file)
    base = dict(epochs=2, batch_size=4, threads=1, seed=0, vision_frames=frames, loss_reduction="sum")
    loaded = fit(ds, model_config=SMALL, train_config=TrainConfig(**base, stream_frames=False), progress=False)
    tc = TrainConfig(**base, stream_frames=True, loader_workers=workers)
    streamed = fit(ds, model_config=SMALL, train_config=tc, progress=False)
    assert same_state(loaded.state, streamed.state)
    assert numbers(loaded.history) == numbers(streamed.history)
    if workers:  # inference and evaluate read the frames the same way
        kw = dict(epochs=2, indices=[1, 3, 5], progress=False)
        a = infer(loaded, ds, **kw, stream_frames=False)
        b = infer(loaded, ds, **kw, stream_frames=True, loader_workers=workers)
        assert same_state(a.state, b.state) and numbers(a.history) == numbers(b.history)
        assert evaluate(b, ds, indices=[1, 3, 5]) == evaluate(a, ds, indices=[1, 3, 5])


def test_a_run_resumes_streamed_exactly(data_file, tmp_path):
    ds = MotionDataset.load(data_file)
    tc = TrainConfig(epochs=3, batch_size=4, threads=1, seed=0, vision_frames=3, stream_frames=False)
    straight = fit(ds, model_config=SMALL, train_config=tc, progress=False)
    fit(
        ds,
        tmp_path / "run",
        model_config=SMALL,
        train_config=TrainConfig(**{**tc.to_dict(), "epochs": 1}),
        progress=False,
    )
    streamed = TrainConfig(**{**tc.to_dict(), "stream_frames": True, "loader_workers": 0})
    resumed = fit(ds, tmp_path / "run", model_config=SMALL, train_config=streamed, resume=True, progress=False)
    np.testing.assert_array_equal(resumed.latents, straight.latents)


def test_the_automatic_choice_streams_what_does_not_fit(data_file):
    ds = MotionDataset.load(data_file)
    size = frames_bytes(ds)
    assert size == 9 * 12 * 8 * 8 * 3
    fits = TrainConfig(frames_memory_gb=size / 1e9)
    assert not should_stream(fits, ds, True, CPU)
    assert should_stream(fits, ds, True, CPU, sharing=2)  # two processes of one machine load them twice
    assert should_stream(TrainConfig(frames_memory_gb=size / 2e9), ds, True, CPU)
    assert not should_stream(TrainConfig(), ds, True, CPU)  # default: half of the RAM
    assert not should_stream(TrainConfig(stream_frames=True), ds, False, CPU)  # no vision loss: nothing to read
    in_memory = ds.load_images()  # frames already in memory are used as they are
    assert not should_stream(TrainConfig(frames_memory_gb=1e-9), in_memory, True, CPU)
    assert not should_stream(TrainConfig(stream_frames=True), in_memory, True, CPU)
    for bad in (dict(loader_workers=-1), dict(frames_memory_gb=0.0), dict(micro_batches=0), dict(stream_frames=1)):
        with pytest.raises(UserError):
            TrainConfig(**bad).validate()


def test_a_worker_reads_the_stored_frames_of_the_part(data_file):
    ds = MotionDataset.load(data_file)
    view = ds.subset([8, 2, 5]).images
    reader = FrameReader(view)
    steps = np.array([[0, 11], [3, 3], [7, 1]])
    frames, seconds = reader[(np.array([2, 0]), steps[:2])]
    full = np.asarray(view)
    assert frames.dtype == torch.uint8 and frames.shape == (2, 2, 8, 8, 3) and seconds >= 0
    np.testing.assert_array_equal(frames[0].numpy(), full[2, [0, 11]])
    np.testing.assert_array_equal(frames[1].numpy(), full[0, [3, 3]])
    np.testing.assert_array_equal(reader[(np.array([1]), None)][0].numpy(), full[1:2])


def test_the_command_line_streams_on_request(data_file, tmp_path, run_cli):
    args = (
        "--layers",
        "12,6",
        "--image-channels",
        "8,4",
        "--latent-dim",
        "3",
        "--threads",
        "1",
        "--batch-size",
        "4",
        "--epochs",
        "1",
    )
    a = run_cli("train", data_file, "--out", tmp_path / "a", *args, "--load-frames")
    b = run_cli("train", data_file, "--out", tmp_path / "b", *args, "--stream-frames", "--loader-workers", "0")
    assert a.code == 0 and b.code == 0, (a.err, b.err)
    np.testing.assert_array_equal(np.load(tmp_path / "a" / "latents.npy"), np.load(tmp_path / "b" / "latents.npy"))
    c = run_cli(
        "infer",
        tmp_path / "a",
        data_file,
        "--out",
        tmp_path / "c",
        "--epochs",
        "1",
        "--stream-frames",
        "--loader-workers",
        "0",
        "--threads",
        "1",
    )
    assert c.code == 0, c.err
    assert_user_error(
        run_cli("train", data_file, "--out", tmp_path / "d", *args, "--loader-workers", "-1"), "loader_workers"
    )


def test_a_corrupted_chunk_read_by_a_worker_names_the_sample(data_file, tmp_path):
    from test_data_dataset import _corrupt_chunk

    path = tmp_path / "bad.h5"
    path.write_bytes(data_file.read_bytes())
    _corrupt_chunk(path, 4)
    ds = MotionDataset.load(path)
    tc = TrainConfig(epochs=1, batch_size=4, seed=0, stream_frames=True, loader_workers=1)
    with pytest.raises(DataError, match=r"bad\.h5, field 'images', sample 4: cannot be read"):
        fit(ds, model_config=SMALL, train_config=tc, progress=False)
