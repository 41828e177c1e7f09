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

__all__ = ["PolicyPlanner", "ProMPPlanner", "PLANNERS"]

#: The planners of ``primspace act`` and the act experiment, by the name their rows carry.
PLANNERS = ("closed loop", "open loop", "ProMP re-conditioned")


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
