"""`predict` options are honoured or refused in one line, never silently ignored, and the work
they ask for is bounded before it starts.

- ``--online --iterations`` is read by gradient inference only: with the mixture or the prior
  (which predict each arriving step without iterations) it is refused.
- A primitive named by a label name that two labels share is ambiguous: refused, naming the ids.
- ``--prior-samples`` is at most ``primspace.predict.prior.MAX_PRIOR_SAMPLES``.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.utils.errors import UserError


@pytest.fixture
def data(tmp_path):
    from primspace.data import MotionDataset

    MotionDataset(np.zeros((2, 5, 2), np.float32), labels=np.array([0, 1]), dt=0.1).save(tmp_path / "d.h5")
    return tmp_path / "d.h5"


@pytest.mark.parametrize("predictor", [[], ["--init", "mixture"], ["--init", "prior"], ["--primitive", "push"]])
@pytest.mark.parametrize("iterations", ["7", "-1", "100000000"])
def test_online_iterations_are_refused_where_no_iteration_reads_them(run_cli, tmp_path, data, predictor, iterations):
    """Refused before any work (the run does not exist here)."""
    res = run_cli(
        "predict", tmp_path / "run", data, "--online", "--iterations", iterations, *predictor,
        "--out", tmp_path / "o",
    )  # fmt: skip
    assert_user_error(res, "--iterations", "gradient")
    assert not (tmp_path / "o").exists()


def test_online_iterations_still_go_to_gradient_inference(run_cli, tmp_path, data):
    res = run_cli(
        "predict", tmp_path / "run", data, "--online", "--iterations", "7", "--init", "zero",
        "--out", tmp_path / "o",
    )  # fmt: skip
    assert res.code == 2 and "--iterations" not in res.err  # refused for the missing run, not for --iterations


def test_a_label_name_two_labels_share_is_refused_by_name_and_taken_by_id():
    from primspace.predict.primitives import primitives_from_labels

    primitives = primitives_from_labels(np.array([0, 1, 2, 0, 1, 2]), ["push", "reach", "push"])
    with pytest.raises(UserError, match=r"'push' names primitives 0 and 2"):
        primitives.resolve("push")
    assert primitives.resolve("reach") == 1 and primitives.resolve(2) == 2 and primitives.resolve("2") == 2


@pytest.mark.parametrize("samples", ["1000000000", "50001"])
def test_prior_samples_are_bounded_before_any_work(run_cli, tmp_path, data, samples):
    from primspace.predict.prior import MAX_PRIOR_SAMPLES

    res = run_cli(
        "predict", tmp_path / "run", data, "--init", "prior", "--prior-samples", samples,
        "--out", tmp_path / "o",
    )  # fmt: skip
    assert_user_error(res, "--prior-samples", samples, str(MAX_PRIOR_SAMPLES))
    assert not (tmp_path / "o").exists()


def test_the_prior_predictor_bounds_its_draws():
    from primspace.predict.prior import MAX_PRIOR_SAMPLES, PriorPredictor

    with pytest.raises(UserError, match=f"n_samples must be a whole number in 2..{MAX_PRIOR_SAMPLES}"):
        PriorPredictor(None, n_samples=MAX_PRIOR_SAMPLES + 1)._check_params()
