"""The measure of a prediction, and the checks of the arrays every predictor reads.

The task of every predictor of :mod:`primspace.predict`: a demonstration's first steps are
observed (a boolean mask ``observed`` ``(n, T)``, a prefix of its valid steps); predict the
rest. :func:`unobserved_mse` is the one error of the motor, for primspace's predictors and
the peers alike (scaled units: the run's joints scaled to [-1, 1] over its fitted data);
:func:`frame_errors` the error of the frames ([0, 1] intensity, PSNR); :func:`finite_mean`
the mean over samples that had steps left. Steps at or after a sample's length are padding:
never observed, never scored.
"""

from __future__ import annotations

import math

import numpy as np

from primspace.utils.errors import UserError

__all__ = [
    "unobserved_mse",
    "frame_errors",
    "finite_mean",
    "observed_prefix",
    "check_motor",
    "check_lengths",
    "check_labels",
    "check_observed",
    "valid_mask",
]


def check_motor(motor, name: str = "motor") -> np.ndarray:
    """``motor`` as a non-empty float64 ``(n, T, J)`` array, or one UserError."""
    arr = np.asarray(motor, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[0] == 0 or arr.shape[1] == 0 or arr.shape[2] == 0:
        raise UserError(f"{name} must be a non-empty (n, T, J) array, got shape {arr.shape}")
    return arr


def check_lengths(lengths, n: int, steps: int) -> np.ndarray:
    """Valid steps per sample as int64 ``(n,)`` in [1, T] (T each when None), or one UserError."""
    if lengths is None:
        return np.full(n, steps, dtype=np.int64)
    arr = np.asarray(lengths)
    if arr.shape != (n,):
        raise UserError(f"lengths must have shape ({n},) like motor's first axis, got {arr.shape}")
    if arr.size and (not np.all(np.equal(np.mod(arr, 1), 0)) or arr.min() < 1 or arr.max() > steps):
        raise UserError(f"lengths must be whole numbers in [1, {steps}] (T = {steps})")
    return arr.astype(np.int64)


def check_labels(labels, n: int) -> np.ndarray | None:
    """Integer labels ``(n,)`` as int64 (None stays None), or one UserError."""
    if labels is None:
        return None
    arr = np.asarray(labels)
    if arr.shape != (n,):
        raise UserError(f"labels must have shape ({n},) like motor's first axis, got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise UserError(f"labels must be integers, got dtype {arr.dtype}")
    return arr.astype(np.int64)


def valid_mask(lengths: np.ndarray, steps: int) -> np.ndarray:
    """``(n, T)``: True on the valid (not padding) steps."""
    return np.arange(steps)[None, :] < lengths[:, None]


def check_observed(observed, shape: tuple[int, int], valid: np.ndarray) -> np.ndarray:
    """A boolean ``(n, T)`` mask that marks no padding step, or one UserError."""
    arr = np.asarray(observed)
    if arr.shape != shape:
        raise UserError(f"observed must have shape (n, T) = {shape} like motor's first two axes, got {arr.shape}")
    if arr.dtype != bool:
        raise UserError(f"observed must be a boolean mask, got dtype {arr.dtype}")
    bad = np.flatnonzero(np.any(arr & ~valid, axis=1))
    if bad.size:
        raise UserError(f"observed marks padding steps (at or after the length) of sample {int(bad[0])}")
    return arr


def observed_prefix(n: int, steps: int, fraction: float, lengths=None) -> np.ndarray:
    """The mask ``(n, T)`` of the first ``ceil(fraction * length)`` steps of each sample.

    Parameters
    ----------
    n, steps : int
        Samples and T.
    fraction : float
        In [0, 1]; ``ceil`` is taken with a 1e-9 tolerance, so ``0.1 * 100`` is 10 steps.
    lengths : array-like of int, optional
        Valid steps per sample (default T each): the prefix is a fraction of these.
    """
    if not 0.0 <= fraction <= 1.0:
        raise UserError(f"the observed fraction must be in [0, 1], got {fraction}")
    lengths = check_lengths(lengths, n, steps)
    counts = np.array([math.ceil(fraction * length - 1e-9) for length in lengths], dtype=np.int64)
    return np.arange(steps)[None, :] < counts[:, None]


def unobserved_mse(predicted, truth, observed, lengths=None) -> np.ndarray:
    """Per-sample mean squared error over the valid, unobserved steps (all joints).

    This is the one definition of the prediction error: the peers and primspace's own
    prediction are scored by it.

    Parameters
    ----------
    predicted, truth : array-like, shape (n, T, J)
    observed : array-like of bool, shape (n, T)
        The steps that were given to the predictor: not scored.
    lengths : array-like of int, optional
        Valid steps per sample; steps at or after it are padding and not scored.

    Returns
    -------
    ndarray, shape (n,)
        The mean over the scored steps and joints; NaN for a sample with none.
    """
    predicted = check_motor(predicted, "predicted")
    truth = check_motor(truth, "truth")
    if predicted.shape != truth.shape:
        raise UserError(f"predicted has shape {predicted.shape} but truth has {truth.shape}")
    n, steps, joints = truth.shape
    valid = valid_mask(check_lengths(lengths, n, steps), steps)
    observed = np.asarray(observed)
    if observed.shape != (n, steps):
        raise UserError(f"observed must have shape (n, T) = {(n, steps)}, got {observed.shape}")
    scored = valid & ~observed.astype(bool)
    sq = np.where(scored[..., None], (predicted - truth) ** 2, 0.0).sum(axis=(1, 2))
    count = scored.sum(axis=1) * joints
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, sq / np.maximum(count, 1), np.nan)


def frame_errors(predicted: np.ndarray, truth: np.ndarray, observed: np.ndarray, valid: np.ndarray) -> tuple:
    """Per-sample MSE ([0, 1] intensity) and PSNR (dB) over the unobserved valid frames.

    ``predicted``, ``truth``: (n, T, H, W, 3) uint8; ``observed``, ``valid``: (n, T) bool.
    NaN where no frame is left unobserved.
    """
    left = valid & ~observed
    mse = np.full(len(predicted), np.nan)
    for i in range(len(predicted)):
        if left[i].any():
            diff = predicted[i, left[i]].astype(np.float64) - truth[i, left[i]].astype(np.float64)
            mse[i] = float(np.mean(np.square(diff / 255.0)))
    with np.errstate(divide="ignore"):
        psnr = np.where(np.isfinite(mse), 10.0 * np.log10(1.0 / np.maximum(mse, 1e-12)), np.nan)
    return mse, psnr


def finite_mean(values) -> float | None:
    """The mean of the finite values (samples with steps left); None when there are none."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else None
