"""The schema table (primspace.data.schema) and the one index check (primspace.data.indices)."""

import dataclasses
import doctest
from pathlib import Path

import h5py
import numpy as np
import pytest

import primspace.data.importers.frames
import primspace.data.indices
import primspace.data.schema
from primspace.data import DatasetWriter, MotionDataset, check_indices, read_indices
from primspace.data.schema import ARRAYS, ATTRIBUTES, FIELDS, arrays_of, dims_of, empty_arrays, field, markdown_table
from primspace.utils.errors import DataError, UserError

DOCS = Path(__file__).resolve().parents[1] / "docs" / "data.md"


def test_docs_table_is_the_schema_table():
    assert markdown_table() in DOCS.read_text()


def test_the_class_holds_the_schema_fields_in_table_order():
    init = [
        f.name for f in dataclasses.fields(MotionDataset) if f.name not in ("path", "file_indices")
    ]  # where, not what
    assert init == [f.name for f in FIELDS if f.in_memory]
    assert [f.name for f in ARRAYS + ATTRIBUTES] == [f.name for f in FIELDS]


def test_a_saved_file_has_what_the_table_says(tmp_path):
    n, t, j, h, w = 3, 4, 2, 5, 6
    rng = np.random.default_rng(0)
    ds = MotionDataset(
        rng.normal(size=(n, t, j)),
        images=rng.integers(0, 255, (n, t, h, w, 3), dtype=np.uint8),
        labels=[0, 1, -1],
        params=np.ones((n, 2)),
        lengths=[4, 3, 2],
        step_labels=[[0, 0, 1, 1], [1, 1, 1, -1], [0, 0, -1, -1]],
        step_segments=[[0, 0, 1, 1], [0, 0, 0, -1], [0, 0, -1, -1]],
        source_ids=["a.hdf5:data/demo_0", "a.hdf5:data/demo_1", "b.npz:0"],
        scene=np.zeros((n, 4)),
    )
    dims = {"N": n, "T": t, "J": j, "H": h, "W": w, "P": 2, "S": 4}
    with h5py.File(ds.save(tmp_path / "d.h5", compression_level=6)) as f:
        assert set(f.keys()) == {a.name for a in ARRAYS}
        assert set(f.attrs) == {a.name for a in ATTRIBUTES}
        for a in ARRAYS:
            node, options = f[a.name], a.create_options(dims, 6)
            assert node.shape == options["shape"] and node.dtype == a.dtype
            assert node.chunks == options.get("chunks")
            assert node.compression == options.get("compression")
            assert node.compression_opts == options.get("compression_opts")
            if a.fillvalue is not None:
                assert node.fillvalue == a.fillvalue


def test_field_lookup_shapes_and_buffers():
    assert field("images").file_shape({"N": 2, "T": 5, "H": 48, "W": 64}) == (2, 5, 48, 64, 3)
    with pytest.raises(KeyError):
        field("depth")
    assert list(empty_arrays({"N": 4, "T": 3, "J": 9, "P": 3})) == [
        "motor",
        "labels",
        "params",
        "lengths",
        "step_labels",
        "step_segments",
        "source_ids",
    ]
    buf = empty_arrays({"N": 4, "T": 3, "J": 9, "P": 3}, ["motor", "labels", "params"])
    assert list(buf) == ["motor", "labels", "params"]
    assert buf["motor"].dtype == np.float32 and buf["labels"].shape == (4,) and buf["params"].shape == (4, 3)
    assert dims_of(buf) == {"N": 4, "T": 3, "J": 9, "P": 3}
    shard = dict(buf, ik_error=np.zeros(4), start=0)
    assert list(arrays_of(shard)) == [
        "motor",
        "images",
        "labels",
        "params",
        "lengths",
        "step_labels",
        "step_segments",
        "source_ids",
        "scene",
    ]
    assert arrays_of(shard)["images"] is None


def test_a_shard_dict_writes_through_arrays_of(tmp_path):
    buf = empty_arrays({"N": 2, "T": 3, "J": 1}, ["motor", "labels"])
    buf["motor"][:] = 1.0
    buf["labels"][:] = [0, -1]
    with DatasetWriter(tmp_path / "s.h5", n_samples=2, length=3, joint_names=["a"], label_names=["x"]) as w:
        w.write(0, **arrays_of(dict(buf, ik_error=None)))
    back = MotionDataset.load(tmp_path / "s.h5")
    np.testing.assert_array_equal(back.labels, [0, -1])


@pytest.mark.parametrize("module", [primspace.data.schema, primspace.data.indices, primspace.data.importers.frames])
def test_module_examples_run(module):
    assert doctest.testmod(module, optionflags=doctest.ELLIPSIS).failed == 0


# ------------------------------------------------------------------------ indices


def test_check_indices_of_an_argument():
    np.testing.assert_array_equal(check_indices([2, 0], 3), [2, 0])
    assert check_indices(np.array([1], np.uint8), 3).dtype == np.int64
    for bad, message in [
        ([0, 0], "list a sample more than once"),
        ([0, 3], "sample index 3 out of range for 3 samples"),
        ([-1], "sample index -1 out of range"),
        ([], "an empty selection of samples"),
        ([0.5], "must be integers, got float64"),
        ([[0, 1]], "must be a 1-d list of integers"),
    ]:
        with pytest.raises(UserError, match=message):
            check_indices(bad, 3)
    np.testing.assert_array_equal(check_indices([1, 1], 3, unique=False), [1, 1])


def test_check_indices_from_a_file_names_the_file_and_the_data():
    with pytest.raises(
        DataError, match=r"^idx\.txt, field 'indices': sample 5 is out of range for the 3 samples of d\.h5$"
    ):
        check_indices([0, 5], 3, source="idx.txt", data_path="d.h5")
    with pytest.raises(DataError, match=r"^idx\.txt, field 'indices': lists a sample more than once$"):
        check_indices([1, 1], 3, source="idx.txt")
    np.testing.assert_array_equal(check_indices([-4, 9], None, source="idx.txt"), [-4, 9])


def test_read_indices_checks_against_the_data(tmp_path):
    (tmp_path / "i.txt").write_text("2, 0  # two samples\n")
    ds = MotionDataset(np.zeros((3, 2, 1)), path=tmp_path / "d.h5")
    np.testing.assert_array_equal(read_indices(tmp_path / "i.txt", ds), [2, 0])
    (tmp_path / "j.txt").write_text("3")
    with pytest.raises(
        DataError, match=r"j\.txt, field 'indices': sample 3 is out of range for the 3 samples of .*d\.h5"
    ):
        read_indices(tmp_path / "j.txt", ds)
