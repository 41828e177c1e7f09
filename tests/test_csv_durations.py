"""CSV folders whose files last differently (issue 37, section 3): each file is resampled to
T steps (time normalised per demonstration, as the paper does), and its own duration is kept
as the parameter ``duration`` instead of vanishing into one ``dt``."""

import numpy as np

from primspace.data import MotionDataset, import_csv_folder


def _write(path, t, values):
    rows = "\n".join(",".join(f"{v:g}" for v in (s, *x)) for s, x in zip(t, values))
    path.write_text("time,q1,q2\n" + rows + "\n")


def test_each_files_duration_is_kept_and_said(tmp_path):
    rng = np.random.default_rng(0)
    for name, seconds in (("a", 1.0), ("b", 2.5), ("c", 2.0)):
        t = np.arange(0, seconds + 1e-9, 0.1)
        _write(tmp_path / f"{name}.csv", t, rng.normal(size=(len(t), 2)))
    ds = import_csv_folder(tmp_path, 11)
    assert ds.param_names == ["duration"]  # before: no params, every file "lasting" the mean
    np.testing.assert_allclose(ds.params[:, 0], [1.0, 2.5, 2.0])
    np.testing.assert_allclose(ds.dt, np.mean([1.0, 2.5, 2.0]) / 10)
    assert "durations 1-2.5 s, each resampled to 11 steps, dt = their mean / 10" in ds.source
    ds.save(tmp_path / "d.h5")
    np.testing.assert_allclose(MotionDataset.load(tmp_path / "d.h5").params[:, 0], [1.0, 2.5, 2.0])


def test_equal_durations_or_no_clock_add_nothing(tmp_path):
    for name in ("a", "b"):
        t = np.arange(0, 1.0 + 1e-9, 0.25)
        _write(tmp_path / f"{name}.csv", t, np.ones((len(t), 2)))
    ds = import_csv_folder(tmp_path, 6)
    assert ds.params is None and "; durations" not in ds.source
    other = tmp_path / "noclock"
    other.mkdir()
    (other / "a.csv").write_text("q1,q2\n1,2\n3,4\n")
    (other / "b.csv").write_text("q1,q2\n1,2\n3,4\n5,6\n")
    ds = import_csv_folder(other, 5)
    assert ds.params is None and ds.dt == 1.0
