"""Acting in the simulator: plan a motion from the scene, execute it, observe, re-plan.

* :mod:`primspace.act.planner`: the one interface of a planner (:class:`Planner`: ``reset``,
  ``due``, ``plan``);
* :mod:`primspace.act.planners`: the planners (the scene policy in closed or open loop; ProMP
  re-conditioned on the executed joints);
* :mod:`primspace.act.scene_policy`: the scene policy (:class:`ScenePolicy`), the whole motion
  from the first frame and joints and the primitive, corrected by what a later frame shows;
  :func:`predict_from_scene` runs it on a data set (``primspace predict --scene``);
* :mod:`primspace.act.scene_peers`: the scene-only peers (:class:`ContextualProMPPeer`,
  :class:`NearestFramePeer`); :mod:`primspace.act.scene_kernel`: the scene policy's kind of map as
  a peer (:class:`KernelRidgePeer`, tuned by K-fold); :mod:`primspace.act.frame_features`: what is
  read of a frame;
* :mod:`primspace.act.episode`: one episode in MuJoCo (:class:`~primspace.sim.execute.Executor`),
  optionally with the block moved during the motion;
* :mod:`primspace.act.command`: ``primspace act``'s work (a scene, the planners, the outputs).

This package sits above ``predict`` and ``sim`` (it joins them) and below ``experiments``.
"""

from importlib import import_module
from typing import TYPE_CHECKING

from primspace.act.episode import Episode, run_episode
from primspace.act.planner import Planner
from primspace.act.planners import PLANNERS, PolicyPlanner, ProMPPlanner

# Loaded on first use (PEP 562): the scene policy imports the decoder (torch); the command
# line's options read only the planners.
_HOME = {
    "ScenePolicy": "scene_policy",
    "SCENE_POLICY": "scene_policy",
    "predict_from_scene": "scene_policy",
    "ContextualProMPPeer": "scene_peers",
    "NearestFramePeer": "scene_peers",
    "KernelRidgePeer": "scene_kernel",
    "ColourBlob": "frame_features",
}

__all__ = ["Episode", "run_episode", "Planner", "PolicyPlanner", "ProMPPlanner", "PLANNERS", *_HOME]


def __getattr__(name: str):
    if name not in _HOME:
        raise AttributeError(f"module 'primspace.act' has no attribute {name!r}")
    value = getattr(import_module(f"primspace.act.{_HOME[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


if TYPE_CHECKING:  # for type checkers and IDEs
    from primspace.act.frame_features import ColourBlob  # noqa: F401
    from primspace.act.scene_kernel import KernelRidgePeer  # noqa: F401
    from primspace.act.scene_peers import ContextualProMPPeer, NearestFramePeer  # noqa: F401
    from primspace.act.scene_policy import SCENE_POLICY, ScenePolicy, predict_from_scene  # noqa: F401
