"""Where inference starts: the codes a new sample's optimisation begins from.

:func:`primspace.train.infer` (and :mod:`primspace.predict`'s gradient predictors) start
each new sample's code from what was observed of it (:mod:`primspace.train.observe`):

* ``zero``, ``random``: as without observation (they read no data);
* ``projection``: ``P (M ⊙ m)``, the run's ``P`` (paper, *Initialization of Latent
  Vectors*) applied to the scaled motor sequence with its unobserved steps set to zero;
  Appendix A then holds for the observed parts (:func:`primspace.model.latent.appendix_a_observed`);
* ``pca``: ``V_q (M ⊙ (m − mean))``, the principal directions (the run's when it was fitted
  with ``pca``; else fitted here on the zero-filled observed part of the data inferred);
* ``calibrated``: the ridge map towards the identity
  (:class:`primspace.model.calibration.CodeCalibration`) from the fitted demonstrations' observed
  projections (the same rule applied to them) to their fitted codes
  (:func:`observed_calibration`);
* ``nearest``: the fitted code of the fitted demonstration whose motor is nearest over the
  new sample's observed steps (Euclidean, scaled units; :func:`nearest_codes`);
* ``projection-vision``: the run's motor projection plus the projection of the samples' keypoint
  trajectories through its frozen keypoint encoder (:mod:`primspace.train.vision_start`);
  only from a run fitted with it;
* ``calibrated`` with no joints observed (``observe="none"``) and frames observed: a random
  projection of the observed frames minus the run's mean frame, mapped to the fitted codes
  by a calibration fitted the same way (:mod:`primspace.train.frames_start`).

The starts that read the fitted demonstrations (``calibrated`` under a rule, ``nearest``)
take them as a :class:`~primspace.data.MotionDataset` in the run's order (:func:`fitted_samples`).
Nothing is cached on the run: a caller that starts many times under one rule (a predictor)
passes its own ``cache`` dict to :func:`fitted_start`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from primspace.data import MotionDataset
from primspace.model.calibration import CodeCalibration
from primspace.model.config import ModelConfig
from primspace.model.latent import CALIBRATABLE, CALIBRATED, NEAREST, VISION_PROJECTION, LatentInitializer
from primspace.train.frames_start import check_frames_start, frames_start, frames_start_codes
from primspace.train.observe import NOTHING, Observation, observation_masks
from primspace.train.rundata import load_fitted_data
from primspace.train.vision_start import VISION_KEYPOINTS, VisionProjection
from primspace.utils.errors import UserError

__all__ = [
    "FittedDemonstrations",
    "derived_seeds",
    "run_initializer",
    "initial_codes",
    "start_codes",
    "inference_start",
    "fitted_start",
    "observed_calibration",
    "nearest_codes",
    "fitted_samples",
    "STARTS_FROM_FITTED",
]

#: The starts that read the fitted demonstrations (under an observation rule for ``calibrated``).
STARTS_FROM_FITTED = (CALIBRATED, NEAREST)


@dataclass
class FittedDemonstrations:
    """A run's fitted demonstrations as the starts read them, in the run's order (the rows of its codes).

    Attributes
    ----------
    scaled : ndarray (m, T, J)
        Their motor in the run's scaled units.
    lengths : ndarray (m,) int
        Valid steps of each.
    images : array-like (m, T, H, W, 3) uint8 or None
        Their frames (read by the frames start only).
    """

    scaled: np.ndarray
    lengths: np.ndarray
    images: object = None

    @classmethod
    def of(cls, parent, fitted: MotionDataset) -> FittedDemonstrations:
        """From ``fitted``, the run's fitted samples in its order (:func:`fitted_samples`)."""
        lengths = fitted.valid_lengths
        return cls(
            parent.scaler.transform(fitted.motor), np.asarray(lengths), fitted.images if fitted.has_images else None
        )

    def masks(self, observation: Observation | None) -> tuple[np.ndarray, np.ndarray]:
        """Their motor and frame masks (m, T) under ``observation`` (valid steps without one)."""
        rule = Observation.build(1.0) if observation is None else observation
        return rule.masks(self.lengths, self.scaled.shape[1])


def derived_seeds(seed: int) -> dict:
    """Independent seeds for each use of randomness of a run, all derived from its ``TrainConfig.seed``."""
    names = ("model", "projection", "codes_fit", "codes_infer", "shuffle", "frames")  # append only: keeps the others
    values = np.random.SeedSequence(int(seed)).generate_state(len(names), dtype=np.uint32)
    return {name: int(v) for name, v in zip(names, values)}


def run_initializer(
    init: str, parent, mc: ModelConfig, scaled: np.ndarray, seeds: dict, data: MotionDataset | None = None
) -> LatentInitializer | VisionProjection:
    """The parent's initialiser for the same init (its ``P``); otherwise one fitted here
    (one code per window of ``mc.code_window`` steps when set; ``projection-vision`` also
    fits its keypoint encoder on ``data``'s frames, K = ``mc.keypoints`` or
    :data:`~primspace.train.vision_start.VISION_KEYPOINTS`)."""
    if parent is not None and init in (parent.init, CALIBRATED, NEAREST):
        return parent.initializer
    if init == VISION_PROJECTION:
        images, lengths = (None, None) if data is None else (data.images, data.valid_lengths)
        k = mc.keypoints or VISION_KEYPOINTS
        vision = VisionProjection(mc.latent_dim, k, random_state=seeds["projection"], window=mc.code_window)
        return vision.fit(scaled, images, lengths)
    return LatentInitializer(init, mc.latent_dim, random_state=seeds["projection"], window=mc.code_window).fit(scaled)


def start_codes(initializer, scaled: np.ndarray, data: MotionDataset | None, **kwargs) -> np.ndarray:
    """``initializer.transform(scaled, **kwargs)``, with ``data``'s frames for ``projection-vision``."""
    if isinstance(initializer, VisionProjection):
        images, lengths = (None, None) if data is None else (data.images, data.valid_lengths)
        return initializer.transform(scaled, images=images, lengths=lengths, **kwargs)
    return initializer.transform(scaled, **kwargs)


def initial_codes(
    init: str,
    parent,
    initializer: LatentInitializer,
    scaled: np.ndarray,
    seed: int,
    initial_latents: np.ndarray | None = None,
    data: MotionDataset | None = None,
) -> np.ndarray:
    """The starting codes (float64) without an observation rule: the initialiser's, mapped by the
    parent's calibration for ``calibrated``; rows of ``initial_latents`` without NaN replace them;
    ``data``: the samples (their frames, for ``projection-vision``)."""
    codes = start_codes(initializer, scaled, data, random_state=seed)
    codes = (parent.calibration.transform(codes) if init == CALIBRATED else codes).astype(np.float64)
    return _given(codes, initial_latents)


def _given(codes: np.ndarray, initial_latents: np.ndarray | None) -> np.ndarray:
    if initial_latents is not None:
        given = ~np.isnan(initial_latents).any(axis=1)
        codes[given] = initial_latents[given]
    return codes


def inference_start(
    parent,
    init: str,
    data: MotionDataset,
    scaled: np.ndarray,
    observation: Observation | None,
    fitted_data: MotionDataset | None,
    seed: int,
    initial_latents: np.ndarray | None = None,
) -> tuple[LatentInitializer, np.ndarray]:
    """The initialiser and the starting codes (float64, (n, K·q)) of :func:`~primspace.train.infer`.

    ``scaled``: ``data``'s scaled motor; ``seed``: the inference's ``TrainConfig.seed``;
    ``fitted_data``: the data set ``parent`` was fitted on (its data file when None), read
    only by the starts of :data:`STARTS_FROM_FITTED`. Rows of ``initial_latents`` without
    NaN replace the start's (when every row is given, the start is not computed).
    """
    seeds = derived_seeds(seed)
    if init == VISION_PROJECTION and parent.init != VISION_PROJECTION:
        raise UserError(
            f"init 'projection-vision' infers through the keypoint encoder of a run fitted with it; "
            f"this run was fitted with {parent.init!r}: start by {parent.init!r} or 'nearest'"
        )
    observed = None
    if observation is not None or init == NEAREST:
        observed = observation_masks(observation, data)[0]
    seen = scaled if observed is None else scaled * observed[..., None]  # what a new pca fits
    initializer = run_initializer(init, parent, parent.model_config, seen, seeds)
    if initial_latents is not None and not np.isnan(initial_latents).any():  # every row given
        return initializer, np.asarray(initial_latents, dtype=np.float64).copy()
    if observed is None:
        codes = initial_codes(init, parent, initializer, scaled, seeds["codes_infer"], initial_latents, data)
        return initializer, codes
    codes = _observed_start(
        parent, init, initializer, data, scaled, observed, observation, fitted_data, seeds["codes_infer"]
    )
    return initializer, _given(codes, initial_latents)


def _observed_start(parent, init, initializer, data, scaled, observed, observation, fitted_data, seed) -> np.ndarray:
    """The start under an observation rule (or ``nearest``)."""
    frames_only = observation is not None and observation.motor == NOTHING
    if frames_only and init not in ("zero", "random", CALIBRATED):
        raise UserError(
            f"init {init!r} starts from the observed joints, and observe='none' observes none: "
            "start by 'calibrated' (from the frames), 'zero' or 'random'"
        )
    if init in STARTS_FROM_FITTED:  # calibrated (from the joints, or from the frames alone) and nearest
        return fitted_start(parent, init, _fitted(parent, fitted_data), data, scaled, observed, observation)
    return start_codes(initializer, scaled, data, random_state=seed, observed=observed).astype(np.float64)


def _fitted(parent, fitted_data: MotionDataset | None) -> FittedDemonstrations:
    return FittedDemonstrations.of(parent, fitted_samples(parent, fitted_data))


def fitted_start(
    parent,
    init: str,
    fitted: FittedDemonstrations,
    data: MotionDataset,
    scaled: np.ndarray,
    observed: np.ndarray,
    observation: Observation | None,
    cache: dict | None = None,
) -> np.ndarray:
    """Starting codes (float64) of the starts that read the fitted demonstrations.

    Parameters
    ----------
    parent : TrainedRun
    init : str
        ``nearest`` or ``calibrated`` (from the observed joints, or from the frames alone
        when ``observation.motor`` is ``"none"``).
    fitted : FittedDemonstrations
        The run's fitted demonstrations in its order.
    data, scaled, observed
        The samples, their scaled motor and observed motor mask (n, T).
    observation : Observation
        The rule (None: every step; only ``nearest`` then).
    cache : dict, optional
        The caller's: calibrations fitted for a rule are kept there, keyed by the rule.
    """
    if init == NEAREST:
        if observation is not None and observation.motor == NOTHING:  # nothing to be near to
            raise UserError(
                "init 'nearest' compares the observed joints, and observe='none' observes none: "
                "start by 'calibrated' (from the frames), 'zero' or 'random'"
            )
        return nearest_codes(scaled, observed, fitted.scaled, fitted.masks(None)[0], parent.latents)
    if init != CALIBRATED:
        raise UserError(f"init {init!r} does not read the fitted demonstrations: start by 'nearest' or 'calibrated'")
    cache = {} if cache is None else cache
    if observation.motor == NOTHING:
        check_frames_start(parent, data, "the data set")
        key = ("frames",) + tuple(observation.key)
        if key not in cache:
            cache[key] = frames_start(parent, observation, fitted.images, fitted.lengths)
        return frames_start_codes(cache[key], data, observation)
    if observation.key not in cache:
        cache[observation.key] = observed_calibration(parent, observation, fitted)
    codes = parent.initializer.transform(scaled, observed=observed)
    return cache[observation.key].transform(codes).astype(np.float64)


def observed_calibration(parent, observation: Observation | None, fitted: FittedDemonstrations) -> CodeCalibration:
    """The ridge map (towards the identity) from the fitted demonstrations' observed codes
    ``P (M_i ⊙ m_i)`` to their fitted codes, for ``observation`` (the run's own map without one).
    """
    if observation is None:
        return parent.calibration
    if parent.initializer.method not in CALIBRATABLE:
        raise UserError(
            f"init 'calibrated' needs a run fitted with projection or pca init, not '{parent.initializer.method}'"
        )
    initial = parent.initializer.transform(fitted.scaled, observed=fitted.masks(observation)[0])
    return CodeCalibration(parent.model_config.latent_dim).fit(initial, parent.latents)


def nearest_codes(
    scaled: np.ndarray, observed: np.ndarray, fitted: np.ndarray, fitted_valid: np.ndarray, fitted_codes: np.ndarray
) -> np.ndarray:
    """For each sample, the code of the fitted demonstration whose motor is nearest over its observed steps.

    The squared distance is the mean over the entries observed in the sample and valid in
    the fitted demonstration (all of its observed entries, when the fitted demonstrations
    have one length: then the Euclidean distance of the observed parts); a demonstration
    sharing no step is never nearest. Ties go to the first.

    Parameters
    ----------
    scaled : ndarray (n, T, J)
    observed : ndarray (n, T) bool
    fitted : ndarray (m, T, J)
        The fitted demonstrations, scaled.
    fitted_valid : ndarray (m, T) bool
    fitted_codes : ndarray (m, K·q)

    Returns
    -------
    ndarray (n, K·q) float64: rows of ``fitted_codes``.
    """
    j = scaled.shape[2]
    a, m = scaled.reshape(len(scaled), -1), np.repeat(np.asarray(observed, dtype=np.float64), j, axis=1)
    b, v = fitted.reshape(len(fitted), -1), np.repeat(np.asarray(fitted_valid, dtype=np.float64), j, axis=1)
    a, b = a * m, b * v
    sums = (a**2) @ v.T + m @ (b**2).T - 2.0 * a @ b.T  # Σ over shared entries of (a - b)²
    counts = m @ v.T
    dist = np.where(counts > 0, np.maximum(sums, 0.0) / np.maximum(counts, 1.0), np.inf)
    return np.asarray(fitted_codes, dtype=np.float64)[np.argmin(dist, axis=1)]


def fitted_samples(parent, fitted_data: MotionDataset | None) -> MotionDataset:
    """The parent's own samples in its order, checked against its record: from ``fitted_data``
    (the data set it was fitted on, or a subset holding them) or its recorded data file
    (:func:`primspace.train.rundata.load_fitted_data`)."""
    return load_fitted_data(parent, fitted_data)
