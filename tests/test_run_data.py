"""A run's data: samples numbered by the data file's index (a run fitted on a subset finds
them again after loading), and a recorded data file that moved is named as the run's, with
how to give another (issue 37, section 3)."""

import shutil

import numpy as np
import pytest

from primspace.data import MotionDataset
from primspace.train import TrainConfig, check_run_data, fit, infer, load_run
from primspace.train.rundata import load_fitted_data
from primspace.utils.errors import DataError, UserError
from test_train import SMALL, primitives

TC = TrainConfig(epochs=1, batch_size=12, threads=1, seed=3)
PICKED = [2, 5, 7, 9]


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A run fitted on ``data.subset(PICKED)`` of a data file, written to disk."""
    where = tmp_path_factory.mktemp("subset-fit")
    path = primitives(4, seed=0).save(where / "demos.h5")
    data = MotionDataset.load(path)
    fit(data.subset(PICKED), where / "run", model_config=SMALL, train_config=TC, progress=False)
    return where, path


def test_a_subset_knows_its_rows_in_the_file():
    data = primitives(2, seed=0)
    np.testing.assert_array_equal(data.file_indices, np.arange(len(data)))
    sub = data.subset([5, 1, 3]).subset([2, 0])
    np.testing.assert_array_equal(sub.file_indices, [3, 5])
    np.testing.assert_array_equal(data.subset([4, 1]).rows_of([1, 4]), [1, 0])
    assert data.subset([4, 1]).rows_of([0]) is None
    np.testing.assert_array_equal(data.subset(np.arange(6) % 2 == 0).file_indices, [0, 2, 4])
    with pytest.raises(DataError, match="file_indices"):
        MotionDataset(np.zeros((3, 5, 2)), file_indices=[0, 1])


def test_a_run_fitted_on_a_subset_records_the_files_indices_and_finds_its_data(fitted):
    where, path = fitted
    run = load_run(where / "run")
    np.testing.assert_array_equal(run.indices, PICKED)  # before: 0..3, the subset's rows
    data = MotionDataset.load(path)
    check_run_data(run, data)  # before: "its joint values differ ... not its data"
    np.testing.assert_array_equal(load_fitted_data(run).motor, data.subset(PICKED).motor)
    # the subset it was fitted on, in any order, holds them too
    np.testing.assert_array_equal(
        load_fitted_data(run, data.subset(PICKED[::-1] + [0])).motor, data.subset(PICKED).motor
    )
    # a start that reads the fitted samples finds them in the recorded file
    new = primitives(1, seed=50)
    inferred = infer(run, new, epochs=0, init="nearest", progress=False)
    assert all((run.latents == row).all(axis=1).any() for row in inferred.initial_latents)


def test_another_subset_or_file_is_refused_in_one_line(fitted):
    where, path = fitted
    run = load_run(where / "run")
    data = MotionDataset.load(path)
    with pytest.raises(UserError, match="does not hold sample 2 of the data file"):
        load_fitted_data(run, data.subset([0, 5, 7, 9]))
    with pytest.raises(UserError, match="a subset.*give the whole file"):
        check_run_data(run, data.subset(PICKED))
    other = primitives(4, seed=1)
    with pytest.raises(UserError, match="joint values differ"):
        load_fitted_data(run, other)


def test_a_moved_data_file_is_named_as_the_runs_with_how_to_give_it(fitted, tmp_path):
    where, path = fitted
    moved = tmp_path / "demos.h5"
    shutil.copy(path, moved)
    run_dir = tmp_path / "run"
    shutil.copytree(where / "run", run_dir)
    run = load_run(run_dir)
    run.data_path = str(tmp_path / "gone.h5")  # as after `mv demos.h5 elsewhere/`
    with pytest.raises(UserError) as err:
        load_fitted_data(run)
    message = str(err.value)
    assert "gone.h5: no such file: it is the data file run" in message and "recorded in its config.json" in message
    assert "fitted_data=MotionDataset.load(PATH)" in message and "\n" not in message
    from primspace.cli.app import as_flags  # the command line (predict) names its flag instead

    assert as_flags(message).endswith("give its new place as --fitted-data PATH")
    np.testing.assert_array_equal(
        load_fitted_data(run, MotionDataset.load(moved)).motor, MotionDataset.load(moved).subset(PICKED).motor
    )


def test_a_run_fitted_in_memory_without_a_file_asks_for_fitted_data():
    data = primitives(2, seed=0)
    run = fit(data.subset([1, 3]), None, model_config=SMALL, train_config=TC, progress=False)
    np.testing.assert_array_equal(run.indices, [1, 3])
    with pytest.raises(UserError, match="records no data file: give fitted_data="):
        load_fitted_data(run)
    np.testing.assert_array_equal(load_fitted_data(run, data).motor, data.motor[[1, 3]])
