"""The data a run was fitted (or inferred) on: its record, the check, and finding it again.

A run records its samples by their numbers in its data file (``config.json``
``data.indices``, :attr:`primspace.data.MotionDataset.file_indices`, the one rule of
:mod:`primspace.data.schema`, *Sample numbers*), the file's absolute path
(``data.path``) and the SHA-1 of those samples' joint values (``data.motor_sha1``).
:func:`check_run_data` refuses a data set that is not the run's file;
:func:`load_fitted_data` returns the run's own samples from the file it records, from
another copy of it, or from any data set holding them (a subset included), and says what
to pass when the recorded file is gone.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.train.run import TrainedRun
from primspace.utils.errors import UserError

__all__ = ["fingerprint", "check_run_data", "load_fitted_data", "recorded_data"]


def fingerprint(data: MotionDataset) -> str:
    """The SHA-1 of the samples' joint values (float32), as ``config.json`` records it."""
    return hashlib.sha1(np.ascontiguousarray(data.motor, dtype=np.float32).tobytes()).hexdigest()


def _name(run: TrainedRun) -> str:
    return str(run.run_dir) if run.run_dir is not None else "(in memory)"


def _check_shape(run: TrainedRun, dataset: MotionDataset, where: str) -> None:
    mc = run.model_config
    if dataset.n_joints != mc.n_joints or dataset.length != mc.length:
        raise UserError(
            f"{where}: has T={dataset.length} steps x J={dataset.n_joints} joints; run {_name(run)} "
            f"was trained on T={mc.length} x J={mc.n_joints}: not its data"
        )


def check_run_data(run: TrainedRun, dataset: MotionDataset) -> None:
    """Refuse a data set that is not the data file ``run`` was trained or inferred on.

    Compares what a resume compares: joints and steps, the run's sample numbers, and the
    SHA-1 of those samples' joint values (``config.json`` ``data.motor_sha1``). After it,
    ``dataset.subset(run.indices)`` are the run's samples. A subset of the file is refused
    (its rows are not the file's numbers): :func:`load_fitted_data` takes one.
    """
    where = str(dataset.path) if dataset.path is not None else "the data set"
    _check_shape(run, dataset, where)
    is_subset = not np.array_equal(dataset.file_indices, np.arange(len(dataset)))
    if is_subset:
        raise UserError(
            f"{where}: holds {len(dataset)} of its file's samples (a subset); run {_name(run)} numbers "
            "its samples by their index in the data file: give the whole file (or call "
            "primspace.train.rundata.load_fitted_data, which takes a subset)"
        )
    if len(run.indices) and int(run.indices.max()) >= len(dataset):
        raise UserError(
            f"{where}: has {len(dataset)} samples, run {_name(run)} used sample {int(run.indices.max())}: not its data"
        )
    saved = run.config.get("data", {}).get("motor_sha1")
    if saved is not None and fingerprint(dataset.subset(run.indices)) != saved:
        raise UserError(
            f"{where}: its joint values differ from those run {_name(run)} used "
            "(SHA-1 of the run's samples): not its data"
        )


def recorded_data(run: TrainedRun) -> MotionDataset:
    """The data file ``run`` records (``config.json`` ``data.path``), loaded; one line saying
    what it is and how to give another where there is none or it is gone."""
    if run.data_path is None:
        raise UserError(
            f"run {_name(run)} was fitted on a data set in memory and records no data file: "
            "give fitted_data= (the data set it was fitted on)"
        )
    path = Path(run.data_path)
    if not path.is_file():
        raise UserError(
            f"{path}: no such file: it is the data file run {_name(run)} was fitted on (recorded in "
            "its config.json); if it moved, give its new place as fitted_data=MotionDataset.load(PATH)"
        )
    return MotionDataset.load(path)


def load_fitted_data(run: TrainedRun, fitted_data: MotionDataset | None = None) -> MotionDataset:
    """The samples ``run`` was fitted (or inferred) on, in the run's row order, checked against its record.

    Parameters
    ----------
    run : TrainedRun
    fitted_data : MotionDataset, optional
        A data set holding them: the data file (wherever it is now), or any subset of it
        holding the run's samples (found by :attr:`~primspace.data.MotionDataset.file_indices`;
        e.g. the ``data.subset(...)`` the run was fitted on). Default: the data file the
        run records (:func:`recorded_data`).

    Raises
    ------
    UserError
        One line: no recorded file and none given, the recorded file gone (saying to give
        ``fitted_data=``), a data set of another shape, without the run's samples, or whose
        joint values differ from those the run used.
    """
    if fitted_data is None:
        fitted_data = recorded_data(run)
    if not isinstance(fitted_data, MotionDataset):
        raise UserError(f"fitted_data must be a MotionDataset, got {type(fitted_data).__name__}")
    where = str(fitted_data.path) if fitted_data.path is not None else "fitted_data"
    _check_shape(run, fitted_data, where)
    saved = run.config.get("data", {}).get("motor_sha1")
    tried = [fitted_data.rows_of(run.indices)]
    if len(run.indices) and int(run.indices.max()) < len(fitted_data):  # runs of primspace <= 0.8 fitted on a
        tried.append(run.indices)  # subset in memory recorded its rows: read them as rows of fitted_data
    for rows in tried:
        if rows is not None and (saved is None or fingerprint(fitted_data.subset(rows)) == saved):
            return fitted_data.subset(rows)
    if tried[0] is None:
        have = set(fitted_data.file_indices.tolist())
        missing = [int(i) for i in run.indices if int(i) not in have]
        raise UserError(
            f"{where}: does not hold sample {missing[0]} of the data file ({len(missing)} of run "
            f"{_name(run)}'s {len(run.indices)} samples missing): not its data"
        )
    raise UserError(
        f"{where}: its joint values differ from those run {_name(run)} used (SHA-1 of the run's samples): not its data"
    )
