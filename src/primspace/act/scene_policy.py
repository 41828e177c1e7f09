"""See the block, do the primitive: a motion from what the camera sees (docs/act.md).

The paper leaves this as future work: "Another point is visual perception information is not
used to initialize encodings." Given the primitive (its label) and a camera frame, the policy
returns the whole motion; in closed loop (:mod:`primspace.act`) it is asked again every few
steps with the frame of that step and the joints executed so far.

**What it reads of a frame.** The block is 2-4 pixels wide in a 48 x 64 frame; its position
and size are all a scene-only motion depends on, and the pixels' principal components spend
themselves on the arm (docs/act.md measures both). The default features are the moments of
the block's colour (:class:`~primspace.act.frame_features.ColourBlob`: mass, column,
row), read the same way from the fitted demonstrations' frames and from a new frame.

**The map.** Per primitive, a Gaussian process (an RBF kernel with one length per feature, a
constant scale and white noise, fitted by maximum marginal likelihood, scikit-learn) from the
features of the fitted demonstrations' first frame to ``space``:

* ``"motion"`` (the default: it acts best, docs/act.md): the demonstration's whole motion
  (scaled, flattened; each entry standardised);
* ``"code"``: the demonstration's fitted code (the run's ``latents``), the plan the decoder's
  motion for the predicted code (the paper's code space, frozen θ).

**Seeing what was not predicted** (closed loop). The paper: "Predicted information is compared
with the real one and internal state is corrected based on the error." The internal state is
the belief about the first frame's features (where the block was put, how big it is). For
every later step of :attr:`steps` a second Gaussian process per primitive predicts the
features the camera will see at that step from the belief (the arm comes into view, the
fingers cover the block, a push moves it), fitted on the demonstrations' frames; its
leave-one-out residual spread on them (root mean square per feature, exact for a Gaussian
process, floored at :attr:`floor`) is the scale of a surprise. At a planning step
the error between the features seen and those predicted is the surprise; when one feature's
error exceeds :attr:`threshold` times its scale the belief is corrected by the error
(:meth:`correct`) and the motion is planned again from it; otherwise the plan stands. A frame
in which less than :attr:`visible` of the believed block's colour mass is seen (the fingers
cover it) is not compared: the centroid of a covered block is not where the block is.

A new plan's steps after the last executed one are moved to continue from it: the residual
at the last executed step decays linearly to zero over :attr:`horizon` steps.

**The default scene mode.** :func:`predict_from_scene` fits the policy on a run's fitted
demonstrations and predicts a data set's motions from their first frames and first joints:
it is what ``primspace predict --scene`` runs. Measured on the paper preset (docs/act.md, three
seeds) it succeeds 0.98 ± 0.004 in the simulator. The primitives are
the fitted labels or, without labels, clusters of the run's fitted codes (``primitives=``).
"""

from __future__ import annotations

import numpy as np

from primspace.act.frame_features import ColourBlob, frame_features
from primspace.act.gp_map import GaussianMap, gaussian_process
from primspace.act.planner import DEFAULT_EVERY
from primspace.act.planners import PolicyPlanner
from primspace.data import MotionDataset
from primspace.data.images import as_view
from primspace.predict.api import Prediction
from primspace.predict.base import Forecast, Predictor
from primspace.predict.candidates import continuity_correction
from primspace.predict.metrics import check_labels, check_lengths, check_motor, unobserved_mse, valid_mask
from primspace.predict.primitives import (
    PRIMITIVE_SOURCES,
    Primitives,
    primitives_from_clusters,
    primitives_from_labels,
)
from primspace.train.api import as_run
from primspace.train.checks import select
from primspace.train.observe import FIRST, Observation, observation_masks
from primspace.train.starts import fitted_samples
from primspace.utils.errors import UserError
from primspace.utils.seeds import library_seed

__all__ = [
    "ScenePolicy",
    "POLICY_SPACES",
    "SCENE_POLICY",
    "SURPRISE_FLOOR",
    "continue_from",
    "first_frames",
    "predict_from_scene",
]

#: ``space`` of :class:`ScenePolicy`.
POLICY_SPACES = ("motion", "code")
#: ``Prediction.init`` / ``result.json``'s ``mode`` of a scene policy's plan.
SCENE_POLICY = "scene policy"
#: The share of the believed block mass that must be seen for a frame to be compared (below: hidden).
VISIBLE = 0.6
#: The smallest scale of a feature's surprise (mass in weighted pixels, column and row in pixels).
SURPRISE_FLOOR = 0.25


class ScenePolicy(Predictor):
    """A motion from a camera frame and the primitive; corrected by what it did not predict
    (module docstring).

    Parameters
    ----------
    run : TrainedRun or path-like, optional
        The trained run whose fitted demonstrations (in its order) are fitted; needed for
        ``space="code"`` (its codes and decoder).
    features : "blob", "learned", "pca" or a transformer
        What is read of a frame (:func:`~primspace.act.frame_features.frame_features`):
        ``"learned"``, keypoints of an encoder fitted on the demonstrations' first frames alone
        (seeded by ``random_state``); ``"blob"``, told the block's colour, is its ablation.
    space : {"motion", "code"}
        What the first frame's map predicts (module docstring).
    steps : sequence of int
        The steps whose frame may be compared with the prediction (0 is the scene itself).
    threshold : float
        A surprise larger than this many scales corrects the belief.
    horizon : int
        Steps over which a new plan joins the executed motion.
    visible : float
        The share of the believed block's colour mass a frame must show to be compared (below:
        hidden, not compared). Only with the colour features (``"blob"``): with others
        (``"learned"`` included) there is no colour mass to read, and every frame is compared.
    floor : float
        The smallest scale of a feature's surprise.
    primitive : str or int, optional
        The primitive of every motion; None: each motion's label (``labels`` of :meth:`predict`).
    label_names : list of str, optional
    random_state : int
        Seed of the optimiser's restarts (and of the clustering, ``primitives="clusters"``).
    primitives : {"labels", "clusters"}
        What groups the demonstrations into primitives: their labels, or clusters of the run's
        fitted codes (:func:`~primspace.predict.primitives.primitives_from_clusters`; needs ``run``,
        its codes in the demonstrations' order), so that without labels a user still names
        ``"cluster 2"``. ``primitive`` is resolved against this grouping.
    n_clusters : int, optional
        With ``"clusters"``: how many (default: the number of distinct labels; without labels
        it must be given).
    """

    needs_labels = True

    def __init__(
        self,
        run=None,
        features="blob",
        space="motion",
        steps=(0,),
        threshold: float = 3.0,
        horizon: int = 4,
        primitive=None,
        label_names=None,
        random_state=0,
        primitives="labels",
        n_clusters=None,
        visible: float = VISIBLE,
        floor: float = SURPRISE_FLOOR,
    ):
        self.run = run
        self.features = features
        self.space = space
        self.steps = steps
        self.threshold = threshold
        self.horizon = horizon
        self.primitive = primitive
        self.label_names = label_names
        self.random_state = random_state
        self.primitives = primitives
        self.n_clusters = n_clusters
        self.visible = visible
        self.floor = floor

    # -- fit ------------------------------------------------------------------------------
    def fit(self, motor, labels=None, lengths=None, frames=None) -> ScenePolicy:
        """Fit each primitive's maps on the demonstrations ``motor`` (m, T, J) scaled, their
        ``labels`` and camera ``frames`` (m, T, H, W, 3) uint8 (the steps of :attr:`steps` are read)."""
        motor = check_motor(motor)
        m, length = motor.shape[:2]
        self._check(length)
        labels = check_labels(labels, m)
        if labels is None and self.primitives == "labels":
            raise UserError("the scene policy is given the primitive: fit it on labelled demonstrations")
        frames = self._frames(frames, m, length)
        self.primitives_ = self._grouping(labels, m)
        self.primitive_ = None if self.primitive is None else self.primitives_.resolve(self.primitive)
        self.steps_ = sorted({int(t) for t in np.atleast_1d(self.steps)})
        seed = library_seed(self.random_state, "random_state")
        self.extractor_ = frame_features(self.features, random_state=seed).fit(frames[:, 0])
        first = self.extractor_.transform(frames[:, 0])
        targets = self._targets(motor)
        make = gaussian_process(seed)
        self.maps_, self.expected_, self.spreads_ = {}, {}, {}
        for k in range(self.primitives_.count):
            rows = self.primitives_.members(k)
            if len(rows) < 2:
                raise UserError(f"primitive {self.primitives_.names[k]} has {len(rows)} demonstration: at least 2")
            self.maps_[k] = GaussianMap(first[rows], targets[rows], make)
        for t in self.steps_[1:]:
            seen = self.extractor_.transform(frames[:, t])
            for k in range(self.primitives_.count):
                rows = self.primitives_.members(k)
                self.expected_[t, k] = GaussianMap(first[rows], seen[rows], make)
                residual = self.expected_[t, k].held_out_residuals()
                self.spreads_[t, k] = np.sqrt((residual**2).mean(axis=0))
        self.shape_ = motor.shape[1:]
        return self

    def _grouping(self, labels, m: int) -> Primitives:
        """The demonstrations' primitives: their labels, or clusters of the run's fitted codes."""
        if self.primitives == "labels":
            return primitives_from_labels(labels, self.label_names)
        codes = np.asarray(as_run(self.run).latents, dtype=np.float64)
        if len(codes) != m:
            raise UserError(f"the run has {len(codes)} fitted codes, got {m} demonstrations")
        k = self.n_clusters
        if k is None:
            if labels is None or not (labels >= 0).any():
                raise UserError(
                    "clusters of the fitted codes are counted by the labels, and the demonstrations have none: "
                    "give n_clusters (--primitives K)"
                )
            k = int(np.unique(labels[labels >= 0]).size)
        return primitives_from_clusters(codes, k, labels, self.label_names, random_state=int(self.random_state))

    def _check(self, length: int) -> None:
        if self.primitives not in PRIMITIVE_SOURCES:
            raise UserError(f"primitives must be one of {', '.join(PRIMITIVE_SOURCES)}, got {self.primitives!r}")
        if self.primitives == "clusters" and self.run is None:
            raise UserError("primitives='clusters' clusters the run's fitted codes: give the run")
        if self.n_clusters is not None and (
            isinstance(self.n_clusters, bool)
            or not isinstance(self.n_clusters, (int, np.integer))
            or self.n_clusters < 1
        ):
            raise UserError(f"n_clusters must be a whole number >= 1, got {self.n_clusters!r}")
        if self.space not in POLICY_SPACES:
            raise UserError(f"space must be one of {', '.join(POLICY_SPACES)}, got {self.space!r}")
        steps = [int(t) for t in np.atleast_1d(self.steps)]
        if not steps or min(steps) < 0 or max(steps) >= length:
            raise UserError(f"steps must lie in 0..{length - 1}, got {list(np.atleast_1d(self.steps))}")
        if self.space == "code" and self.run is None:
            raise UserError("space='code' predicts the run's codes: give the run")
        threshold = self.threshold
        if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.number)) or not threshold > 0:
            raise UserError(f"threshold must be a number > 0, got {self.threshold!r}")
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, (int, np.integer)) or self.horizon < 1:
            raise UserError(f"horizon must be a whole number of steps >= 1, got {self.horizon!r}")
        for name, low in (("visible", 0.0), ("floor", 0.0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not value >= low:
                raise UserError(f"{name} must be a number >= {low:g}, got {value!r}")

    @staticmethod
    def _frames(frames, m: int, length: int) -> np.ndarray:
        if frames is None:
            raise UserError("the scene policy reads camera frames: the demonstrations have none")
        frames = np.asarray(frames)
        if frames.ndim != 5 or frames.shape[:2] != (m, length) or frames.shape[-1] != 3:
            raise UserError(f"frames must have shape ({m}, {length}, H, W, 3), got {frames.shape}")
        return frames

    def _targets(self, motor: np.ndarray) -> np.ndarray:
        if self.space == "motion":
            return motor.reshape(len(motor), -1)
        from primspace.train.api import as_run

        self.run_ = as_run(self.run)
        codes = np.asarray(self.run_.latents, dtype=np.float64)
        if len(codes) != len(motor):
            raise UserError(f"the run has {len(codes)} fitted codes, got {len(motor)} demonstrations")
        return codes

    # -- seeing and planning --------------------------------------------------------------
    def planner(self, primitive, every: int | None = DEFAULT_EVERY) -> PolicyPlanner:
        """The episode's :class:`~primspace.act.planner.Planner` of ``primitive`` (a name or an id):
        closed loop every ``every`` steps, open loop with None; it drives :meth:`see`,
        :meth:`correct` and :meth:`replan`."""
        return PolicyPlanner(self, self.primitives_.resolve(primitive), every)

    def see(self, frames) -> np.ndarray:
        """The features (n, d) of ``frames`` (n, H, W, 3)."""
        return self.extractor_.transform(np.asarray(frames))

    def plans(self, primitives, belief: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Whole motions (n, T, J) scaled, and their codes (``space="code"``; else None), of primitive
        ids ``primitives`` (n,) from first-frame features ``belief`` (n, d); no continuity applied."""
        primitives = np.asarray(primitives, dtype=np.int64).reshape(-1)
        belief = np.atleast_2d(belief)
        width = int(np.prod(self.shape_)) if self.space == "motion" else self.run_.latents.shape[1]
        out = np.empty((len(primitives), width))
        for k in np.unique(primitives):
            rows = np.flatnonzero(primitives == k)
            out[rows] = self.maps_[int(k)](belief[rows])
        if self.space == "code":
            from primspace.train.api import reconstruct

            decoded = reconstruct(self.run_, out.astype(np.float32), images=False, batch_size=1024)[0]
            return self.run_.scaler.transform(decoded).astype(np.float64), out.astype(np.float32)
        return out.reshape((len(primitives),) + tuple(self.shape_)), None

    def surprise(self, primitive: int, step: int, belief: np.ndarray, seen: np.ndarray) -> np.ndarray:
        """The error (d,) of the features ``seen`` at ``step`` against those predicted from ``belief``,
        in scales (module docstring); zeros at a step without a prediction (step 0 included)."""
        key = (int(step), int(primitive))
        if key not in self.expected_:
            return np.zeros_like(np.asarray(seen, dtype=np.float64))
        return (np.asarray(seen) - self.expected_[key](belief)[0]) / self.scale(step, primitive)

    def scale(self, step: int, primitive: int) -> np.ndarray:
        """The scale (d,) of a surprise at ``step``: the leave-one-out spread floored at :attr:`floor`."""
        return np.maximum(self.spreads_[int(step), int(primitive)], float(self.floor))

    def hidden(self, belief: np.ndarray, seen: np.ndarray) -> bool:
        """Whether the block is mostly hidden in ``seen``: with the colour features, its mass below
        :attr:`visible` of the belief's (a centroid of a covered block is not where the block is)."""
        if not isinstance(self.extractor_, ColourBlob):
            return False
        return float(seen[0]) < float(self.visible) * float(np.asarray(belief)[0])

    def correct(self, primitive: int, step: int, belief: np.ndarray, seen: np.ndarray) -> np.ndarray | None:
        """The corrected belief (d,) when the surprise of ``seen`` at ``step`` exceeds the threshold and
        the block is not hidden (:meth:`hidden`), else None."""
        if self.hidden(belief, seen):
            return None
        error = self.surprise(primitive, step, belief, seen)
        if np.abs(error).max() <= float(self.threshold):
            return None
        return np.asarray(belief, dtype=np.float64) + error * self.scale(step, primitive)

    def replan(self, primitive: int, belief: np.ndarray, executed: np.ndarray) -> np.ndarray:
        """One motion (T, J) scaled planned from ``belief`` and continued from ``executed`` (s+1, J) scaled."""
        plan = self.plans([primitive], np.asarray(belief)[None])[0][0]
        return continue_from(plan, np.asarray(executed, dtype=np.float64), int(self.horizon))

    def forecast(self, motor, observed=None, labels=None, lengths=None, frames=None) -> Forecast:
        """Scene only: each motion's plan from its first frame (``frames`` (n, T, H, W, 3) or
        (n, H, W, 3)), continued from its first step (``motor[:, 0]``, scaled)."""
        motor = check_motor(motor)
        n, length = motor.shape[:2]
        if frames is None:
            raise UserError("the scene policy reads the first camera frame: the motions have none")
        frames = np.asarray(frames)
        ids = self._ids(labels, n)
        plans, codes = self.plans(ids, self.see(frames[:, 0] if frames.ndim == 5 else frames))
        out = np.stack([continue_from(p, m[:1], int(self.horizon)) for p, m in zip(plans, motor)])
        valid = valid_mask(check_lengths(lengths, n, length), length)
        out = np.where(valid[..., None], out, out[np.arange(n), check_lengths(lengths, n, length) - 1][:, None])
        return Forecast(out, codes, {"policy": self.summary(), "model_share": self.model_share()})

    def _ids(self, labels, n: int) -> np.ndarray:
        if self.primitive_ is not None:
            return np.full(n, self.primitive_, dtype=np.int64)
        labels = check_labels(labels, n)
        if labels is None:
            raise UserError("the scene policy is given each motion's primitive: pass labels (or primitive=)")
        return self.primitives_.for_labels(labels)

    def model_share(self) -> float:
        """The share of a plan through the run's decoder: 1.0 with ``space="code"``, 0.0 with ``"motion"``."""
        return 1.0 if self.space == "code" else 0.0

    def summary(self) -> dict:
        """What was fitted, for ``result.json``."""
        return {
            "features": self.features if isinstance(self.features, str) else type(self.features).__name__,
            "space": self.space,
            "steps": list(self.steps_),
            "threshold": float(self.threshold),
            "horizon": int(self.horizon),
            "visible": float(self.visible),
            "floor": float(self.floor),
            "primitives": self.primitives_.summary(),
            "source": self.primitives_.source,
        }


def predict_from_scene(
    run,
    data: MotionDataset,
    primitive,
    *,
    primitives: str | None = "labels",
    n_clusters: int | None = None,
    indices=None,
    fitted_data: MotionDataset | None = None,
    features="blob",
    random_state: int | None = None,
) -> Prediction:
    """Each sample's whole motion from its first frame and first joints, as primitive ``primitive``,
    by the scene policy: the default of ``primspace predict --scene`` (docs/act.md: on the paper
    preset it succeeds 0.98 ± 0.004 in the simulator over three seeds).

    Parameters
    ----------
    run : TrainedRun or path-like
        The run whose fitted demonstrations (with their camera frames) the policy is fitted on;
        it needs no image head (the policy reads frames, not the run's decoder of them).
    data : MotionDataset
        The scenes (with frames); every step after the first is the answer the errors are measured against.
    primitive : int or str
        The primitive to perform: a name (a label name, ``"cluster 2"``) or an id of ``primitives``.
    primitives : {"labels", "clusters"} or None
        The grouping of the fitted demonstrations (:class:`ScenePolicy`); None: labels when the fitted
        data has labels, else clusters.
    n_clusters : int, optional
        With clusters: how many (default: the number of distinct fitted labels).
    indices, fitted_data
        As in :func:`primspace.predict.predict`.
    features : "blob", "pca" or a transformer
        What is read of a frame.
    random_state : int, optional
        Seed of the policy (default: the run's seed).

    Returns
    -------
    Prediction
        ``init`` ``"scene policy"``; ``codes`` an empty (n, 0) array (the policy predicts the motion
        itself, no code); ``frames`` None; the first step observed; ``details``: ``mode``, ``policy``
        (:meth:`ScenePolicy.summary`), ``primitive`` (its id), ``name`` and ``model_share`` (0.0: the
        motion does not come through the run's decoder).
    """
    parent = as_run(run)
    sub, idx = select(data, indices)
    if not data.has_images:
        where = str(data.path) if data.path is not None else "the data set"
        raise UserError(f"the scene policy reads each motion's first camera frame, and {where} has no frames")
    fitted = fitted_samples(parent, fitted_data)
    if not fitted.has_images:
        where = str(fitted.path) if fitted.path is not None else "the fitted data"
        raise UserError(
            f"the scene policy learns from the fitted demonstrations' camera frames, and {where} has none: "
            "give the fitted data with frames (fitted_data=, --fitted-data)"
        )
    if primitives is None:
        labelled = fitted.labels is not None and bool((fitted.labels >= 0).any())
        primitives = "labels" if labelled else "clusters"
    seed = int(parent.train_config.seed) if random_state is None else random_state
    first = first_frames(fitted.images)
    policy = ScenePolicy(
        parent,
        features=features,
        primitive=primitive,
        label_names=fitted.label_names,
        random_state=seed,
        primitives=primitives,
        n_clusters=n_clusters,
    ).fit(
        parent.scaler.transform(fitted.motor),
        fitted.labels,
        fitted.lengths,
        np.broadcast_to(first[:, None], (len(first), fitted.length) + first.shape[1:]),
    )
    truth = parent.scaler.transform(sub.motor)
    forecast = policy.forecast(truth, None, None, sub.lengths, first_frames(sub.images))
    observation = Observation.build(1, FIRST)
    motor_observed, frames_observed = observation_masks(observation, sub)
    k = policy.primitive_
    return Prediction(
        codes=np.zeros((len(sub), 0), dtype=np.float32),
        motor=parent.scaler.inverse_transform(forecast.motor).astype(np.float32),
        frames=None,
        motor_observed=motor_observed,
        frames_observed=frames_observed,
        indices=idx,
        errors={"motor_mse": unobserved_mse(forecast.motor, truth, motor_observed, sub.valid_lengths)},
        observation=observation.to_dict(),
        init=SCENE_POLICY,
        details={"mode": SCENE_POLICY, "policy": policy.summary(), "primitive": k, "name": policy.primitives_.names[k]}
        | {"model_share": policy.model_share()},
    )


def first_frames(images) -> np.ndarray:
    """The first frame of every sample (n, H, W, 3) of ``images`` (n, T, H, W, 3), read a block at a time."""
    blocks = [np.array(block[:, 0]) for _, block in as_view(images).iter_blocks()]
    return np.concatenate(blocks) if blocks else np.zeros((0,) + tuple(images.shape[2:]), dtype=np.uint8)


def continue_from(plan: np.ndarray, executed: np.ndarray, horizon: int) -> np.ndarray:
    """``plan`` (T, J) with ``executed`` (s+1, J) as its first steps, and the next ``horizon`` steps
    moved towards the plan from the last executed joints (the residual at step ``s`` decaying
    linearly to zero at ``s + horizon``)."""
    plan = np.asarray(plan, dtype=np.float64)
    observed = (np.arange(len(plan)) < len(executed))[None]
    seen = plan.copy()
    seen[: len(executed)] = executed
    out = continuity_correction(plan[None], seen[None], observed, np.ones_like(observed), horizon)[0]
    out[: len(executed)] = executed
    return out
