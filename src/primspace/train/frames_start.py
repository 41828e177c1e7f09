"""The frames-only start: codes from the observed camera frames, no joints seen.

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
* ``B, c``: a :class:`~primspace.model.calibration.CodeCalibration` from the fitted
  demonstrations' ``x`` (the same observation rule applied to them) to their fitted codes
  (a caller starting many times keeps it: :func:`primspace.train.starts.fitted_start`'s
  ``cache``, keyed by ``("frames",) + rule``). One map over the whole code (``K·q`` outputs, windows not
  pooled), pulled towards **zero** (``prior="zero"``), not towards the identity as the
  motor calibration is: ``x`` is not a code (it lives in frame space), so ``B = I`` has no
  meaning here, and a strong penalty then leaves the mean fitted code, a sensible start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from primspace.data import MotionDataset
from primspace.data.images import IMAGE_BLOCK, as_view
from primspace.model.calibration import CodeCalibration
from primspace.train.observe import Observation, observation_masks
from primspace.utils.errors import UserError

__all__ = [
    "FRAMES_PROJECTION_KEY",
    "PROJECTION_BYTES",
    "FramesStart",
    "frame_matrix",
    "frames_projection",
    "mean_frame",
    "frames_start",
    "frames_start_codes",
    "check_frames_start",
]

#: Mixed with the run's seed (and the step) to draw ``P_t``: keeps these draws apart from the run's others.
FRAMES_PROJECTION_KEY = 25
#: At most this many bytes of ``P`` (float32) are held at once.
PROJECTION_BYTES = 64 << 20


def frame_matrix(seed: int, step: int, dim: int, size: int) -> np.ndarray:
    """``P_t`` (``dim x size``, float32, entries ``N(0, 1/dim)``) of step ``step`` for the run seed ``seed``."""
    rng = np.random.default_rng([int(seed), FRAMES_PROJECTION_KEY, int(step)])
    return rng.standard_normal((dim, size), dtype=np.float32) / np.float32(np.sqrt(dim))


def frames_projection(
    images, observed, mean: np.ndarray, dim: int, seed: int, *, budget: int = PROJECTION_BYTES
) -> np.ndarray:
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


def mean_frame(images, valid: np.ndarray) -> np.ndarray:
    """The mean of every valid frame of ``images`` (n, T, H, W, 3) in [0, 1], ``valid`` (n, T):
    float64 ``(H, W, 3)``."""
    total, count = np.zeros(images.shape[2:], dtype=np.float64), 0
    for start, block in as_view(images).iter_blocks(IMAGE_BLOCK):
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


def check_frames_start(parent, data: MotionDataset | None, what: str) -> None:
    """One line: a run without an image head, or ``data`` without frames (None: not checked)."""
    if not parent.model_config.has_images:
        raise UserError(
            "init 'calibrated' from frames alone (observe='none') needs a run with an image head; "
            "this run was fitted on joints only"
        )
    if data is not None and not data.has_images:
        where = str(data.path) if data.path is not None else what
        raise UserError(f"init 'calibrated' from frames alone (observe='none') reads frames, and {where} has no frames")


def frames_start(parent, observation, images, lengths: np.ndarray) -> FramesStart:
    """The run's :class:`FramesStart` for ``observation`` (motor ``"none"``), fitted on the frames
    ``images`` (m, T, H, W, 3) of the run's fitted demonstrations (in its order; None: they
    have none) of valid ``lengths`` under the same rule.

    Raises
    ------
    UserError
        A run without an image head, fitted data without frames.
    """
    if not parent.model_config.has_images:
        check_frames_start(parent, None, "the fitted data")
    if images is None:
        raise UserError(
            "init 'calibrated' from frames alone (observe='none') reads frames, and the fitted data has no frames"
        )
    dim = int(parent.model_config.code_size)
    seed = int(parent.train_config.seed)
    length = images.shape[1]
    mean = mean_frame(images, Observation.build(1.0).masks(lengths, length)[0])
    x = frames_projection(images, observation.masks(lengths, length)[1], mean, dim, seed)
    calibration = CodeCalibration(dim, prior="zero").fit(x, parent.latents)
    return FramesStart(mean.astype(np.float32), seed, dim, calibration)


def frames_start_codes(start: FramesStart, data: MotionDataset, observation) -> np.ndarray:
    """Starting codes (float64, (n, K·q)) of ``data`` from its observed frames alone
    (module docstring), by the run's :class:`FramesStart` ``start``."""
    if tuple(data.images.shape[2:]) != tuple(start.mean.shape):
        raise UserError(
            f"frames of size {tuple(data.images.shape[2:4])} differ from the run's {tuple(start.mean.shape[:2])}"
        )
    return start.transform(data.images, observation_masks(observation, data)[1])
