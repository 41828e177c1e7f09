"""The frames-only start: codes from the observed camera frames, no joints seen (issue 25, item 1).

The paper names this as future work (*Summary and Discussion*): "Another point is visual
perception information is not used to initialize encodings." and gives the difficulty:
"The problem here is only a small portion of each perceived image is relevant to motion,
the rest is a background noise which will clutter random projection." Here the static
background is removed before projecting, and a map fitted on the run's own demonstrations
keeps what of the projection predicts their codes.

With ``infer(..., observe="none", observe_frames=..., init="calibrated")`` the start is

    z = B x + c,    x = Σ_t M_t P_t (s_t − s̄)

* ``s_t``: frame ``t`` in [0, 1] intensity, flattened (``H·W·3``); ``s̄``: the run's mean
  frame, the mean over every valid frame of the fitted demonstrations; ``M_t``: 1 where
  the frame was observed, else 0 (unobserved frames are zero after subtracting the mean,
  as the motor projection zero-fills the unobserved steps); with ``observe_frames="first"``
  only the first frame counts;
* ``P_t``: a fixed Gaussian matrix per step, ``K·q x H·W·3`` (``K·q`` the run's code size),
  entries ``N(0, 1/(K·q))`` as the paper's ``P``; drawn from
  ``numpy.random.default_rng([seed, FRAMES_PROJECTION_KEY, t])`` with ``seed`` the run's
  ``TrainConfig.seed``, so it is the same for every call and never stored. The frames are
  projected a chunk of steps at a time (:data:`PROJECTION_BYTES` of ``P`` at most) and the
  images read a block of samples at a time: the whole ``P`` is never held;
* ``B, c``: a :class:`~primspace.calibration.CodeCalibration` from the fitted
  demonstrations' ``x`` (the same observation rule applied to them) to their fitted codes,
  fitted on first use and cached in memory on the run (``TrainedRun.observed_calibrations``,
  keyed by ``("frames",) + rule``). One map over the whole code (``K·q`` outputs, windows not
  pooled), pulled towards **zero** (``prior="zero"``), not towards the identity as the
  motor calibration is: ``x`` is not a code (it lives in frame space), so ``B = I`` has no
  meaning here, and a strong penalty then leaves the mean fitted code, a sensible start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from primspace.calibration import CodeCalibration
from primspace.data import MotionDataset
from primspace.data.images import IMAGE_BLOCK, as_view
from primspace.errors import UserError
from primspace.train.observe import fitted_samples, observation_masks

__all__ = ["FRAMES_PROJECTION_KEY", "PROJECTION_BYTES", "FramesStart", "frame_matrix", "frames_projection",
           "mean_frame", "frames_start", "frames_start_codes"]

#: Mixed with the run's seed (and the step) to draw ``P_t``: keeps these draws apart from the run's others.
FRAMES_PROJECTION_KEY = 25
#: At most this many bytes of ``P`` (float32) are held at once.
PROJECTION_BYTES = 64 << 20


def frame_matrix(seed: int, step: int, dim: int, size: int) -> np.ndarray:
    """``P_t`` (``dim x size``, float32, entries ``N(0, 1/dim)``) of step ``step`` for the run seed ``seed``."""
    rng = np.random.default_rng([int(seed), FRAMES_PROJECTION_KEY, int(step)])
    return rng.standard_normal((dim, size), dtype=np.float32) / np.float32(np.sqrt(dim))


def frames_projection(images, observed, mean: np.ndarray, dim: int, seed: int, *,
                      budget: int = PROJECTION_BYTES) -> np.ndarray:
    """``x_i = Σ_t M_it P_t (s_it − s̄)`` for every sample: float64 ``(n, dim)``.

    Parameters
    ----------
    images : ndarray or LazyImages (n, T, H, W, 3) uint8
    observed : ndarray (n, T) bool
        The observed frames (unobserved ones count as the mean frame: zero after centring).
    mean : ndarray (H, W, 3)
        The mean frame ``s̄`` in [0, 1].
    dim : int
    seed : int
        The run's seed (:func:`frame_matrix`).
    budget : int
        Bytes of ``P`` held at once: steps are projected in chunks of that size.
    """
    view = as_view(images)
    n, length = view.shape[:2]
    size = int(np.prod(view.shape[2:]))
    observed = np.asarray(observed, dtype=bool)
    out = np.zeros((n, dim))
    steps = np.flatnonzero(observed.any(axis=0)[:length])
    per_chunk = max(1, int(budget) // (dim * size * 4))
    centre = np.asarray(mean, dtype=np.float32).reshape(-1)
    for first in range(0, len(steps), per_chunk):
        chunk = steps[first : first + per_chunk]
        p = np.concatenate([frame_matrix(seed, t, dim, size).T for t in chunk])  # (k·size, dim)
        for start, block in view.iter_blocks(IMAGE_BLOCK):
            x = block[:, chunk].reshape(len(block), len(chunk), size).astype(np.float32) / np.float32(255.0)
            x -= centre
            x *= observed[start : start + len(block), chunk][..., None]
            out[start : start + len(block)] += x.reshape(len(block), -1) @ p
    return out


def mean_frame(data: MotionDataset) -> np.ndarray:
    """The mean of every valid frame of ``data`` in [0, 1]: float64 ``(H, W, 3)``."""
    valid = observation_masks(None, data)[0]
    total, count = np.zeros(data.images.shape[2:], dtype=np.float64), 0
    for start, block in as_view(data.images).iter_blocks(IMAGE_BLOCK):
        rows = valid[start : start + len(block)]
        total += block[rows].sum(axis=0, dtype=np.float64)
        count += int(rows.sum())
    return total / (255.0 * max(count, 1))


@dataclass
class FramesStart:
    """The frames start of one run and rule: its mean frame, seed, code size and map.

    Attributes
    ----------
    mean : ndarray (H, W, 3)
        The run's mean frame (fitted demonstrations, valid frames) in [0, 1].
    seed : int
        The run's seed (``P_t`` of :func:`frame_matrix`).
    dim : int
        The code size ``K·q``.
    calibration : CodeCalibration
        From the fitted demonstrations' frame projections to their fitted codes.
    """

    mean: np.ndarray
    seed: int
    dim: int
    calibration: CodeCalibration

    def project(self, images, observed) -> np.ndarray:
        """The frame projections ``x`` (n, dim) of ``images`` observed at ``observed`` (n, T)."""
        return frames_projection(images, observed, self.mean, self.dim, self.seed)

    def transform(self, images, observed) -> np.ndarray:
        """The starting codes ``B x + c`` (float64, (n, dim))."""
        return self.calibration.transform(self.project(images, observed)).astype(np.float64)


def _check(parent, data: MotionDataset, what: str) -> None:
    """One line: a run without an image head, or ``data`` without frames."""
    if not parent.model_config.has_images:
        raise UserError("init 'calibrated' from frames alone (observe='none') needs a run with an image head; "
                        "this run was fitted on joints only")
    if not data.has_images:
        where = str(data.path) if data.path is not None else what
        raise UserError(f"init 'calibrated' from frames alone (observe='none') reads frames, and {where} has no frames")


def frames_start(parent, observation, fitted_data: MotionDataset | None = None) -> FramesStart:
    """The run's :class:`FramesStart` for ``observation`` (motor ``"none"``): fitted on first
    use on the fitted demonstrations under the same rule, cached in
    ``parent.observed_calibrations`` under ``("frames",) + observation.key``.

    Raises
    ------
    UserError
        A run without an image head, fitted data without frames, a run without a data
        file and no ``fitted_data``.
    """
    key = ("frames",) + tuple(observation.key)
    cache = parent.observed_calibrations
    if key not in cache:
        fitted = fitted_samples(parent, fitted_data)
        _check(parent, fitted, "the fitted data")
        dim = int(parent.model_config.code_size)
        seed = int(parent.train_config.seed)
        mean = mean_frame(fitted)
        x = frames_projection(fitted.images, observation_masks(observation, fitted)[1], mean, dim, seed)
        calibration = CodeCalibration(dim, prior="zero").fit(x, parent.latents)
        cache[key] = FramesStart(mean.astype(np.float32), seed, dim, calibration)
    return cache[key]


def frames_start_codes(parent, data: MotionDataset, observation, fitted_data: MotionDataset | None = None) -> np.ndarray:
    """Starting codes (float64, (n, K·q)) of ``data`` from its observed frames alone
    (module docstring); ``parent``: the trained run, ``fitted_data``: the data set it was
    fitted on (default: its data file)."""
    _check(parent, data, "the data set")
    start = frames_start(parent, observation, fitted_data)
    if tuple(data.images.shape[2:]) != tuple(start.mean.shape):
        raise UserError(f"frames of size {tuple(data.images.shape[2:4])} differ from the run's "
                        f"{tuple(start.mean.shape[:2])}")
    return start.transform(data.images, observation_masks(observation, data)[1])
