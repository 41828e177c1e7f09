"""Sharded generation: DatasetWriter.copy_from, shard files, resuming, failures, backends."""

from __future__ import annotations

import dataclasses
import json
import os

import h5py
import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import DatasetWriter, MotionDataset
from primspace.sim import generate
from primspace.sim.generate import GenerationConfig, generate_dataset, shard_dir, shard_ranges, shard_size
from primspace.utils.errors import DataError, OutputExistsError, UserError

# 14 samples in shards (0, 4), (4, 8), (8, 12), (12, 14)
TINY = GenerationConfig(block_x=(0.45, 0.55), block_y=(0.0,), block_size=(0.05,), length=31, height=12, width=16)


def _dataset(n=6, t=5, size=(6, 8), seed=0, **kwargs) -> MotionDataset:
    rng = np.random.default_rng(seed)
    # smooth images (they compress, as camera frames do) with a little noise
    base = np.linspace(0, 200, size[0] * size[1] * 3).reshape(size + (3,))
    images = (base + rng.integers(0, 30, (n, t, *size, 3))).astype(np.uint8)
    return MotionDataset(
        motor=rng.normal(size=(n, t, 2)),
        images=images,
        labels=rng.integers(0, 3, n),
        params=rng.normal(size=(n, 2)),
        joint_names=["a", "b"],
        label_names=["x", "y", "z"],
        param_names=["p", "q"],
        dt=0.5,
        **kwargs,
    )


def _writer(path, n, like: MotionDataset, **kwargs) -> DatasetWriter:
    settings = dict(
        n_samples=n,
        length=like.length,
        joint_names=like.joint_names,
        image_size=like.image_size,
        label_names=like.label_names,
        param_names=like.param_names,
        dt=like.dt,
    )
    return DatasetWriter(path, **{**settings, **kwargs})


def _chunk(path, i) -> bytes:
    with h5py.File(path, "r") as f:
        return f["images"].id.read_direct_chunk((i, 0, 0, 0, 0))[1]


def _assert_same(a: MotionDataset, b: MotionDataset) -> None:
    np.testing.assert_array_equal(a.motor, b.motor)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.params, b.params)
    assert (a.images is None) == (b.images is None)
    if a.images is not None:
        np.testing.assert_array_equal(np.asarray(a.images), np.asarray(b.images))


# ------------------------------------------------------------------ copy_from


def test_copy_from_merges_shards_in_any_order_copying_raw_chunks(tmp_path):
    whole = _dataset(n=6)
    whole.subset([0, 1, 2, 3]).save(tmp_path / "a.h5")
    whole.subset([4, 5]).save(tmp_path / "b.h5")
    out = tmp_path / "merged.h5"
    with _writer(out, 6, whole) as writer:
        assert writer.copy_from(4, tmp_path / "b.h5") == 2
        assert writer.copy_from(0, tmp_path / "a.h5") == 4
    merged = MotionDataset.load(out)
    _assert_same(merged, whole)
    assert merged.joint_names == ["a", "b"] and merged.dt == 0.5
    # the stored (compressed) bytes were copied, not recompressed
    assert _chunk(out, 5) == _chunk(tmp_path / "b.h5", 1)
    assert _chunk(out, 0) == _chunk(tmp_path / "a.h5", 0)


def test_copy_from_decodes_when_the_compression_differs(tmp_path):
    whole = _dataset(n=3)
    whole.save(tmp_path / "fast.h5", compression_level=1)
    out = tmp_path / "merged.h5"
    with _writer(out, 3, whole) as writer:  # gzip 4
        writer.copy_from(0, tmp_path / "fast.h5")
    _assert_same(MotionDataset.load(out), whole)
    assert _chunk(out, 0) != _chunk(tmp_path / "fast.h5", 0)  # re-encoded at this file's level
    with h5py.File(out, "r") as f:
        assert f["images"].compression_opts == 4


def test_copy_from_a_file_without_chunks_or_compression(tmp_path):
    whole = _dataset(n=2)
    src = tmp_path / "plain.h5"
    whole.save(src)
    with h5py.File(src, "a") as f:  # rewrite the images contiguous, uncompressed
        data = f["images"][()]
        del f["images"]
        f.create_dataset("images", data=data)
    out = tmp_path / "merged.h5"
    with _writer(out, 2, whole) as writer:
        writer.copy_from(0, src)
    _assert_same(MotionDataset.load(out), whole)


@pytest.mark.parametrize(
    "change, start, fragments",
    [
        ({"joint_names": ["a", "c"]}, 0, ("field 'joint_names'", "['a', 'c'] does not match the file's ['a', 'b']")),
        ({"dt": 1.0}, 0, ("field 'dt'",)),
        ({"images": None}, 0, ("field 'images'", "missing")),
        ({"labels": None, "label_names": None}, 0, ("field 'labels'", "missing")),
        ({}, 2, ("field 'motor'", "block of 2 samples at 2 does not fit in N=3")),
    ],
)
def test_copy_from_refuses_a_file_that_does_not_match(tmp_path, change, start, fragments):
    whole = _dataset(n=2)
    src = tmp_path / "shard.h5"
    MotionDataset(
        **{
            **{
                f: getattr(whole, f)
                for f in ("motor", "images", "labels", "params", "joint_names", "label_names", "param_names", "dt")
            },
            **change,
        }
    ).save(src)
    out = tmp_path / "merged.h5"
    with pytest.raises(DataError) as info:
        with _writer(out, 3, whole) as writer:
            writer.copy_from(start, src)
    message = str(info.value)
    assert message.startswith(str(src)) and "\n" not in message
    for fragment in fragments:
        assert fragment in message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shard.h5"]  # nothing half-written


def test_copy_from_a_broken_file_names_it(tmp_path):
    whole = _dataset(n=2)
    src = tmp_path / "shard.h5"
    src.write_bytes(b"not hdf5")
    with pytest.raises(DataError, match="shard.h5: not a readable HDF5 file"):
        with _writer(tmp_path / "merged.h5", 2, whole) as writer:
            writer.copy_from(0, src)


# ------------------------------------------------------------------ layout


def test_shard_layout_depends_on_the_number_of_samples_only():
    assert [shard_size(n) for n in (1, 14, 126, 1715, 10**6)] == [4, 4, 16, 32, 32]
    for n in (1, 14, 126, 1715):
        ranges = shard_ranges(n)
        assert ranges[0][0] == 0 and ranges[-1][1] == n
        assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:]))
    assert shard_ranges(14) == [(0, 4), (4, 8), (8, 12), (12, 14)]
    assert shard_dir("data/paper.h5") == shard_dir(os.path.abspath("data/paper.h5"))
    assert shard_dir("data/paper.h5").name == ".paper.h5.shards"


# ------------------------------------------------------------------ generation


@pytest.fixture(scope="module")
def reference():
    """TINY in memory, seed 5: what every other route must give bit for bit."""
    return generate_dataset(TINY, seed=5, workers=1, progress=False)


_SIMULATE = generate.simulate_sample


def _fail_at(monkeypatch, bad: set[int]) -> list[int]:
    """Make these samples fail like an IK miss (in this process: workers=1); record every sample made."""
    made = []

    def simulate(scene, camera, config, label, x, y, size, index):
        made.append(index)
        if index in bad:
            raise DataError("inverse kinematics misses the scripted path by 3.00 mm (test)", field="motor", index=index)
        return _SIMULATE(scene, camera, config, label, x, y, size, index)

    monkeypatch.setattr(generate, "simulate_sample", simulate)
    return made


@pytest.mark.slow
def test_merged_file_equals_in_memory_generation(tmp_path, reference):
    out = tmp_path / "d.h5"
    shards = []
    ds = generate_dataset(TINY, seed=5, workers=1, out=out, progress=False, on_shard=shards.append)
    _assert_same(ds, reference)
    assert ds.source == reference.source
    assert not shard_dir(out).exists()  # removed once the file is published
    assert sorted(s["start"] for s in shards) == [0, 4, 8, 12] and not any(s["reused"] for s in shards)
    assert all(len(s["ik_error"]) == s["stop"] - s["start"] for s in shards)


def test_a_failed_shard_stops_no_other_and_a_rerun_makes_only_the_missing(tmp_path, monkeypatch, reference):
    out = tmp_path / "d.h5"
    made = _fail_at(monkeypatch, {5, 12})
    with pytest.raises(DataError) as info:
        generate_dataset(TINY, seed=5, workers=1, out=out, progress=False)
    message = str(info.value)
    assert "\n" not in message
    for fragment in (
        str(out),
        "field 'motor', sample 5: inverse kinematics misses",
        "sample 12",
        "2 of 4 shards failed",
        f"the other 2 are kept in {shard_dir(out)}",
    ):
        assert fragment in message, fragment
    assert made == [0, 1, 2, 3, 4, 5, 8, 9, 10, 11, 12]  # shard (8, 12) ran after (4, 8) failed
    assert not out.exists()
    files = sorted(p.name for p in shard_dir(out).iterdir())
    assert files == ["manifest.json", "shard-000000-000004.h5", "shard-000008-000012.h5"]
    manifest = json.loads((shard_dir(out) / "manifest.json").read_text())
    assert manifest["seed"] == 5 and manifest["shard_size"] == 4 and manifest["config"] == TINY.to_dict()
    # each shard is a valid data set of its samples
    _assert_same(MotionDataset.load(shard_dir(out) / "shard-000008-000012.h5"), reference.subset(range(8, 12)))

    made = _fail_at(monkeypatch, set())  # the cause is gone (e.g. a node came back)
    shards = []
    ds = generate_dataset(TINY, seed=5, workers=1, out=out, progress=False, on_shard=shards.append)
    assert made == [4, 5, 6, 7, 12, 13]
    assert sorted((s["start"], s["reused"]) for s in shards) == [(0, True), (4, False), (8, True), (12, False)]
    _assert_same(ds, reference)
    assert not shard_dir(out).exists()


def test_a_rerun_reuses_shards_with_another_worker_count(tmp_path, monkeypatch):
    out = tmp_path / "d.h5"
    config = dataclasses.replace(TINY, images=False)
    _fail_at(monkeypatch, {0, 13})
    with pytest.raises(DataError, match="sample 0"):
        generate_dataset(config, seed=1, workers=1, out=out, progress=False)
    monkeypatch.undo()
    shards = []  # the two missing shards run on a pool of 2 processes
    ds = generate_dataset(config, seed=1, workers=2, out=out, progress=False, on_shard=shards.append)
    assert sorted((s["start"], s["reused"]) for s in shards) == [(0, False), (4, True), (8, True), (12, False)]
    _assert_same(ds, generate_dataset(config, seed=1, workers=1, progress=False))


@pytest.mark.parametrize(
    "change, seed, what",
    [({}, 2, "different seed"), ({"jitter": 0.1}, 5, "different jitter"), ({"length": 33}, 5, "different length")],
)
def test_shards_of_another_generation_are_never_reused(tmp_path, monkeypatch, change, seed, what):
    out = tmp_path / "d.h5"
    config = dataclasses.replace(TINY, images=False)
    _fail_at(monkeypatch, {13})
    with pytest.raises(DataError):
        generate_dataset(config, seed=5, workers=1, out=out, progress=False)
    monkeypatch.undo()
    kept = {p.name: p.stat().st_mtime_ns for p in shard_dir(out).iterdir()}
    assert len(kept) == 4  # manifest + 3 shards

    other = dataclasses.replace(config, **change)
    with pytest.raises(UserError) as info:
        generate_dataset(other, seed=seed, workers=1, out=out, progress=False)
    message = str(info.value)
    assert str(shard_dir(out)) in message and what in message and "--overwrite" in message
    assert {p.name: p.stat().st_mtime_ns for p in shard_dir(out).iterdir()} == kept and not out.exists()

    shards = []
    ds = generate_dataset(other, seed=seed, workers=1, out=out, overwrite=True, progress=False, on_shard=shards.append)
    assert not any(s["reused"] for s in shards)
    _assert_same(ds, generate_dataset(other, seed=seed, workers=1, progress=False))


def test_a_run_that_finishes_no_shard_leaves_nothing(tmp_path, monkeypatch):
    _fail_at(monkeypatch, set(range(14)))
    with pytest.raises(DataError, match=r"sample 0: .*4 of 4 shards failed; none finished"):
        generate_dataset(dataclasses.replace(TINY, images=False), workers=1, out=tmp_path / "d.h5", progress=False)
    assert list(tmp_path.iterdir()) == []


def test_existing_output_is_refused_before_shards_are_made(tmp_path):
    out = tmp_path / "d.h5"
    out.write_text("keep me")
    with pytest.raises(OutputExistsError):
        generate_dataset(TINY, out=out, progress=False)
    assert out.read_text() == "keep me" and not shard_dir(out).exists()


def test_unknown_backend_is_refused_before_any_work(tmp_path):
    with pytest.raises(UserError, match="unknown backend 'dask'; choose from local, ray"):
        generate_dataset(TINY, backend="dask", out=tmp_path / "d.h5", progress=False)
    assert list(tmp_path.iterdir()) == []


def test_cli_reports_failed_samples_in_one_line_and_resumes(run_cli, tmp_path, monkeypatch):
    settings = tmp_path / "tiny.json"
    settings.write_text(json.dumps(dataclasses.replace(TINY, images=False).to_dict()))
    out = tmp_path / "d.h5"
    args = ("generate", "--config", settings, "--out", out, "--workers", 1)
    _fail_at(monkeypatch, {6})
    assert_user_error(
        run_cli(*args), str(out), "sample 6: inverse kinematics misses", "1 of 4 shards failed", "the other 3 are kept"
    )
    monkeypatch.undo()
    res = run_cli(*args)
    assert res.code == 0, res.err
    assert "14 motions" in res.out and "3 of 4 shards from an earlier run" in res.out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.h5", "tiny.json"]
    assert_user_error(run_cli(*args, "--overwrite", "--backend", "dask"), "unknown backend 'dask'")


def _ray_or_skip():
    """CI sets PRIMSPACE_REQUIRE_RAY=1 so a missing ray fails instead of skipping."""
    if os.environ.get("PRIMSPACE_REQUIRE_RAY") == "1":
        import ray  # noqa: F401
    else:
        pytest.importorskip("ray")


@pytest.mark.ray
@pytest.mark.slow
def test_ray_backend_gives_the_same_file_as_local(tmp_path, reference):
    _ray_or_skip()
    ds = generate_dataset(TINY, seed=5, backend="ray", workers=2, out=tmp_path / "d.h5", progress=False)
    _assert_same(ds, reference)
    assert not shard_dir(tmp_path / "d.h5").exists()
