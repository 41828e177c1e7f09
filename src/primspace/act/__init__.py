"""Acting in the simulator: plan a motion from the scene, execute it, observe, re-plan (issue 40).

* :mod:`primspace.act.planners`: what makes a plan at a step (the scene policy, in closed or
  open loop; ProMP re-conditioned on the executed joints);
* :mod:`primspace.act.episode`: one episode in MuJoCo (:class:`~primspace.sim.execute.Executor`),
  optionally with the block moved during the motion;
* :mod:`primspace.act.command`: ``primspace act``'s work (a scene, the planners, the outputs).

This package sits above ``predict`` and ``sim`` (it joins them) and below ``experiments``.
"""

from primspace.act.episode import Episode, run_episode
from primspace.act.planners import PLANNERS, PolicyPlanner, ProMPPlanner

__all__ = ["Episode", "run_episode", "PolicyPlanner", "ProMPPlanner", "PLANNERS"]
