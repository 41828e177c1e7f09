"""The prediction numbers pinned before prediction moved into ``primspace.predict`` (issue 37).

A small run (the observation tests' data, 30 epochs, no learning-rate decay given
explicitly so a change of defaults cannot move it) and every row of the prediction grid
on its evaluation samples: the gradient starts, the mixture's variants, the peers, the
label-given diagnostic and the online predictors, at 10, 25 and 50 % observed. The
numbers were recorded with the code as it stood before the move (0.8.0) and are kept:
the refactor must reproduce them.
"""

import json
from pathlib import Path

import pytest

from conftest import pinned_for_this_cpu
from primspace.predict.grid import PRIOR_ROWS, TUNED_PEERS
from test_train import primitives, small_run

PINNED = Path(__file__).with_suffix(".json")
FRACTIONS = (0.1, 0.25, 0.5)
#: The priors' rows, small and fast (their numbers are not pinned, only that they exist): few draws,
#: fixed noise, temperature and blend (no K-fold choice), a short MAP and tiny encoders.
CHEAP_PRIORS = {
    "prior": dict(n_samples=200, noise=1e-3, temperature=10.0, blend=0.5),
    "map": dict(iterations=5),
    "encoder": dict(n_train=256, steps=20, hidden=16, batch_size=64),
}
#: The Gaussian peers' rows, small: the tuned ProMP's basis count fixed and few EM iterations.
CHEAP_PEERS = {"promp_tuned": dict(n_basis=8, n_iter=50)}


@pytest.fixture(scope="module")
def case():
    train, test = primitives(8, seed=0), primitives(4, seed=100)
    run = small_run(train, epochs=30, final_lr_fraction=1.0)
    return run, train, test


def grid_numbers(run, train, test) -> dict:
    """{row: {fraction: mean unobserved MSE}} of every predictor on ``test``."""
    from primspace.predict import grid_predictions

    return grid_predictions(
        run,
        train,
        test,
        FRACTIONS,
        epochs=5,
        online_iterations=2,
        prior_settings=CHEAP_PRIORS,
        peer_settings=CHEAP_PEERS,
    )


@pytest.mark.slow
def test_the_prediction_grid_keeps_its_numbers(case):
    pinned = pinned_for_this_cpu(json.loads(PINNED.read_text()), "prediction numbers", vendor=True)
    numbers = grid_numbers(*case)
    # the rows pinned before 0.9, the priors' (issue 39) and the Gaussian peers' (issue 50; pinned apart)
    assert set(numbers) - set(pinned) == set(PRIOR_ROWS) | {row for row, _, _ in TUNED_PEERS}
    for row, cells in pinned.items():
        for key, value in cells.items():
            assert numbers[row][key] == pytest.approx(value, rel=1e-6, abs=1e-12), (row, key)


def test_the_priors_settings_name_their_kinds():
    from primspace.predict.grid import grid_predictors
    from primspace.utils.errors import UserError

    with pytest.raises(UserError, match="prior_settings takes prior, map, encoder, got 'mixture'"):
        grid_predictors(None, None, (), 1, prior_settings={"mixture": {}})
