"""``train --scale-over-file``: the joints scaled to [-1, 1] over every sample of the file, as the
experiments scale every run (errors then in their units), instead of over the samples trained on."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import JointScaler, MotionDataset
from primspace.train import load_run

FLAGS = ["--epochs", "1", "--layers", "4,2", "--latent-dim", "2", "--batch-size", "4", "--threads", "1"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("scale")
    motor = np.random.default_rng(0).normal(size=(8, 6, 2)).astype(np.float32)
    motor[1::2] *= 3  # the samples not trained on reach further
    MotionDataset(motor, dt=0.1).save(root / "d.h5")
    (root / "fit.txt").write_text("\n".join(str(i) for i in range(0, 8, 2)) + "\n")
    return root


def test_the_scaling_is_fitted_on_the_whole_file_when_asked(run_cli, files, tmp_path):
    data = MotionDataset.load(files / "d.h5")
    whole = JointScaler().fit(data.motor)
    fitted = JointScaler().fit(data.motor[0::2])
    for flag, expected in (([], fitted), (["--scale-over-file"], whole)):
        out = tmp_path / ("file" if flag else "fitted")
        res = run_cli("train", files / "d.h5", "--indices", files / "fit.txt", "--out", out, *FLAGS, *flag)
        assert res.code == 0, res.err
        scaler = load_run(out).scaler
        np.testing.assert_array_equal(scaler.data_min_, expected.data_min_)
        np.testing.assert_array_equal(scaler.data_max_, expected.data_max_)
    assert not np.array_equal(whole.data_min_, fitted.data_min_)  # the two differ on this data


def test_not_with_weights_from(run_cli, files, tmp_path):
    parent = tmp_path / "parent"
    assert run_cli("train", files / "d.h5", "--out", parent, *FLAGS).code == 0
    res = run_cli("train", files / "d.h5", "--out", tmp_path / "o", "--weights-from", parent, "--scale-over-file")
    assert_user_error(res, "--scale-over-file goes without --weights-from")
