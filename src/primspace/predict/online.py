"""Online inference as predictive coding: the code follows a motion as its steps arrive.

The paper's Background describes predictive coding: "Predicted information is compared
with the real one and internal state is corrected based on the error". Here the internal
state is the code ``z`` of each demonstration, the prediction is the decoder's whole
sequence ``d(θ, z)``, and the real information is the prefix of the motion seen so far.
After each arriving step ``t`` (a counter shared by the samples of a data set, which are
processed together as one batch, each within its own valid length):

1. ``k`` iterations of the row-wise Adam of :func:`~primspace.train.infer`
   (:class:`~primspace.model.latent.LatentTable`: the run's ``latent_lr``, Adam's betas) on the
   codes, θ frozen, with the loss of ``infer(..., observe=t)``
   (:func:`~primspace.train.loss.batch_loss`: the motor MSE over each sample's observed
   valid entries, plus the vision term over its observed frames when the run uses
   frames), warm-started from the code after step ``t - 1``. By default each step's
   Adam starts afresh (moments reset) on the warm code; ``carry_moments=True`` runs
   one Adam along the stream instead;
2. one decode: the motor prediction of the whole sequence, steps ``t+1..T`` being the
   forecast.

The code before the first step comes from the chosen start under an observation of
``start_step`` steps (:func:`~primspace.train.starts.inference_start`, exactly the start
of ``infer(..., observe=start_step)``).

Differences from :func:`~primspace.train.infer`: the learning rate is constant (infer's
cosine schedule runs over epochs, and a stream has none); the vision term is computed on
every observed frame (infer may draw ``vision_frames`` of them); float32 (no autocast);
no run directory, no checkpoint, no data loader: a plain torch loop over the model. The
decoder is causal, so the iterations run the recurrence over the observed prefix only
(``t / T`` of a full pass; not with a code window); a step costs ``k`` forward/backward
passes over ``t`` steps and one motor-only forward pass over ``T``.

The error of the remaining steps is :func:`primspace.predict.metrics.unobserved_mse` (motor MSE in
scaled units over each sample's valid steps after ``t``), the measure that
:func:`offline_errors` applies to ``infer(..., observe=t)``, and the peers of prediction
theirs, so that they all read alike.
"""

from __future__ import annotations

import copy
import math
import os
from dataclasses import replace

import numpy as np
import torch

from primspace.data import MotionDataset
from primspace.model.latent import INFER_STARTS, LatentTable
from primspace.predict.metrics import unobserved_mse
from primspace.predict.stream import OnlineResult, Stream, follow, mean_over_samples, online_steps, prefix_mask
from primspace.train.api import as_run, infer, uses_images
from primspace.train.checks import check_calibrated, check_data_fits, check_init
from primspace.train.config import resolve_device
from primspace.train.loss import DataTensors, autocast_for, code_step
from primspace.train.observe import Observation
from primspace.train.run import TrainedRun, require_run
from primspace.train.starts import inference_start
from primspace.utils.errors import UserError

__all__ = ["OnlineInference", "OnlineResult", "infer_online", "offline_errors", "online_steps"]


# ------------------------------------------------------------------------- the loop


class OnlineInference(Stream):
    """The codes of a batch of demonstrations, corrected as their steps arrive (predictive coding).

    "Predicted information is compared with the real one and internal state is corrected
    based on the error" (paper, Background): each :meth:`step` observes one more step,
    corrects the codes by ``iterations`` Adam iterations on the error of the steps seen
    so far, and returns the decoder's prediction of the whole sequence.

    Parameters
    ----------
    run : TrainedRun
        The trained run (θ frozen; its scaler, initialiser, ``latent_lr`` and loss), resolved
        (:func:`infer_online` reads a run directory).
    data : MotionDataset
        The demonstrations, with the run's T and J (and frames of its size if used). Only
        the steps observed so far ever reach the loss; padding never does.
    iterations : int
        k >= 0, the iterations per arriving step (0: the codes stay the start).
    init : str, optional
        The start (:func:`~primspace.train.infer`'s ``init``; default: the run's), under
        an observation of ``start_step`` steps.
    start_step : int
        The first step to arrive is ``start_step`` (1..T): the start reads steps
        ``1..start_step``.
    latent_lr : float, optional
        Constant learning rate of the codes (default: the run's ``latent_lr``).
    fitted_data : MotionDataset, optional
        The run's training data, for the starts that read it (``nearest``, ``calibrated``).
    device : str
    images : bool, optional
        Use the frames (default: when the run has an image head and the data has frames,
        :func:`~primspace.train.uses_images`).
    seed : int, optional
        Seed of a ``random`` start (default: the run's, as :func:`~primspace.train.infer`).
    carry_moments : bool
        False (default): each arriving step runs a fresh Adam (moments and bias
        correction reset) from the warm code; True: one Adam runs along the stream, its
        moments carried from step to step. The fresh one forecast better at every ``k``
        on ``benchmarks/bench_online.py`` (old moments damp and misdirect the steps
        that follow new evidence).
    start_codes : ndarray (n, K·q), optional
        The codes before the first step, computed by the caller (e.g. a predictor that
        keeps its calibrations); default: the start of ``init``.
    """

    def __init__(
        self,
        run: TrainedRun | str | os.PathLike,
        data: MotionDataset,
        *,
        iterations: int,
        init: str | None = None,
        start_step: int = 1,
        latent_lr: float | None = None,
        fitted_data: MotionDataset | None = None,
        device: str = "cpu",
        images: bool | None = None,
        seed: int | None = None,
        carry_moments: bool = False,
        start_codes: np.ndarray | None = None,
    ) -> None:
        parent = require_run(run)
        if not isinstance(data, MotionDataset):
            raise UserError(f"expected a MotionDataset, got {type(data).__name__}")
        self.iterations = _check_whole("iterations", iterations, 0)
        self.carry_moments = bool(carry_moments)
        self.init = parent.init if init is None else init
        check_init(self.init, INFER_STARTS)
        check_calibrated(self.init, parent)
        lr = _check_lr(parent.train_config.latent_lr if latent_lr is None else latent_lr)
        self.tc = replace(
            parent.train_config,
            latent_lr=lr,
            amp=False,
            seed=parent.train_config.seed if seed is None else _check_whole("seed", seed, 0),
        )
        self.use_images = uses_images(parent.model_config, data, self.tc, images)
        self.length, self.n = data.length, len(data)
        self.start_step = _check_whole("start_step", start_step, 1)
        if self.start_step > self.length:
            raise UserError(f"start_step must be in 1..T={self.length}, got {start_step}")
        self.run, self.device = parent, resolve_device(device)
        self.lengths = np.full(self.n, self.length) if data.lengths is None else np.asarray(data.lengths)
        scaled = parent.scaler.transform(data.motor)
        start = _start(parent, self.init, data, scaled, self.start_step, fitted_data, self.tc.seed, start_codes)
        self.table = LatentTable(torch.from_numpy(start.astype(np.float32)).to(self.device), lr)
        self.start_codes = self.table.numpy()
        self.model = copy.deepcopy(parent.model).to(self.device).eval().requires_grad_(False)
        self.tensors = DataTensors.build(data, parent.scaler, self.use_images, self.device)
        self.truth = self.tensors.motor.cpu().numpy()
        self._full = self.model.config
        self._valid = (
            torch.ones(self.n, self.length, device=self.device) if self.tensors.mask is None else self.tensors.mask
        )
        self._arange = torch.arange(self.length, device=self.device)
        self._idx = torch.arange(self.n, device=self.device)
        self._autocast = autocast_for(self.tc, self.device)
        self.t = self.start_step - 1

    @property
    def codes(self) -> np.ndarray:
        """The current codes (n, q) float32."""
        return self.table.numpy()

    @property
    def scaler(self):
        """The run's scaler."""
        return self.run.scaler

    @property
    def latent_lr(self) -> float:
        """The codes' constant learning rate."""
        return self.tc.latent_lr

    def sync(self) -> None:
        """Wait for the device's work (CUDA), so that a step's latency counts it."""
        if self.device.type == "cuda":
            torch.cuda.synchronize()

    def arrive(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        """Observe step ``t`` (the next one, :meth:`step`): the prediction (n, T, J) scaled and the codes."""
        if t != self.t + 1:
            raise UserError(f"step {t} arrived after step {self.t}: the steps arrive in order")
        return self.step().cpu().numpy(), self.codes

    def step(self) -> torch.Tensor:
        """Observe step ``t + 1``: correct the codes on the error of steps ``1..t+1``, then predict.

        Returns
        -------
        Tensor (n, T, J)
            The decoder's motor prediction of the whole sequence (scaled units, on the
            device); the steps after the one observed are the forecast.
        """
        if self.t >= self.length:
            raise UserError(f"all T={self.length} steps have been observed")
        self.t += 1
        if self.iterations:
            if not self.carry_moments:  # a fresh Adam for this step, on the warm code
                for moment in (self.table.exp_avg, self.table.exp_avg_sq, self.table.steps):
                    moment.zero_()
            seen = self._targets(self.t)
            try:
                for _ in range(self.iterations):  # each code on its own sample's gradient, as in infer
                    code_step(self.model, self.table, self._idx, seen, self.tc, self._autocast)
            finally:
                self.model.config = self._full
        with torch.no_grad():
            return self.model(self.table.codes, images=False).motor

    def _targets(self, t: int) -> DataTensors:
        """The targets and masks of the loss after step ``t``: ``infer(..., observe=t)``'s loss.

        The decoder is causal (step ``t`` reads steps ``<= t`` only) and the loss counts the
        observed steps only, so the iterations decode the observed prefix (this module's
        copy of the model set to ``t`` steps; :meth:`step` sets it back): each sample's
        mean over its valid steps ``<= t``, at ``t / T`` of a full pass. A model with a code
        window (its K codes tie it to T steps) decodes all T, the unobserved ones masked.
        """
        whole = self.tensors
        if self._full.code_window is not None or t >= self.length:
            observed = None if t >= int(self.lengths.max()) else self._valid * (self._arange < t)
            return DataTensors(whole.motor, whole.images, whole.mask, observed, observed)
        self.model.config = replace(self._full, length=t)
        mask = None if whole.mask is None else whole.mask[:, :t]
        return DataTensors(
            whole.motor[:, :t], None if whole.images is None else whole.images[:, :t], whole.mask, mask, mask
        )


def infer_online(
    run: TrainedRun | str | os.PathLike,
    data: MotionDataset,
    *,
    iterations: int,
    init: str | None = None,
    start_step: int = 1,
    latent_lr: float | None = None,
    fitted_data: MotionDataset | None = None,
    device: str = "cpu",
    images: bool | None = None,
    seed: int | None = None,
    carry_moments: bool = False,
    progress: bool | None = None,
    start_codes: np.ndarray | None = None,
) -> OnlineResult:
    """Online inference over a data set: steps ``start_step..T`` arrive one at a time.

    After each step, the codes are corrected on the error of the steps seen so far
    ("Predicted information is compared with the real one and internal state is
    corrected based on the error", paper, Background) and the decoder predicts the whole
    sequence; the error of the prediction of the remaining steps is recorded with the
    codes and the latency (:class:`OnlineInference` does the steps).

    Parameters
    ----------
    run, data, iterations, init, start_step, latent_lr, fitted_data, device, images, seed, carry_moments, start_codes
        As :class:`OnlineInference`.
    progress : bool, optional
        Progress bar (default: when stderr is a terminal).

    Returns
    -------
    OnlineResult
    """
    online = OnlineInference(
        as_run(run),
        data,
        iterations=iterations,
        init=init,
        start_step=start_step,
        latent_lr=latent_lr,
        fitted_data=fitted_data,
        device=device,
        images=images,
        seed=seed,
        carry_moments=carry_moments,
        start_codes=start_codes,
    )
    steps, keep = online_steps(online.start_step, None, online.length)
    return follow(online, online.truth, online.lengths, steps, keep, label="online", progress=progress)


# ---------------------------------------------------------------- the offline figure


def offline_errors(
    run: TrainedRun | str | os.PathLike,
    data: MotionDataset,
    steps,
    *,
    epochs: int,
    init: str | None = None,
    fitted_data: MotionDataset | None = None,
    **overrides,
) -> dict:
    """The error of the remaining steps after offline inference from the first ``t`` steps, for a few ``t``.

    The reference for the online figures: for each ``t``, ``infer(run, data,
    observe=t, epochs=epochs, init=init)`` (its start, loss and schedule), its codes
    decoded, and the prediction of the valid steps after ``t`` compared with the real
    ones (:func:`~primspace.predict.metrics.unobserved_mse`, the online measure): the internal state corrected by
    the error to convergence rather than step by step.

    Parameters
    ----------
    run, data
        As :func:`infer_online`.
    steps : iterable of int
        The ``t`` (1..T) to infer from.
    epochs : int
        Epochs of each offline inference (enough to converge).
    init, fitted_data
        As :func:`~primspace.train.infer`.
    **overrides
        Train config overrides of :func:`~primspace.train.infer` (``latent_lr``,
        ``batch_size``, ``device``, ``seed`` ...).

    Returns
    -------
    dict
        ``steps`` (S,) int, ``errors`` (n, S) float64 (NaN: no step left), ``mean_error`` (S,),
        ``codes`` (n, S, q) float32.
    """
    parent = as_run(run)
    if not isinstance(data, MotionDataset):
        raise UserError(f"expected a MotionDataset, got {type(data).__name__}")
    check_data_fits(data, parent.model_config, False)
    steps = np.asarray([_check_whole("steps", t, 1) for t in np.atleast_1d(np.asarray(steps, dtype=object))])
    if steps.size == 0 or steps.max() > data.length:
        raise UserError(f"steps must be one or more steps in 1..T={data.length}, got {steps.tolist()}")
    truth = parent.scaler.transform(data.motor)
    errors, codes = [], []
    for t in steps:
        inferred = infer(
            parent, data, epochs=epochs, init=init, observe=int(t), fitted_data=fitted_data, progress=False, **overrides
        )
        with torch.no_grad():
            predicted = parent.model(torch.from_numpy(inferred.latents), images=False).motor.numpy()
        errors.append(unobserved_mse(predicted, truth, prefix_mask(len(data), data.length, t), data.lengths))
        codes.append(inferred.latents)
    errors = np.stack(errors, axis=1)
    return {
        "steps": steps,
        "errors": errors,
        "mean_error": mean_over_samples(errors),
        "codes": np.stack(codes, axis=1),
    }


# --------------------------------------------------------------------------- helpers


def _start(
    parent: TrainedRun,
    init: str,
    data: MotionDataset,
    scaled: np.ndarray,
    start_step: int,
    fitted_data: MotionDataset | None,
    seed: int,
    start_codes: np.ndarray | None,
) -> np.ndarray:
    """The codes before the first step: ``infer(..., observe=start_step)``'s start
    (:func:`~primspace.train.starts.inference_start`), or ``start_codes`` when given."""
    observation = Observation.build(int(start_step))
    return inference_start(parent, init, data, scaled, observation, fitted_data, seed, start_codes)[1]


def _check_whole(name: str, value, least: int) -> int:
    """``value`` as an int >= ``least`` (not a bool, not a float), or one UserError."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < least:
        raise UserError(f"{name} must be a whole number >= {least}, got {value!r}")
    return int(value)


def _check_lr(value) -> float:
    if (
        isinstance(value, (bool, np.bool_))
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not math.isfinite(value)
        or value <= 0
    ):
        raise UserError(f"latent_lr must be a finite number > 0, got {value!r}")
    return float(value)
