"""The planners of ``primspace act`` and the act experiment (:class:`~primspace.act.planner.Planner`).

* :class:`PolicyPlanner`: the scene policy (:class:`~primspace.act.scene_policy.ScenePolicy`)
  asked with the current frame every ``every`` steps (closed loop) or only at step 0 (open
  loop: the first plan replayed); each plan continues from the last executed step.
* :class:`ProMPPlanner`: the peer that cannot see: a ProMP of the primitive
  (:class:`~primspace.predict.peers.ProMPPeer`, given the label) conditioned on every
  executed step, every ``every`` steps.
"""

from __future__ import annotations

import numpy as np

from primspace.act.planner import DEFAULT_EVERY, Planner

__all__ = ["PolicyPlanner", "ProMPPlanner", "SeeingProMPPlanner", "PLANNERS", "SEEING_PROMP"]

#: The planners of ``primspace act`` and the act experiment, by the name their rows carry.
PLANNERS = ("closed loop", "open loop", "ProMP re-conditioned")
#: The row of :class:`SeeingProMPPlanner` in the act experiment.
SEEING_PROMP = "contextual ProMP re-planned (sees)"
#: Observation noise variance of the ProMP peers' conditioning on executed steps.
CONDITION_NOISE = 1e-3


class PolicyPlanner(Planner):
    """The scene policy: the plan from the first frame, corrected when a later frame surprises it.

    At step 0 the belief is the first frame's features and the plan is made from it. At a later
    due step the frame is compared with what the policy predicted for it
    (:meth:`~primspace.act.scene_policy.ScenePolicy.correct`): a surprise corrects the belief
    and a new plan continues from the executed joints; otherwise the plan stands.
    :attr:`corrections` lists the steps of the corrections.

    Parameters
    ----------
    policy : ScenePolicy
        Fitted, with maps at the steps it will be asked from (its ``steps``).
    primitive : int
        The primitive's id in ``policy.primitives_``.
    every : int or None
        Re-plan every this many steps; None: open loop.
    """

    def __init__(self, policy, primitive: int, every: int | None = DEFAULT_EVERY):
        super().__init__(every)
        self.policy, self.primitive = policy, int(primitive)
        self.reset()

    def reset(self) -> None:
        """Forget the belief, the plan and the corrections of the last episode."""
        self.belief, self.current, self.corrections = None, None, []

    def plan(self, step: int, frame: np.ndarray, executed: np.ndarray) -> np.ndarray:
        seen = self.policy.see(np.asarray(frame)[None])[0]
        if self.current is None:
            self.belief = seen
        else:
            corrected = self.policy.correct(self.primitive, step, self.belief, seen)
            if corrected is None:
                return self.current
            self.belief = corrected
            self.corrections.append(int(step))
        self.current = self.policy.replan(self.primitive, self.belief, executed)
        return self.current


class ProMPPlanner(Planner):
    """A fitted :class:`~primspace.predict.peers.ProMPPeer` (per label) conditioned on the executed
    steps; the frame is not read.

    Parameters
    ----------
    promp : ProMPPeer
    label : int
        The primitive's label.
    length : int
        Steps of a motion.
    every : int or None
    """

    def __init__(self, promp, label: int, length: int, every: int | None = DEFAULT_EVERY):
        super().__init__(every)
        self.promp, self.label, self.length = promp, int(label), int(length)

    def plan(self, step: int, frame: np.ndarray, executed: np.ndarray) -> np.ndarray:
        executed = np.asarray(executed, dtype=np.float64)
        length, joints = self.length, executed.shape[1]
        seen = np.zeros((1, length, joints))
        seen[0, : len(executed)] = executed
        observed = (np.arange(length) < len(executed))[None]
        out = self.promp.predict(seen, observed, np.array([self.label]))[0]
        out[: len(executed)] = executed
        return out


class SeeingProMPPlanner(Planner):
    """The peer that sees: a contextual ProMP re-planned from each due frame, conditioned on the executed joints.

    At each due step the frame's features (the peer's own transformer: the block's colour moments with
    ``features="blob"``, the scene policy's) are the context; with the block's colour features, a frame
    showing less than ``visible`` of the first frame's colour mass (the fingers cover the block) keeps
    the last context, as the scene policy does. The primitive's ProMP weight distribution is
    re-centred on the weights the peer's ridge regression predicts from the context (its covariance
    kept) and conditioned on every executed step (the package's ``condition_position``, noise
    :data:`CONDITION_NOISE`); the plan is its mean trajectory, the executed steps kept.

    Parameters
    ----------
    peer : ContextualProMPPeer
        Fitted per label on the fitted demonstrations' first frames.
    label : int
        The primitive's label.
    length : int
        Steps of a motion.
    every : int or None
    visible : float
        The share of the first frame's block mass a frame must show to replace the context.
    """

    def __init__(self, peer, label: int, length: int, every: int | None = DEFAULT_EVERY, visible: float = 0.6):
        super().__init__(every)
        self.peer, self.label, self.length, self.visible = peer, int(label), int(length), float(visible)
        self.reset()

    def reset(self) -> None:
        """Forget the first frame's and the last context."""
        self.first, self.context, self.contexts = None, None, []

    def _context(self, seen: np.ndarray) -> np.ndarray:
        """The context after a frame with features ``seen``: the frame's, unless it hides the block."""
        from primspace.act.frame_features import ColourBlob

        if self.first is None:
            self.first = seen
        elif isinstance(self.peer.features_, ColourBlob) and seen[0] < self.visible * self.first[0]:
            return self.context
        return seen

    def plan(self, step: int, frame: np.ndarray, executed: np.ndarray) -> np.ndarray:
        import copy

        from primspace.predict.peers import phase

        seen = np.asarray(self.peer.features_.transform(np.asarray(frame)[None]), dtype=np.float64)[0]
        self.context = self._context(seen)
        self.contexts.append(self.context.copy())
        promp = copy.copy(self.peer.promps_[self.label])
        offset = self.peer.regressions_[self.label].predict(self.context[None])[0]
        promp.weight_mean = self.peer.promps_[self.label].weight_mean + offset
        executed = np.asarray(executed, dtype=np.float64)
        phases = phase(self.length)
        cov = CONDITION_NOISE * np.eye(executed.shape[1])
        for y, t in zip(executed, phases):
            promp = promp.condition_position(y, y_cov=cov, t=float(t), t_max=1.0)
        out = promp.mean_trajectory(phases)
        out[: len(executed)] = executed
        return out
