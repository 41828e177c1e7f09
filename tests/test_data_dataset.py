"""MotionDataset: HDF5 round trip, lazy images, subsets, validation, corrupted files."""

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from primspace.data import DatasetWriter, LazyImages, MotionDataset
from primspace.data.schema import SCHEMA_VERSION
from primspace.utils.errors import DataError, OutputExistsError, UserError


def make_dataset(n=5, t=6, j=3, images=True, seed=0):
    rng = np.random.default_rng(seed)
    return MotionDataset(
        motor=rng.normal(size=(n, t, j)),
        images=rng.integers(0, 256, size=(n, t, 4, 5, 3), dtype=np.uint8) if images else None,
        labels=np.arange(n) % 2,
        params=rng.normal(size=(n, 2)),
        joint_names=[f"q{i}" for i in range(j)],
        label_names=["a", "b"],
        param_names=["x", "y"],
        dt=0.5,
        source="test",
    )


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    motor=arrays(
        np.float32,
        st.tuples(st.integers(1, 4), st.integers(2, 6), st.integers(1, 3)),
        elements=st.floats(-1e6, 1e6, width=32, allow_nan=False, allow_infinity=False),
    ),
    with_images=st.booleans(),
    with_labels=st.booleans(),
)
def test_save_load_roundtrip(tmp_path_factory, motor, with_images, with_labels):
    n, t, _ = motor.shape
    rng = np.random.default_rng(n * 100 + t)
    ds = MotionDataset(
        motor=motor,
        images=rng.integers(0, 256, (n, t, 3, 2, 3), dtype=np.uint8) if with_images else None,
        labels=rng.integers(-1, 3, n) if with_labels else None,
        label_names=["x", "y", "z"] if with_labels else None,
        dt=0.25,
    )
    path = tmp_path_factory.mktemp("rt") / "d.h5"
    ds.save(path)
    back = MotionDataset.load(path)
    np.testing.assert_array_equal(back.motor, motor)
    assert back.motor.dtype == np.float32
    assert back.joint_names == ds.joint_names and back.dt == 0.25
    if with_images:
        assert isinstance(back.images, LazyImages)
        np.testing.assert_array_equal(np.asarray(back.images), ds.images)
    else:
        assert back.images is None
    if with_labels:
        np.testing.assert_array_equal(back.labels, ds.labels)
        assert back.label_names == ["x", "y", "z"]
    else:
        assert back.labels is None


def test_images_are_chunked_per_sample_and_compressed(tmp_path):
    ds = make_dataset()
    path = ds.save(tmp_path / "d.h5")
    with h5py.File(path) as f:
        assert f["images"].chunks == (1, 6, 4, 5, 3)
        assert f["images"].compression == "gzip"
        assert f.attrs["schema_version"] == SCHEMA_VERSION == 2  # 2: fletcher32 checksums (0.6)
        assert list(f.attrs["label_names"]) == ["a", "b"]


def test_lazy_images_index_like_arrays_and_subsets_do_not_copy(tmp_path):
    ds = make_dataset(n=7)
    back = MotionDataset.load(ds.save(tmp_path / "d.h5"))
    full = ds.images
    view = back.images
    np.testing.assert_array_equal(view[3], full[3])
    np.testing.assert_array_equal(view[-1], full[-1])
    np.testing.assert_array_equal(view[1:4], full[1:4])
    np.testing.assert_array_equal(view[[5, 0, 5]], full[[5, 0, 5]])
    np.testing.assert_array_equal(view[2, 1:3], full[2, 1:3])
    sub = back.subset([6, 2, 4])
    assert isinstance(sub.images, LazyImages) and sub.images.path == back.images.path
    np.testing.assert_array_equal(np.asarray(sub.images), full[[6, 2, 4]])
    np.testing.assert_array_equal(sub.motor, ds.motor[[6, 2, 4]].astype(np.float32))
    np.testing.assert_array_equal(sub.labels, ds.labels[[6, 2, 4]])
    sub2 = sub.subset(np.array([False, True, True]))
    np.testing.assert_array_equal(np.asarray(sub2.images), full[[2, 4]])
    with pytest.raises(IndexError):
        view[7]


def test_lazy_images_survive_pickling_for_worker_processes(tmp_path):
    import pickle

    back = MotionDataset.load(make_dataset().save(tmp_path / "d.h5"))
    back.images[0]  # opens the file handle
    clone = pickle.loads(pickle.dumps(back))
    np.testing.assert_array_equal(clone.images[1], back.images[1])


def test_load_images_reads_once_into_memory(tmp_path):
    back = MotionDataset.load(make_dataset().save(tmp_path / "d.h5"))
    mem = back.load_images()
    assert isinstance(mem.images, np.ndarray)
    np.testing.assert_array_equal(mem.images, np.asarray(back.images))


def test_existing_output_is_refused_and_kept(tmp_path):
    path = tmp_path / "d.h5"
    make_dataset(seed=1).save(path)
    before = path.read_bytes()
    with pytest.raises(OutputExistsError, match="--overwrite"):
        make_dataset(seed=2).save(path)
    assert path.read_bytes() == before
    make_dataset(seed=2).save(path, overwrite=True)
    np.testing.assert_array_equal(MotionDataset.load(path).motor, make_dataset(seed=2).motor.astype(np.float32))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(motor=np.zeros((2, 5))), "field 'motor'.*rank 2"),
        (dict(motor=np.zeros((2, 1, 3))), "at least 2 time steps"),
        (dict(motor=np.zeros((0, 4, 3))), "no samples"),
        (dict(motor=np.array([[[0.0], [np.inf]], [[0.0], [1.0]]])), "field 'motor', sample 0: contains NaN or inf"),
        (dict(motor=np.zeros((3, 4, 2)), labels=[0, 1]), "field 'labels'.*shape"),
        (
            dict(motor=np.zeros((3, 4, 2)), labels=[0, 1, 2], label_names=["a", "b"]),
            "field 'labels', sample 2: label 2 out of range",
        ),
        (dict(motor=np.zeros((3, 4, 2)), labels=[0.5, 1, 0]), "labels must be integers"),
        (dict(motor=np.zeros((2, 4, 2)), images=np.zeros((2, 4, 3, 3, 3), np.float32)), "images must be uint8"),
        (dict(motor=np.zeros((2, 4, 2)), images=np.zeros((2, 5, 3, 3, 3), np.uint8)), "5 time steps but motor has T=4"),
        (dict(motor=np.zeros((2, 4, 2)), images=np.zeros((3, 4, 3, 3, 3), np.uint8)), "3 samples but motor has 2"),
        (dict(motor=np.zeros((2, 4, 2)), joint_names=["a"]), "1 joint names for J=2"),
        (dict(motor=np.zeros((2, 4, 2)), params=np.array([[1.0], [np.nan]])), "field 'params', sample 1"),
        (dict(motor=np.array([["a"]])), "must be numbers"),
    ],
)
def test_validation_names_field_and_sample(kwargs, match):
    with pytest.raises(DataError, match=match):
        MotionDataset(**kwargs)


def _write_raw(path, **arrays):
    with h5py.File(path, "w") as f:
        for name, value in arrays.items():
            f.create_dataset(name, data=value)
    return path


def test_corrupted_files_fail_with_file_field_and_index(tmp_path):
    good = make_dataset().save(tmp_path / "good.h5")
    truncated = tmp_path / "trunc.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 3])
    with pytest.raises(DataError, match=r"trunc\.h5: .*(not a readable HDF5|truncated|cannot read)"):
        MotionDataset.load(truncated)
    text = tmp_path / "text.h5"
    text.write_text("hello")
    with pytest.raises(DataError, match=r"text\.h5: not a readable HDF5 file"):
        MotionDataset.load(text)
    with pytest.raises(DataError, match=r"no_motor\.h5, field 'motor': missing"):
        MotionDataset.load(_write_raw(tmp_path / "no_motor.h5", labels=np.zeros(3, np.int32)))
    motor = np.zeros((4, 3, 2), np.float32)
    motor[2, 1, 0] = np.nan
    with pytest.raises(DataError, match=r"nan\.h5, field 'motor', sample 2: contains NaN"):
        MotionDataset.load(_write_raw(tmp_path / "nan.h5", motor=motor))
    with pytest.raises(DataError, match=r"int\.h5, field 'motor': must be floating point"):
        MotionDataset.load(_write_raw(tmp_path / "int.h5", motor=np.zeros((2, 3, 1), np.int64)))
    with pytest.raises(DataError, match=r"img\.h5, field 'images': must be uint8"):
        MotionDataset.load(
            _write_raw(
                tmp_path / "img.h5", motor=np.zeros((2, 3, 1), np.float32), images=np.zeros((2, 3, 2, 2, 3), np.float32)
            )
        )
    with pytest.raises(DataError, match=r"lab\.h5, field 'labels', sample 1: label -3"):
        MotionDataset.load(
            _write_raw(tmp_path / "lab.h5", motor=np.zeros((2, 3, 1), np.float32), labels=np.array([0, -3]))
        )
    with pytest.raises(DataError, match="no such file"):
        MotionDataset.load(tmp_path / "missing.h5")


def test_subset_errors():
    ds = make_dataset(images=False)
    with pytest.raises(UserError, match="out of range"):
        ds.subset([0, 5])
    with pytest.raises(UserError, match="empty"):
        ds.subset([])


def test_writer_streams_blocks_in_any_order(tmp_path):
    ds = make_dataset(n=6)
    path = tmp_path / "w.h5"
    with DatasetWriter(
        path,
        n_samples=6,
        length=6,
        joint_names=ds.joint_names,
        image_size=(4, 5),
        label_names=["a", "b"],
        param_names=["x", "y"],
        dt=0.5,
    ) as w:
        for start in (4, 0, 2):
            sl = slice(start, start + 2)
            w.write(start, motor=ds.motor[sl], images=ds.images[sl], labels=ds.labels[sl], params=ds.params[sl])
        assert not path.exists()  # published only when complete
    back = MotionDataset.load(path)
    np.testing.assert_array_equal(back.motor, ds.motor.astype(np.float32))
    np.testing.assert_array_equal(np.asarray(back.images), ds.images)


def test_writer_leaves_nothing_when_incomplete_or_failing(tmp_path):
    path = tmp_path / "w.h5"
    with pytest.raises(DataError, match="field 'motor', sample 2: 1 samples never written"):
        with DatasetWriter(path, n_samples=3, length=4, joint_names=["a"]) as w:
            w.write(0, motor=np.zeros((2, 4, 1)))
    assert not path.exists() and list(tmp_path.iterdir()) == []
    bad = np.zeros((1, 4, 1))
    bad[0, 2, 0] = np.nan
    with pytest.raises(DataError, match="sample 0: contains NaN"):
        with DatasetWriter(path, n_samples=1, length=4, joint_names=["a"]) as w:
            w.write(0, motor=bad)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(DataError, match="does not fit"):
        with DatasetWriter(path, n_samples=1, length=4, joint_names=["a"]) as w:
            w.write(1, motor=np.zeros((1, 4, 1)))
    with pytest.raises(DataError, match="field 'images'.*missing"):
        with DatasetWriter(path, n_samples=1, length=4, joint_names=["a"], image_size=(2, 2)) as w:
            w.write(0, motor=np.zeros((1, 4, 1)))
    assert list(tmp_path.iterdir()) == []


def test_summary_counts_labels_and_ranges():
    ds = MotionDataset(np.arange(24, dtype=float).reshape(3, 4, 2), labels=[0, -1, 0], label_names=["a", "b"])
    s = ds.summary()
    assert s["label_counts"] == {"a": 2, "b": 0, "<unknown>": 1}
    assert s["joint_ranges"]["j0"] == [0.0, 22.0]
    assert s["n_samples"] == 3 and s["length"] == 4 and s["image_shape"] is None


# ------------------------------------------------------- values too large for float32


@pytest.mark.parametrize("dtype", [np.float64, np.longdouble])
def test_file_motor_too_large_for_float32_is_named_not_called_inf(tmp_path, dtype):
    motor = np.zeros((4, 3, 2), dtype)
    motor[2, 1, 0] = 1e39
    with pytest.raises(DataError) as info:
        MotionDataset.load(_write_raw(tmp_path / "big.h5", motor=motor))
    assert str(info.value) == (
        f"{tmp_path / 'big.h5'}, field 'motor', sample 2: value 1e+39 exceeds the float32 range "
        "(magnitude at most 3.40282e+38) (step 1, joint 0)"
    )
    params = np.zeros((4, 2))
    params[3, 1] = -1e300
    with pytest.raises(
        DataError, match=r"p\.h5, field 'params', sample 3: value -1e\+300 exceeds the float32 range .*\(column 1\)"
    ):
        MotionDataset.load(_write_raw(tmp_path / "p.h5", motor=np.zeros((4, 3, 2), np.float32), params=params))


def test_constructor_and_writer_refuse_values_too_large_for_float32(tmp_path):
    motor = np.zeros((2, 3, 1))
    motor[1, 2, 0] = 3.5e38
    with pytest.raises(DataError, match=r"field 'motor', sample 1: value 3\.5e\+38 exceeds the float32 range"):
        MotionDataset(motor)
    with pytest.raises(DataError, match=r"w\.h5, field 'motor', sample 1: value 3\.5e\+38 exceeds"):
        with DatasetWriter(tmp_path / "w.h5", n_samples=2, length=3, joint_names=["a"]) as w:
            w.write(0, motor=motor)
    assert list(tmp_path.iterdir()) == []
    edge = np.full((1, 3, 1), float(np.finfo(np.float32).max))  # the largest float32 itself is fine
    assert np.isfinite(MotionDataset(edge).motor).all()


def test_labels_that_do_not_fit_int32_are_refused_not_wrapped(tmp_path):
    # 2**32 would wrap to label 0, a valid label: silently wrong without the check
    with pytest.raises(
        DataError, match=r"lab\.h5, field 'labels', sample 1: label 4294967296 is not a primitive index"
    ):
        MotionDataset.load(
            _write_raw(
                tmp_path / "lab.h5", motor=np.zeros((2, 3, 1), np.float32), labels=np.array([0, 2**32], np.int64)
            )
        )


# ------------------------------------------------------------ corrupted image chunks


def _corrupt_chunk(path, sample):
    """Overwrite the stored (compressed) chunk of one sample's images with garbage."""
    with h5py.File(path, "r") as f:
        dset = f["images"]
        info = dset.id.get_chunk_info_by_coord((sample, 0, 0, 0, 0))
        assert info.chunk_offset == (sample, 0, 0, 0, 0)
        offset, size = info.byte_offset, info.size
    with open(path, "r+b") as fh:
        fh.seek(offset)
        fh.write(bytes(range(256)) * (size // 256) + b"\xff" * (size % 256))


def test_corrupted_image_chunk_is_a_data_error_on_every_read_path(tmp_path):
    ds = make_dataset(n=6)
    path = ds.save(tmp_path / "d.h5")
    _corrupt_chunk(path, 3)
    back = MotionDataset.load(path)  # lazy: loading reads no image chunk
    where = r"d\.h5, field 'images', sample 3: cannot be read, its stored data is corrupted or truncated"
    with pytest.raises(DataError, match=where):
        back.load_images()
    with pytest.raises(DataError, match=where):
        back.images[3]
    with pytest.raises(DataError, match=where):
        back.images[1:5]
    with pytest.raises(DataError, match=where):
        back.images[[5, 3, 0]]
    with pytest.raises(DataError, match=where):  # a view reports the file's sample index
        back.subset([4, 3]).images[1]
    with pytest.raises(DataError, match=where):
        list(back.images.iter_blocks(2))
    # the other samples still read, lazily
    for i in (0, 1, 2, 4, 5):
        np.testing.assert_array_equal(back.images[i], ds.images[i])
    np.testing.assert_array_equal(back.images[4:6], ds.images[4:6])
    np.testing.assert_array_equal(back.subset([5, 0]).images[:], ds.images[[5, 0]])
    # copying it, by save or by merging, refuses it and leaves nothing behind
    with pytest.raises(DataError, match=where):
        back.save(tmp_path / "copy.h5")
    for level in (4, 1):  # raw chunk copy (same compression) and decode/re-encode
        with pytest.raises(DataError, match=where):
            with DatasetWriter(
                tmp_path / "merged.h5",
                n_samples=6,
                length=6,
                joint_names=ds.joint_names,
                image_size=(4, 5),
                label_names=["a", "b"],
                param_names=["x", "y"],
                dt=0.5,
                compression_level=level,
            ) as w:
                w.copy_from(0, path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.h5"]


@pytest.mark.parametrize(
    "attrs, match",
    [
        ({"dt": "fast"}, r"field 'dt': must be one number"),
        ({"dt": [0.1, 0.2]}, r"field 'dt': must be one number, got 2 value"),
        ({"schema_version": "one"}, r"field 'schema_version': must be one number"),
        ({"schema_version": 0.5}, r"field 'schema_version': must be a positive integer, got 0\.5"),
        ({"schema_version": np.inf}, r"field 'schema_version': must be a positive integer, got inf"),
    ],
)
def test_file_attributes_that_are_not_one_number_name_the_attribute(tmp_path, attrs, match):
    path = _write_raw(tmp_path / "a.h5", motor=np.zeros((2, 3, 1), np.float32))
    with h5py.File(path, "a") as f:
        f.attrs.update(attrs)
    with pytest.raises(DataError, match=r"a\.h5, " + match):
        MotionDataset.load(path)
