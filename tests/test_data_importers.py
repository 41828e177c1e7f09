"""Importers: npz layouts, CSV folders, LASA; variable lengths resampled; errors located."""

import numpy as np
import pytest

from primspace.data import import_csv_folder, import_lasa, import_npz, resample
from primspace.data.importers import lasa_shape_names
from primspace.utils.errors import DataError, UserError


def sequences(lengths=(30, 45, 12), joints=3, seed=0):
    rng = np.random.default_rng(seed)
    return [np.cumsum(rng.normal(size=(t, joints)), axis=0) for t in lengths]


def test_npz_list_of_arrays_with_string_labels(tmp_path):
    seqs = sequences()
    path = tmp_path / "d.npz"
    np.savez(path, *seqs, labels=np.array(["push", "grasp", "push"]), joint_names=np.array(["a", "b", "c"]), dt=0.1)
    ds = import_npz(path, 20)
    assert ds.motor.shape == (3, 20, 3)
    assert ds.label_names == ["grasp", "push"]
    np.testing.assert_array_equal(ds.labels, [1, 0, 1])
    assert ds.joint_names == ["a", "b", "c"]
    np.testing.assert_allclose(ds.motor, resample(seqs, 20).astype(np.float32), rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(ds.dt, 0.1 * np.mean([29, 44, 11]) / 19)


def test_npz_concatenated_with_lengths_and_fixed_length(tmp_path):
    seqs = sequences()
    np.savez(tmp_path / "c.npz", motor=np.concatenate(seqs), lengths=[len(s) for s in seqs], labels=[0, 1, -1])
    ds = import_npz(tmp_path / "c.npz", 16)
    np.testing.assert_allclose(ds.motor[1], resample(seqs[1], 16), rtol=1e-5, atol=1e-4)
    np.testing.assert_array_equal(ds.labels, [0, 1, -1])
    fixed = np.stack([s[:12] for s in seqs])
    np.savez(tmp_path / "f.npz", motor=fixed)
    ds2 = import_npz(tmp_path / "f.npz", 12)
    np.testing.assert_allclose(ds2.motor, fixed, rtol=1e-6, atol=1e-5)
    assert ds2.labels is None


@pytest.mark.parametrize(
    "arrays, match",
    [
        (dict(arr_0=np.zeros((5, 2)), arr_1=np.zeros((0, 2))), r"field 'motor', sample 1: has length 0"),
        (dict(arr_0=np.zeros((5, 2)), arr_1=np.zeros((1, 2))), r"field 'motor', sample 1: a sequence of length 1"),
        (dict(arr_0=np.zeros((5, 2)), arr_1=np.zeros((5, 3))), r"field 'motor', sample 1: has 3 joints"),
        (dict(arr_0=np.zeros((5, 2)), arr_1=np.array([[0.0, np.nan]] * 3)), r"field 'motor', sample 1: contains NaN"),
        (dict(arr_0=np.zeros((5, 2)), labels=np.array([0, 1])), r"field 'labels': 2 labels for 1 sequences"),
        (
            dict(
                arr_0=np.zeros((5, 2)),
                arr_1=np.zeros((5, 2)),
                labels=np.array([0, 4]),
                label_names=np.array(["a", "b"]),
            ),
            r"field 'labels', sample 1: label 4 out of range",
        ),
        (dict(motor=np.zeros((6, 2)), lengths=[2, 3]), r"field 'lengths': lengths sum to 5"),
        (dict(arr_0=np.zeros((5, 2)).astype(str)), r"field 'motor', sample 0: must be numbers"),
        (dict(motor=np.zeros((5, 2))), r"field 'motor': must be \(N, T, J\)"),
        (dict(other=np.zeros(3)), r"no 'motor' array"),
    ],
)
def test_npz_bad_input_names_file_field_and_sample(tmp_path, arrays, match):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(DataError, match=r"bad\.npz, " + match if match.startswith("field") else match):
        import_npz(path, 10)


def test_npz_not_an_archive_or_pickled(tmp_path):
    (tmp_path / "x.npz").write_text("not a zip")
    with pytest.raises(DataError, match=r"x\.npz: not a readable \.npz"):
        import_npz(tmp_path / "x.npz", 10)
    np.savez(tmp_path / "o.npz", motor=np.array([np.zeros((3, 2)), np.zeros((4, 2))], dtype=object))
    with pytest.raises(DataError, match="Python objects"):
        import_npz(tmp_path / "o.npz", 10)


def _write_csv(path, header, rows):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")


def test_csv_folder_labels_from_subfolders_and_time_column(tmp_path):
    rng = np.random.default_rng(1)
    expected = {}
    for label, n_files in (("push", 2), ("grasp", 1)):
        for k in range(n_files):
            t = np.arange(10 + 5 * k) * 0.5
            data = rng.normal(size=(len(t), 2))
            _write_csv(tmp_path / label / f"{k}.csv", ["time", "q1", "q2"], np.column_stack([t, data]))
            expected[(label, k)] = data
    _write_csv(
        tmp_path / "loose.csv", ["time", "q1", "q2"], np.column_stack([np.arange(8) * 0.5, rng.normal(size=(8, 2))])
    )
    ds = import_csv_folder(tmp_path, 12)
    assert ds.joint_names == ["q1", "q2"]
    assert ds.label_names == ["grasp", "push"]
    # files sorted by path: grasp/0, loose, push/0, push/1
    np.testing.assert_array_equal(ds.labels, [0, -1, 1, 1])
    np.testing.assert_allclose(ds.motor[0], resample(expected[("grasp", 0)], 12), rtol=1e-5, atol=1e-5)
    assert ds.dt > 0


def test_csv_errors_name_the_file(tmp_path):
    _write_csv(tmp_path / "a.csv", ["q1", "q2"], [[1, 2], [3, 4]])
    _write_csv(tmp_path / "b.csv", ["q1", "q2"], [[1, 2], ["x", 4]])
    with pytest.raises(DataError, match=r"b\.csv, field 'motor', sample 1: line 3, column 'q1': 'x' is not a number"):
        import_csv_folder(tmp_path, 5)
    (tmp_path / "b.csv").unlink()
    _write_csv(tmp_path / "c.csv", ["q1", "q3"], [[1, 2], [3, 4]])
    with pytest.raises(DataError, match=r"c\.csv, field 'header', sample 1: header"):
        import_csv_folder(tmp_path, 5)
    (tmp_path / "c.csv").unlink()
    _write_csv(tmp_path / "d.csv", ["q1", "q2"], [[1, 2]])
    with pytest.raises(DataError, match=r"d\.csv, field 'motor', sample 1: a sequence of length 1"):
        import_csv_folder(tmp_path, 5)
    (tmp_path / "d.csv").write_text("q1,q2\n")
    with pytest.raises(DataError, match=r"d\.csv.*zero-length"):
        import_csv_folder(tmp_path, 5)
    with pytest.raises(DataError, match="holds no .csv files"):
        import_csv_folder(tmp_path / "push", 5) if (tmp_path / "push").mkdir() is None else None


def test_lasa_shapes_labels_and_velocities():
    names = lasa_shape_names()
    assert len(names) == 26 and not any(n.startswith("Multi_Models") for n in names)
    ds = import_lasa(length=50, shapes=["Sine", "Angle"], velocities=True)
    assert ds.motor.shape == (14, 50, 4)
    assert ds.joint_names == ["x", "y", "vx", "vy"]
    assert ds.label_names == ["Sine", "Angle"]
    np.testing.assert_array_equal(ds.labels, [0] * 7 + [1] * 7)
    # LASA demonstrations end at the attractor, the origin
    np.testing.assert_allclose(ds.motor[:, -1, :2], 0.0, atol=1e-3)
    with pytest.raises(UserError, match="unknown LASA shape"):
        import_lasa(length=50, shapes=["Circle"])


# ----------------------------------------------------------- values too large, time column


@pytest.mark.parametrize(
    "arrays, match",
    [
        # a float64 list of sequences: named as too large, at its step and joint, before resampling
        (
            dict(arr_0=np.zeros((5, 2)), arr_1=np.array([[0.0, 0.0], [0.0, 1e39], [0.0, 0.0]])),
            r"field 'motor', sample 1: value 1e\+39 exceeds the float32 range \(magnitude at most 3\.40282e\+38\) \(step 1, joint 1\)",
        ),
        (
            dict(motor=np.concatenate([np.zeros((3, 4, 2)), np.full((1, 4, 2), -4e38)])),
            r"field 'motor', sample 3: value -4e\+38 exceeds the float32 range .*\(step 0, joint 0\)",
        ),
        (
            dict(motor=np.r_[np.zeros((4, 2)), [[5e40, 0.0]]], lengths=[2, 3]),
            r"field 'motor', sample 1: value 5e\+40 exceeds",
        ),
        (
            dict(arr_0=np.array([[0.0], [np.longdouble("1e400")]], dtype=np.longdouble)),
            r"field 'motor', sample 0: value 1e\+400 exceeds the float32 range",
        ),
        (
            dict(arr_0=np.zeros((5, 2)), arr_1=np.zeros((5, 2)), params=np.array([[1.0, 0.0], [0.0, 1e39]])),
            r"field 'params', sample 1: value 1e\+39 exceeds the float32 range .*\(column 1\)",
        ),
        (
            dict(arr_0=np.zeros((5, 2)), labels=np.array([2**32], dtype=np.int64)),
            r"field 'labels', sample 0: label 4294967296 is not a primitive index",
        ),
        (dict(arr_0=np.zeros((5, 2)), dt=np.array("fast")), r"field 'dt': must be one positive number"),
        (
            dict(arr_0=np.zeros((5, 2)), dt=np.array([0.1, 0.2])),
            r"field 'dt': must be one positive number, got 2 value",
        ),
    ],
)
def test_npz_values_too_large_for_float32_are_named_not_called_inf(tmp_path, arrays, match):
    path = tmp_path / "big.npz"
    np.savez(path, **arrays)
    with pytest.raises(DataError, match=r"big\.npz, " + match) as info:
        import_npz(path, 10)
    assert "NaN or inf" not in str(info.value)


def test_npz_int64_values_always_fit_float32(tmp_path):
    # |int64| < 9.3e18, far below float32's 3.4e38: extreme integers import (rounded), finite
    motor = np.array([[[np.iinfo(np.int64).max], [np.iinfo(np.int64).min]]] * 2, dtype=np.int64)
    np.savez(tmp_path / "i.npz", motor=motor)
    ds = import_npz(tmp_path / "i.npz", 2)
    assert ds.motor.dtype == np.float32 and np.isfinite(ds.motor).all()
    np.testing.assert_allclose(ds.motor[0, :, 0], [9.223372e18, -9.223372e18], rtol=1e-6)


def test_csv_value_too_large_names_file_line_and_column(tmp_path):
    _write_csv(tmp_path / "a.csv", ["time", "q1", "q2"], [[0, 1, 2], [1, 3, 4]])
    (tmp_path / "b.csv").write_text("time,q1,q2\n0,1,2\n\n1,3,1e39\n")  # a blank line: line numbers stay the file's
    with pytest.raises(DataError) as info:
        import_csv_folder(tmp_path, 5)
    assert str(info.value) == (
        f"{tmp_path / 'b.csv'}, field 'motor', sample 1: line 4, column 'q2': "
        "value 1e+39 exceeds the float32 range (magnitude at most 3.40282e+38)"
    )
    (tmp_path / "b.csv").write_text("time,q1,q2\n0,1,2\n1,-1e400,4\n")  # overflows even float64
    with pytest.raises(
        DataError, match=r"b\.csv, field 'motor', sample 1: line 3, column 'q1': value -1e400 exceeds the float32 range"
    ):
        import_csv_folder(tmp_path, 5)


@pytest.mark.parametrize(
    "text, match",
    [
        (
            "time,q1\n0,1\n0.5,2\n0.5,3\n",
            r"field 'time', sample 0: line 4: time 0\.5 does not come after 0\.5 on line 3 \(time stamps must strictly increase\)",
        ),
        ("t,q1\n0,1\n2,2\n1,3\n", r"field 't', sample 0: line 4: time 1 does not come after 2 on line 3"),
        ("Time,q1\n0,1\nnan,2\n1,3\n", r"field 'Time', sample 0: line 3: time stamp 'nan' is not a finite number"),
        (
            "time,q1\n0,1\n1e400,2\n",
            r"field 'time', sample 0: line 3, column 'time': value 1e400 exceeds the float64 range",
        ),
        ("t,time,q1\n0,0,1\n1,1,2\n", r"field 'header', sample 0: has 2 time columns \(t, time\); keep one"),
        ("q1,q1\n0,1\n1,2\n", r"field 'header', sample 0: column 'q1' appears twice"),
    ],
)
def test_csv_time_column_must_be_finite_and_strictly_increasing(tmp_path, text, match):
    (tmp_path / "demo.csv").write_text(text)
    with pytest.raises(DataError, match=r"demo\.csv, " + match):
        import_csv_folder(tmp_path, 5)


def test_csv_time_column_increasing_is_accepted_and_sets_dt(tmp_path):
    (tmp_path / "demo.csv").write_text("time,q1\n-1,1\n0,2\n\n3,3\n")
    ds = import_csv_folder(tmp_path, 5)
    assert ds.dt == pytest.approx(4 / 4)


def test_resample_names_a_long_double_value_float64_cannot_hold():
    seq = np.zeros((4, 2), dtype=np.longdouble)
    seq[2, 1] = np.longdouble("1e400")
    with pytest.raises(
        DataError, match=r"field 'motor', sample 1: value 1e\+400 exceeds the float64 range \(step 2, joint 1\)"
    ):
        resample([np.zeros((3, 2)), seq], 5)
