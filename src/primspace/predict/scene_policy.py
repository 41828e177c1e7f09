"""See the block, do the primitive: a motion from what the camera sees (issue 40; docs/act.md).

The paper leaves this as future work: "visual perception information is not used to
initialize encodings". Given the primitive (its label) and a camera frame, the policy
returns the whole motion; in closed loop (:mod:`primspace.act`) it is asked again every few
steps with the frame of that step and the joints executed so far.

**What it reads of a frame.** The block is 2-4 pixels wide in a 48 x 64 frame; its position
and size are all a scene-only motion depends on, and the pixels' principal components spend
themselves on the arm (docs/act.md measures both). The default features are the moments of
the block's colour (:class:`~primspace.predict.frame_features.ColourBlob`: mass, column,
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
fingers cover the block, a push moves it), fitted on the demonstrations' frames; its residual
spread on them (root mean square per feature, floored at :data:`SURPRISE_FLOOR`) is the
scale of a surprise. At a planning step the error between the features seen and those
predicted is the surprise; when one feature's error exceeds :attr:`threshold` times its scale
the belief is corrected by the error (:meth:`correct`) and the motion is planned again from
it; otherwise the plan stands.

A new plan's steps after the last executed one are moved to continue from it: the residual
at the last executed step decays linearly to zero over :attr:`horizon` steps.
"""

from __future__ import annotations

import warnings

import numpy as np

from primspace.errors import UserError
from primspace.predict.base import Forecast, Predictor
from primspace.predict.frame_features import frame_features
from primspace.predict.metrics import check_labels, check_lengths, check_motor, valid_mask
from primspace.predict.primitives import primitives_from_labels

__all__ = ["ScenePolicy", "POLICY_SPACES", "SCENE_POLICY", "SURPRISE_FLOOR", "continue_from"]

#: ``space`` of :class:`ScenePolicy`.
POLICY_SPACES = ("motion", "code")
#: ``Prediction.init`` / ``result.json``'s ``mode`` of a scene policy's plan.
SCENE_POLICY = "scene policy"
#: The smallest scale of a feature's surprise (mass in weighted pixels, column and row in pixels).
SURPRISE_FLOOR = 0.25


def _gaussian_process(seed: int):
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    def make(n_features: int):
        kernel = ConstantKernel(1.0) * RBF(length_scale=np.ones(n_features)) + WhiteKernel(1e-2)
        return GaussianProcessRegressor(kernel, n_restarts_optimizer=2, random_state=seed)

    return make


class _Map:
    """One Gaussian process from standardised features to standardised targets."""

    def __init__(self, x: np.ndarray, y: np.ndarray, make):
        self.x_mean, self.x_std = x.mean(axis=0), x.std(axis=0) + 1e-9
        self.y_mean, self.y_std = y.mean(axis=0), y.std(axis=0) + 1e-6
        self.gp = make(x.shape[1])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # bounds reached by the optimiser: the fit is still used
            self.gp.fit((x - self.x_mean) / self.x_std, (y - self.y_mean) / self.y_std)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.gp.predict((np.atleast_2d(x) - self.x_mean) / self.x_std) * self.y_std + self.y_mean


class ScenePolicy(Predictor):
    """A motion from a camera frame and the primitive; corrected by what it did not predict
    (module docstring).

    Parameters
    ----------
    run : TrainedRun or path-like, optional
        The trained run whose fitted demonstrations (in its order) are fitted; needed for
        ``space="code"`` (its codes and decoder).
    features : "blob", "pca" or a transformer
        What is read of a frame (:func:`~primspace.predict.frame_features.frame_features`).
    space : {"motion", "code"}
        What the first frame's map predicts (module docstring).
    steps : sequence of int
        The steps whose frame may be compared with the prediction (0 is the scene itself).
    threshold : float
        A surprise larger than this many scales corrects the belief.
    horizon : int
        Steps over which a new plan joins the executed motion.
    primitive : str or int, optional
        The primitive of every motion; None: each motion's label (``labels`` of :meth:`predict`).
    label_names : list of str, optional
    random_state : int
        Seed of the optimiser's restarts.
    """

    needs_labels = True

    def __init__(
        self,
        run=None,
        features="blob",
        space="motion",
        steps=(0,),
        threshold: float = 4.0,
        horizon: int = 6,
        primitive=None,
        label_names=None,
        random_state=0,
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

    # -- fit ------------------------------------------------------------------------------
    def fit(self, motor, labels=None, lengths=None, frames=None) -> "ScenePolicy":
        """Fit each primitive's maps on the demonstrations ``motor`` (m, T, J) scaled, their
        ``labels`` and camera ``frames`` (m, T, H, W, 3) uint8 (the steps of :attr:`steps` are read)."""
        motor = check_motor(motor)
        m, length = motor.shape[:2]
        self._check(length)
        labels = check_labels(labels, m)
        if labels is None:
            raise UserError("the scene policy is given the primitive: fit it on labelled demonstrations")
        frames = self._frames(frames, m, length)
        self.primitives_ = primitives_from_labels(labels, self.label_names)
        self.primitive_ = None if self.primitive is None else self.primitives_.resolve(self.primitive)
        self.steps_ = sorted({int(t) for t in np.atleast_1d(self.steps)})
        self.extractor_ = frame_features(self.features).fit(frames[:, 0])
        first = self.extractor_.transform(frames[:, 0])
        targets = self._targets(motor)
        make = _gaussian_process(int(self.random_state))
        self.maps_, self.expected_, self.scales_ = {}, {}, {}
        for k in range(self.primitives_.count):
            rows = self.primitives_.members(k)
            if len(rows) < 2:
                raise UserError(f"primitive {self.primitives_.names[k]} has {len(rows)} demonstration: at least 2")
            self.maps_[k] = _Map(first[rows], targets[rows], make)
        for t in self.steps_[1:]:
            seen = self.extractor_.transform(frames[:, t])
            for k in range(self.primitives_.count):
                rows = self.primitives_.members(k)
                self.expected_[t, k] = _Map(first[rows], seen[rows], make)
                residual = seen[rows] - self.expected_[t, k](first[rows])
                self.scales_[t, k] = np.maximum(np.sqrt((residual**2).mean(axis=0)), SURPRISE_FLOOR)
        self.shape_ = motor.shape[1:]
        return self

    def _check(self, length: int) -> None:
        if self.space not in POLICY_SPACES:
            raise UserError(f"space must be one of {', '.join(POLICY_SPACES)}, got {self.space!r}")
        steps = [int(t) for t in np.atleast_1d(self.steps)]
        if not steps or min(steps) < 0 or max(steps) >= length:
            raise UserError(f"steps must lie in 0..{length - 1}, got {list(np.atleast_1d(self.steps))}")
        if self.space == "code" and self.run is None:
            raise UserError("space='code' predicts the run's codes: give the run")
        if not (isinstance(self.threshold, (int, float)) and self.threshold > 0):
            raise UserError(f"threshold must be a number > 0, got {self.threshold!r}")
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, (int, np.integer)) or self.horizon < 1:
            raise UserError(f"horizon must be a whole number of steps >= 1, got {self.horizon!r}")

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
        return (np.asarray(seen) - self.expected_[key](belief)[0]) / self.scales_[key]

    def correct(self, primitive: int, step: int, belief: np.ndarray, seen: np.ndarray) -> np.ndarray | None:
        """The corrected belief (d,) when the surprise of ``seen`` at ``step`` exceeds the threshold, else None."""
        error = self.surprise(primitive, step, belief, seen)
        if np.abs(error).max() <= float(self.threshold):
            return None
        return np.asarray(belief, dtype=np.float64) + error * self.scales_[int(step), int(primitive)]

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
        return Forecast(out, codes, {"policy": self.summary()})

    def _ids(self, labels, n: int) -> np.ndarray:
        if self.primitive_ is not None:
            return np.full(n, self.primitive_, dtype=np.int64)
        labels = check_labels(labels, n)
        if labels is None:
            raise UserError("the scene policy is given each motion's primitive: pass labels (or primitive=)")
        return self.primitives_.for_labels(labels)

    def summary(self) -> dict:
        """What was fitted, for ``result.json``."""
        return {
            "features": self.features if isinstance(self.features, str) else type(self.features).__name__,
            "space": self.space,
            "steps": list(self.steps_),
            "threshold": float(self.threshold),
            "horizon": int(self.horizon),
            "primitives": self.primitives_.summary(),
        }


def continue_from(plan: np.ndarray, executed: np.ndarray, horizon: int) -> np.ndarray:
    """``plan`` (T, J) with ``executed`` (s+1, J) as its first steps, and the next ``horizon`` steps
    moved towards the plan from the last executed joints (the residual at step ``s`` decaying
    linearly to zero at ``s + horizon``)."""
    out = np.array(plan, dtype=np.float64, copy=True)
    s = len(executed) - 1
    out[: s + 1] = executed
    t = np.arange(len(out))
    ramp = np.clip(1.0 - (t - s) / float(horizon), 0.0, 1.0) * (t > s)
    out += ramp[:, None] * (executed[-1] - plan[s])[None]
    return out
