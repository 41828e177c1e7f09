"""Where the fingers are relative to the TCP, measured once on the model; the home posture.

Offsets that depend on the fingers' shape (how far the closed fingers reach ahead of the
TCP, where the finger pads meet a block) are measured once on the model
(:class:`FingerGeometry`), so a push starts exactly at the block's face and a grasp closes
exactly on it. Every motion starts from the same home posture (the paper, section
"Artificial Data": "Robotic arm always starts from the same position").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from primspace.sim.primitives.script import R_DOWN, SCRIPT
from primspace.sim.scene import FINGER_MAX, Scene

__all__ = ["FingerGeometry", "finger_geometry", "home_posture"]

#: The arm's "ready" posture (the Panda's usual one; joint 6 in this model's convention,
#: standard q6 - pi/2): the start of the search for the home posture.
_READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 0.0, 0.0])


@dataclass
class FingerGeometry:
    """Where the fingers are relative to the TCP, measured once on the model.

    Parameters
    ----------
    scene : Scene

    Attributes
    ----------
    home : ndarray, shape (7,)
        The home posture: the TCP at ``SCRIPT.home_tcp``, pointing down (solved by IK
        from the Panda's ready posture).
    """

    scene: Scene
    home: np.ndarray = field(init=False)
    _cache: dict = field(init=False, default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        from primspace.sim.ik import solve_pose

        result = solve_pose(self.scene, SCRIPT.home_tcp, R_DOWN, _READY, max_iter=500)
        if result.max_position_error > 1e-4:  # pragma: no cover - a broken model
            raise RuntimeError(f"home posture not reachable ({result.max_position_error * 1e3:.2f} mm)")
        self.home = result.q[0]

    def _probe(self, fingers: float) -> np.ndarray:
        self.scene.set_joints(np.r_[self.home, fingers, fingers])
        return self.scene.data.site_xpos[self.scene.tcp].copy()

    def reach(self, axis: int, sign: int, size: float, tcp_height: float) -> float:
        """How far the closed fingers reach ahead of the TCP along ``sign * axis`` (m).

        Only finger geoms that overlap a block face of edge ``size`` on the table, seen
        with the TCP at ``tcp_height`` above the table, count (the pusher of
        :func:`primspace.sim.rollout.pusher_front`).
        """
        key = ("reach", axis, sign, round(size, 9), round(tcp_height, 9))
        if key not in self._cache:
            from primspace.sim.rollout import pusher_front

            p = self._probe(0.0)
            half = 0.5 * size
            lo = np.array([p[0] - half, p[1] - half, p[2] - tcp_height])
            hi = lo + size
            front = pusher_front(
                self.scene, self.scene.left_finger_geoms + self.scene.right_finger_geoms, axis, sign, lo, hi
            )
            self._cache[key] = sign * (front - p[axis])
        return self._cache[key]

    def touch_reach(self, axis: int, sign: int, size: float, tcp_height: float) -> float:
        """How far the TCP stops from a block face when the closed fingers touch it (m).

        Measured with the true signed distance (:func:`mujoco.mj_geomDistance`): a block
        of edge ``size`` on the table, TCP at ``tcp_height``, the face ``sign * axis``
        ahead of the TCP.
        """
        key = ("touch", axis, sign, round(size, 9), round(tcp_height, 9))
        if key not in self._cache:
            import mujoco

            s = self.scene
            p = self._probe(0.0)
            centre = p.copy()
            centre[2] = p[2] - tcp_height + 0.5 * size
            ahead = 0.05 + 0.5 * size  # TCP to block centre: 5 cm to the face
            centre[axis] += sign * ahead
            s.set_block(centre[0], centre[1], size, z=centre[2])
            mujoco.mj_kinematics(s.model, s.data)
            gap = min(
                mujoco.mj_geomDistance(s.model, s.data, g, s.block_geom, 0.1, None)
                for g in s.left_finger_geoms + s.right_finger_geoms
            )
            self._cache[key] = 0.05 - gap
        return self._cache[key]

    def grip_opening(self, size: float, tcp_height: float) -> float:
        """Finger joint value at which both pads touch a block of edge ``size`` centred between them."""
        key = ("grip", round(size, 9), round(tcp_height, 9))
        if key not in self._cache:
            import mujoco

            s = self.scene
            p = self._probe(FINGER_MAX)
            s.set_block(p[0], p[1], size, z=p[2] - tcp_height + 0.5 * size)
            mujoco.mj_kinematics(s.model, s.data)
            gaps = [
                min(mujoco.mj_geomDistance(s.model, s.data, g, s.block_geom, 0.1, None) for g in geoms)
                for geoms in (s.left_finger_geoms, s.right_finger_geoms)
            ]
            self._cache[key] = FINGER_MAX - float(np.mean(gaps))
        return self._cache[key]


def home_posture(scene: Scene) -> np.ndarray:
    """The 9 joint values every motion starts from (fingers closed)."""
    return np.r_[finger_geometry(scene).home, 0.0, 0.0]


def finger_geometry(scene: Scene) -> FingerGeometry:
    """The scene's :class:`FingerGeometry` (measured on first use, then kept on the scene)."""
    geo = getattr(scene, "_finger_geometry", None)
    if geo is None:
        geo = FingerGeometry(scene)
        scene._finger_geometry = geo
    return geo
