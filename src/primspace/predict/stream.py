"""Online prediction, one loop for every predictor: the steps of a motion arrive one at a time.

After each arriving step ``t`` (a counter shared by the motions of a batch, each within its own
valid length) a predictor updates what it keeps and predicts the whole sequence; the steps after
``t`` are the forecast. :func:`follow` is that loop, written once: it times each step, scores the
prediction of the remaining valid steps (:func:`~primspace.predict.metrics.unobserved_mse`, the
one measure) and keeps the prediction after the step asked for. What differs between predictors
is the update of a step, a :class:`Stream`: :meth:`primspace.predict.base.Predictor.predict_online`
asks the predictor for one (:meth:`~primspace.predict.base.Predictor.stream`) and follows it; the
online gradient inference (:func:`~primspace.predict.online.infer_online`) follows its own.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from primspace.predict.metrics import unobserved_mse
from primspace.utils.errors import UserError
from primspace.utils.progress import progress_bar

__all__ = ["OnlineResult", "Stream", "follow", "online_steps", "mean_over_samples", "prefix_mask"]


def prefix_mask(n: int, length: int, t: int) -> np.ndarray:
    """(n, T) bool: steps ``1..t`` observed (a sample's padding is left out by its length)."""
    return np.broadcast_to(np.arange(length) < t, (n, length))


def mean_over_samples(errors: np.ndarray) -> np.ndarray:
    """The mean over samples (axis 0) of the finite errors; NaN where there are none."""
    finite = np.isfinite(errors)
    counts = finite.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, np.where(finite, errors, 0.0).sum(axis=0) / counts, np.nan)


@dataclass
class OnlineResult:
    """What online prediction returns: codes, forecast errors and latency after each step.

    Attributes
    ----------
    steps : ndarray (S,) int
        The steps observed, ``start_step..T``: column ``s`` is "after step ``steps[s]``".
    codes : ndarray (n, S, q) float32
        Each sample's code after each step (the internal state, corrected by the error).
    start_codes : ndarray (n, q) float32
        The codes before the first step (the chosen start; the closed-form predictors: after it).
    errors : ndarray (n, S) float64
        Motor MSE (scaled units) of the prediction of the remaining valid steps ``> t``
        (:func:`~primspace.predict.metrics.unobserved_mse`); NaN for a sample with none left.
    latency : ndarray (S,) float64
        Seconds of each arriving step's update and prediction for the whole batch
        (``time.perf_counter``; CUDA synchronised).
    prediction : ndarray (n, T, J) float32
        The prediction after the step asked for (default T), in physical units (the run's scaler inverted).
    iterations : int
        Gradient iterations per step (0: a closed-form update).
    init : str
        The predictor (or gradient start) that followed the motions.
    latent_lr : float
        The codes' learning rate (NaN: no gradient).
    """

    steps: np.ndarray
    codes: np.ndarray
    start_codes: np.ndarray
    errors: np.ndarray
    latency: np.ndarray
    prediction: np.ndarray
    iterations: int
    init: str
    latent_lr: float

    @property
    def mean_error(self) -> np.ndarray:
        """(S,) the mean over samples of :attr:`errors` (samples with steps left; NaN if none)."""
        return mean_over_samples(self.errors)

    @property
    def latency_mean(self) -> float:
        """Mean seconds per arriving step."""
        return float(np.mean(self.latency))

    @property
    def latency_p95(self) -> float:
        """95th percentile of the seconds per arriving step."""
        return float(np.percentile(self.latency, 95))

    def column(self, t: int) -> int:
        """The column of :attr:`codes` / :attr:`errors` after step ``t``."""
        hits = np.flatnonzero(self.steps == int(t))
        if not hits.size:
            raise UserError(f"step {t} was not recorded (steps {int(self.steps[0])}..{int(self.steps[-1])})")
        return int(hits[0])

    def error_at(self, t: int) -> float:
        """The mean error of the remaining steps after step ``t``."""
        return float(self.mean_error[self.column(t)])


class Stream:
    """A predictor following a batch of motions, a step at a time (prepared before the first step).

    A subclass implements :meth:`arrive`; what it prepares in its constructor (choices per
    prefix length, gains, the steps before the first arrival) is not counted in the latency.

    Attributes
    ----------
    scaler
        The run's scaler (the kept prediction is returned in physical units).
    init : str
        The name the result records.
    iterations : int
        Gradient iterations per step (0: closed form).
    latent_lr : float
        The codes' learning rate (NaN: no gradient).
    start_codes : ndarray (n, q) or None
        The codes before the first step (None: those after it).
    """

    scaler = None
    init = ""
    iterations = 0
    latent_lr = float("nan")
    start_codes = None

    def arrive(self, t: int) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - interface
        """Observe step ``t`` (1-based): the prediction ``(n, T, J)`` (scaled units) and the codes ``(n, q)``."""
        raise NotImplementedError

    def sync(self) -> None:
        """Wait for the device (a CUDA stream), so that the latency counts the step's work."""


def follow(
    stream: Stream,
    truth: np.ndarray,
    lengths: np.ndarray,
    steps: np.ndarray,
    keep: int,
    *,
    label: str = "online",
    progress: bool | None = None,
) -> OnlineResult:
    """Steps ``steps`` arrive one at a time at ``stream``; the result after each (module docstring).

    ``truth`` ``(n, T, J)`` scaled, ``lengths`` each motion's valid steps, ``keep`` the step after
    which the prediction is kept (one of ``steps``)."""
    n, length = truth.shape[:2]
    codes, errors, latency, kept = None, np.empty((n, len(steps))), np.empty(len(steps)), None
    with progress_bar(len(steps), label, enabled=progress) as advance:
        for s, t in enumerate(steps):
            stream.sync()
            t0 = time.perf_counter()
            predicted, code = stream.arrive(int(t))
            stream.sync()
            latency[s] = time.perf_counter() - t0
            if codes is None:
                codes = np.empty((n, len(steps), code.shape[1]), dtype=np.float32)
            codes[:, s] = code
            errors[:, s] = unobserved_mse(predicted, truth, prefix_mask(n, length, t), lengths)
            if t == keep:
                kept = predicted
            advance()
    return OnlineResult(
        steps=steps,
        codes=codes,
        start_codes=codes[:, 0].copy() if stream.start_codes is None else stream.start_codes,
        errors=errors,
        latency=latency,
        prediction=stream.scaler.inverse_transform(kept).astype(np.float32),
        iterations=int(stream.iterations),
        init=stream.init,
        latent_lr=float(stream.latent_lr),
    )


def online_steps(start_step, prediction_after, length: int) -> tuple[np.ndarray, int]:
    """The arriving steps ``start_step..T`` (1-based) and the step after which the prediction is kept
    (``prediction_after``, default T), or one UserError."""
    if isinstance(start_step, bool) or not isinstance(start_step, (int, np.integer)) or not 1 <= start_step <= length:
        raise UserError(f"start_step must be a whole number in 1..T={length}, got {start_step!r}")
    steps = np.arange(int(start_step), length + 1)
    keep = length if prediction_after is None else prediction_after
    if keep not in steps:
        raise UserError(f"prediction_after must be a step in {int(start_step)}..{length}, got {prediction_after!r}")
    return steps, int(keep)
