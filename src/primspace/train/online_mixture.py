"""The mixture as an online predictor (issue 25, item 3): no gradient, a few milliseconds a step.

Gradient inference a step at a time (:mod:`primspace.train.online`) lags its own offline
error unless it runs many iterations per step, more than 20 ms allow on one core
(docs/predict.md, *Online*). The mixture over the fitted codes
(:class:`~primspace.train.mixture.CodeMixture`) needs no iterations: after step ``t`` its
prediction is a function of the prefix ``1..t`` alone, so following a motion online gives
exactly the offline prediction from the same prefix, and an arriving step costs one
update of the squared distances to the decoded candidates (``c x J`` numbers per motion),
the posterior weights and the weighted mean of the candidates. Predictive coding in the
paper's words, "Predicted information is compared with the real one and internal state is
corrected based on the error" (paper, *Background*): the internal state is the posterior
over the candidates, corrected by each step's error.

What does not depend on the new motion is prepared before it arrives, from the fitted
demonstrations only: the candidates (decoded once per run) and ``σ²`` for every prefix
length (the leave-one-out choice of :meth:`~primspace.train.mixture.CodeMixture.choose_noise`,
posterior mean only: the ensemble conditioning's choice costs seconds per prefix length).
"""

from __future__ import annotations

import os
import time

import numpy as np

from primspace.data import MotionDataset
from primspace.data.steps import valid_steps
from primspace.errors import UserError
from primspace.peers import unobserved_mse
from primspace.progress import progress_bar
from primspace.train.api import as_run
from primspace.train.checks import check_data_fits
from primspace.train.mixture import continuity_correction
from primspace.train.observe import Observation, fitted_samples, observation_masks
from primspace.train.online import OnlineResult
from primspace.train.run import TrainedRun

__all__ = ["mixture_online", "prepare_noises"]


def prepare_noises(parent: TrainedRun, steps, fitted_data: MotionDataset | None = None) -> dict:
    """``{t: σ²}``: the mixture's leave-one-out noise for a prefix of ``t`` steps, for each ``t``
    of ``steps`` (the fitted demonstrations only; computed before any new motion arrives)."""
    from primspace.train.predict import code_mixture

    mixture, fitted = code_mixture(parent), fitted_samples(parent, fitted_data)
    scaled, valid = parent.scaler.transform(fitted.motor), observation_masks(None, fitted)[0]
    return {int(t): mixture.choose_noise(scaled, observation_masks(Observation.build(int(t)), fitted)[0], valid,
                                         conditions=(None,))["noise"] for t in steps}


def mixture_online(run: TrainedRun | str | os.PathLike, data: MotionDataset, *, start_step: int = 1,
                   fitted_data: MotionDataset | None = None, continuity: bool = True, noises: dict | None = None,
                   prediction_after: int | None = None, progress: bool | None = None) -> OnlineResult:
    """The mixture's prediction after each arriving step ``start_step..T`` (no gradient).

    Equal, after step ``t``, to ``predict(run, data, observe=t, init="mixture",
    condition=False, continuity=continuity)`` (tested).

    Parameters
    ----------
    run : TrainedRun or path-like
    data : MotionDataset
        The motions, with the run's T and J.
    start_step : int
        The first step to arrive (1..T).
    fitted_data : MotionDataset, optional
        The data set the run was fitted on (default: its data file).
    continuity : bool
        :func:`~primspace.train.mixture.continuity_correction` after each step.
    noises : dict of int to float, optional
        ``σ²`` per prefix length (:func:`prepare_noises`; default: prepared here, before
        the first step, and not counted in the latency).
    prediction_after : int, optional
        The step after which :attr:`OnlineResult.prediction` is kept (default: the last, T).
    progress : bool, optional

    Returns
    -------
    OnlineResult
        ``iterations`` 0, ``latent_lr`` NaN (no gradient); ``codes`` the posterior mode
        after each step (``start_codes``: after the first); ``latency`` the seconds of each step's update, weights, mean and
        correction for the whole batch.
    """
    from primspace.train.predict import code_mixture

    parent = as_run(run)
    if not isinstance(data, MotionDataset):
        raise UserError(f"expected a MotionDataset, got {type(data).__name__}")
    check_data_fits(data, parent.model_config, False)
    length = data.length
    if isinstance(start_step, bool) or not isinstance(start_step, (int, np.integer)) or not 1 <= start_step <= length:
        raise UserError(f"start_step must be a whole number in 1..T={length}, got {start_step!r}")
    steps = np.arange(int(start_step), length + 1)
    keep = length if prediction_after is None else int(prediction_after)
    if keep not in steps:
        raise UserError(f"prediction_after must be a step in {int(start_step)}..{length}, got {prediction_after!r}")
    mixture = code_mixture(parent)
    noises = prepare_noises(parent, steps, fitted_data) if noises is None else noises
    truth = parent.scaler.transform(data.motor)
    lengths = data.lengths if data.lengths is not None else np.full(len(data), length)
    valid = valid_steps(lengths, length)
    n, kept = len(data), None
    by_step = np.ascontiguousarray(mixture.decoded.transpose(1, 0, 2))  # (T, c, J): a step's candidates together
    squares = (by_step**2).sum(axis=2)  # (T, c)

    def arrive(t: int) -> np.ndarray:  # (n, c): the squared distances of step t (1-based), valid samples only
        x = truth[:, t - 1]
        step = (x**2).sum(axis=1)[:, None] + squares[t - 1][None] - 2.0 * x @ by_step[t - 1].T
        return valid[:, t - 1, None] * np.maximum(step, 0.0)

    d2 = np.zeros((n, by_step.shape[1]))
    for t in range(1, int(start_step)):  # the steps before the first arrival
        d2 += arrive(t)
    codes = np.empty((n, len(steps), mixture.candidates.shape[1]), dtype=np.float32)
    errors, latency = np.empty((n, len(steps))), np.empty(len(steps))
    with progress_bar(len(steps), "online mixture", enabled=progress) as advance:
        for s, t in enumerate(steps):
            t0 = time.perf_counter()
            d2 += arrive(int(t))
            energy = d2 / (2.0 * noises[int(t)])
            w = np.exp(-(energy - energy.min(axis=1, keepdims=True)))
            w /= w.sum(axis=1, keepdims=True)
            predicted = mixture.posterior_mean(w)
            observed = (np.arange(length) < t)[None, :] & valid
            if continuity:
                predicted = continuity_correction(predicted, truth, observed, valid)
            latency[s] = time.perf_counter() - t0
            codes[:, s] = mixture.candidates[np.argmax(w, axis=1)]
            kept = predicted if t == keep else kept
            errors[:, s] = unobserved_mse(predicted, truth, observed, lengths)
            advance()
    return OnlineResult(steps=steps, codes=codes, start_codes=codes[:, 0].copy(), errors=errors, latency=latency,
                        prediction=parent.scaler.inverse_transform(kept).astype(np.float32), iterations=0,
                        init="mixture", latent_lr=float("nan"))
