"""The one interface of what plans an episode's motion (:func:`primspace.act.episode.run_episode`).

A :class:`Planner` is made from fitted models (a scene policy, a ProMP) and the primitive to do;
an episode first calls :meth:`Planner.reset`, then, after executing each step ``s`` at which
:meth:`Planner.due` is true (always step 0), :meth:`Planner.plan` with the camera frame seen
after that step and the joints executed so far. The plan is the whole motion ``(T, J)``
(scaled units); between two plans the arm follows the last one. This is the shape of
LeRobot's ``reset`` + ``select_action`` and of movement_primitives' ``step``, with a whole
plan as the action.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from primspace.utils.errors import UserError

__all__ = ["Planner", "DEFAULT_EVERY", "check_every"]

#: Steps between two looks of the closed loop (61-step motions: 20 looks); chosen with the scene
#: policy's threshold and horizon on seed 0's first 70 evaluation samples of the paper preset (docs/act.md).
DEFAULT_EVERY = 3


def check_every(every) -> int | None:
    """``every`` as a positive int, or None (never re-plan); one UserError otherwise."""
    if every is None:
        return None
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise UserError(f"the re-planning interval must be a whole number of steps >= 1, got {every!r}")
    return int(every)


class Planner(ABC):
    """What makes the plan at a step of an episode (module docstring).

    Parameters
    ----------
    every : int or None
        Plan again every this many steps; None: only at step 0 (open loop).
    """

    def __init__(self, every: int | None):
        self.every = check_every(every)

    def reset(self) -> None:
        """Start a new episode: forget what the last one planned and saw."""

    def due(self, step: int) -> bool:
        """Whether a plan is asked for after executing ``step``."""
        return step == 0 or (self.every is not None and step % self.every == 0)

    @abstractmethod
    def plan(self, step: int, frame: np.ndarray, executed: np.ndarray) -> np.ndarray:
        """The whole motion ``(T, J)`` (scaled) after executing ``step``: ``frame`` (H, W, 3) uint8 is
        the camera then, ``executed`` (step + 1, J) the joints executed so far (scaled)."""
