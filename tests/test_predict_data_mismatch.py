"""``predict`` on data of other joints or steps than the run's: one line naming the file, for every
predictor, before any is fitted (the mixture and the prior used to name neither the file nor the run)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset


@pytest.fixture(scope="module")
def run_and_files(tmp_path_factory):
    from primspace.cli import main

    root = tmp_path_factory.mktemp("mismatch")
    rng = np.random.default_rng(0)
    for name, shape in (("fit.h5", (6, 8, 2)), ("joints.h5", (6, 8, 3)), ("steps.h5", (6, 9, 2))):
        motor = rng.normal(size=shape).astype(np.float32)
        MotionDataset(motor, labels=np.arange(6) % 2, label_names=["a", "b"], dt=0.1).save(root / name)
    flags = ["--epochs", "1", "--layers", "4,2", "--latent-dim", "2", "--batch-size", "3", "--threads", "1"]
    try:
        main(["train", str(root / "fit.h5"), "--out", str(root / "run"), *flags])
    except SystemExit as exc:
        assert exc.code in (0, None), exc.code
    return root


@pytest.mark.parametrize("init", ["mixture", "prior", "zero"])
@pytest.mark.parametrize(
    ("name", "fragment"), [("joints.h5", "has T=8 steps x J=3 joints"), ("steps.h5", "has T=9 steps x J=2 joints")]
)
def test_other_joints_or_steps_are_refused_naming_the_file(run_cli, run_and_files, tmp_path, init, name, fragment):
    root = run_and_files
    res = run_cli("predict", root / "run", root / name, "--init", init, "--out", tmp_path / "o")
    assert_user_error(res, f"{root / name}: {fragment}", "the model expects T=8 x J=2")
    assert not (tmp_path / "o").exists()
