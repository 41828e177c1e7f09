"""Replay a joint trajectory through the kinematic simulator: TCP, block motion, contacts.

The simulator is kinematic (the issue allows it): the arm follows the given joint values
exactly, and the block moves only when the fingers push it. The data generator and the
success judge (:mod:`primspace.sim.success`) both use this one replay, so a rendered block
always moves as the judge thinks it does.

**Kinematic block model.** The block (an axis-aligned cube) rests where it was put unless
the primitive moves it along one axis (push: ``+x``; pull: ``-x``). Then, at every step,
the finger geoms whose extent overlaps the block's face (in the two other axes) form a
pusher; its leading point along the axis is the support of those geoms (capsules and
boxes, exact), and the block's trailing face is moved to it if the pusher has passed it:
``x_block(t) = max(x_block(t-1), front(t) + size/2)`` for a push (mirrored for a pull),
provided the pusher was at or behind that face at the step before (a finger that comes
down onto or through the block does not push it: it penetrates it, which the judge sees).
The block never moves back and never rotates.

**Contacts.** :func:`mujoco.mj_geomDistance` gives the signed distance (negative:
penetration depth) from each finger, from the hand and wrist meshes, and from the table to
the block, after the block has moved.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import primspace.sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from primspace.sim.scene import Scene  # noqa: E402

__all__ = ["Rollout", "BlockPusher", "replay", "geom_interval", "pusher_front"]

_CAPSULE = int(mujoco.mjtGeom.mjGEOM_CAPSULE)
_BOX = int(mujoco.mjtGeom.mjGEOM_BOX)
_SPHERE = int(mujoco.mjtGeom.mjGEOM_SPHERE)

#: Distances beyond this are reported as this (m): only near contacts matter.
DIST_MAX = 0.10

#: A pusher this close past the trailing face still counts as behind it (m).
_FACE_TOLERANCE = 1e-3


def geom_interval(model: mujoco.MjModel, data: mujoco.MjData, geom: int, axis: int) -> tuple[float, float]:
    """The extent ``(min, max)`` of a capsule, box or sphere geom along a world axis."""
    c = data.geom_xpos[geom, axis]
    row = data.geom_xmat[geom].reshape(3, 3)[axis]  # the world axis in the geom's frame
    size = model.geom_size[geom]
    kind = model.geom_type[geom]
    if kind == _CAPSULE:
        half = size[1] * abs(row[2]) + size[0]
    elif kind == _BOX:
        half = float(np.abs(row) @ size)
    elif kind == _SPHERE:
        half = size[0]
    else:
        raise ValueError(f"geom {geom}: type {kind} has no analytic extent")
    return c - half, c + half


def pusher_front(scene: Scene, geoms, axis: int, sign: int, box_lo: np.ndarray, box_hi: np.ndarray) -> float | None:
    """Leading coordinate along ``sign * axis`` of the geoms that overlap a box's face.

    A geom counts when its extent overlaps ``[box_lo, box_hi]`` on both other axes.
    Returns None when no geom overlaps the face.
    """
    m, d = scene.model, scene.data
    others = [a for a in range(3) if a != axis]
    front = None
    for g in geoms:
        overlap = True
        for a in others:
            lo, hi = geom_interval(m, d, g, a)
            if hi < box_lo[a] or lo > box_hi[a]:
                overlap = False
                break
        if not overlap:
            continue
        lo, hi = geom_interval(m, d, g, axis)
        lead = hi if sign > 0 else lo
        if front is None or sign * lead > sign * front:
            front = lead
    return front


@dataclass
class Rollout:
    """What a joint trajectory does in the scene, step by step.

    Attributes
    ----------
    tcp : ndarray, shape (T, 3)
        Tool-centre-point positions (m).
    rotation : ndarray, shape (T, 3, 3)
        TCP orientations.
    fingers : ndarray, shape (T, 2)
        Finger joint values (m).
    block : ndarray, shape (T, 3)
        Block centre after the step's push (m).
    size : float
        Block edge (m).
    finger_distance : ndarray, shape (T, 2)
        Signed distance of each finger (joint 1's finger, joint 2's finger) to the block
        (m; negative: penetration; capped at :data:`DIST_MAX`).
    finger_side : ndarray, shape (T, 2)
        y of each finger's lowest capsule minus the block centre's y (m).
    arm_distance : ndarray, shape (T,)
        Signed distance of the hand and wrist meshes to the block.
    table_distance : ndarray, shape (T,)
        Signed distance of the fingers, hand and wrist to the table top (negative: below it).
    external : ndarray, shape (T,), bool
        True at a step before which the block was moved by something other than the robot
        (:meth:`BlockPusher.move_block`, a perturbation); the step's ``block`` is then
        where it was put (plus any push of that step). Default: all False.
    """

    tcp: np.ndarray
    rotation: np.ndarray
    fingers: np.ndarray
    block: np.ndarray
    size: float
    finger_distance: np.ndarray
    finger_side: np.ndarray
    arm_distance: np.ndarray
    table_distance: np.ndarray
    external: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        if self.external is None:
            self.external = np.zeros(len(self.tcp), dtype=bool)
        else:
            self.external = np.asarray(self.external, dtype=bool)

    @property
    def contact_distance(self) -> np.ndarray:
        """(T,) signed distance of the closer finger to the block."""
        return self.finger_distance.min(axis=1)

    @property
    def penetration(self) -> np.ndarray:
        """(T,) deepest penetration of any robot geom into the block (m, >= 0)."""
        deepest = np.minimum(self.finger_distance.min(axis=1), self.arm_distance)
        return np.maximum(0.0, -deepest)


def replay(
    scene: Scene, joints: np.ndarray, block_xy, size: float, push_axis: int | None = None, push_sign: int = 1
) -> Rollout:
    """Run a joint trajectory through the scene's kinematics.

    Every step is one :meth:`BlockPusher.step`; :class:`primspace.sim.execute.Executor`
    runs the same steps one at a time (and may move the block between them).

    Parameters
    ----------
    scene : Scene
    joints : ndarray, shape (T, 9)
        7 arm joint angles (rad) and 2 finger positions (m) per step.
    block_xy : (float, float)
        Where the block starts (its centre; it rests on the table).
    size : float
        Block edge (m).
    push_axis : {None, 0, 1}
        The axis along which the fingers may push the block (None: it stays put).
    push_sign : {1, -1}
        The direction of that push.

    Returns
    -------
    Rollout
    """
    joints = np.asarray(joints, dtype=float)
    pusher = BlockPusher(scene, block_xy, size, len(joints), push_axis, push_sign)
    for q in joints:
        pusher.step(q)
    return pusher.rollout()


class BlockPusher:
    """The kinematic block model and the measurements of :func:`replay`, one step at a time.

    Each :meth:`step` sets the arm's joints, lets the fingers push the block (the model in
    the module docstring), places the block and records the step; :meth:`move_block`
    moves the block between two steps by something other than the robot (an *external*
    move, flagged in :attr:`Rollout.external` at the next step). The scene is the
    pusher's from its construction until its last step (the block's size is set in the
    scene's model).

    Parameters
    ----------
    scene : Scene
    block_xy : (float, float)
        Where the block starts (its centre; it rests on the table).
    size : float
        Block edge (m).
    steps : int
        The most steps that can be recorded (T).
    push_axis : {None, 0, 1}
        The axis along which the fingers may push the block (None: it stays put).
    push_sign : {1, -1}
        The direction of that push.

    Attributes
    ----------
    t : int
        The number of steps recorded.
    block : ndarray, shape (3,)
        The block's centre now (m).
    """

    def __init__(
        self, scene: Scene, block_xy, size: float, steps: int, push_axis: int | None = None, push_sign: int = 1
    ) -> None:
        scene.set_block(float(block_xy[0]), float(block_xy[1]), float(size))
        self.scene, self.size, self.steps = scene, size, int(steps)
        self.push_axis, self.push_sign = push_axis, push_sign
        self.half = 0.5 * size
        self.block = np.array([block_xy[0], block_xy[1], self.half], dtype=float)
        self.t = 0
        self._fingers = scene.left_finger_geoms + scene.right_finger_geoms
        n = self.steps
        self._out = {
            "tcp": np.empty((n, 3)),
            "rotation": np.empty((n, 3, 3)),
            "fingers": np.empty((n, 2)),
            "block": np.empty((n, 3)),
            "finger_distance": np.empty((n, 2)),
            "finger_side": np.empty((n, 2)),
            "arm_distance": np.empty(n),
            "table_distance": np.empty(n),
            "external": np.zeros(n, dtype=bool),
        }
        self._behind = False  # was the pusher at or behind the block's trailing face at the last step?
        self._moved = False  # was the block moved externally since the last step?

    def step(self, q: np.ndarray) -> None:
        """Record the next step: the arm at joints ``q`` (9 values), the block pushed by it.

        Raises
        ------
        IndexError
            When all ``steps`` are recorded.
        """
        t = self.t
        if t >= self.steps:
            raise IndexError(f"all {self.steps} steps are recorded")
        scene, block = self.scene, self.block
        scene.set_joints(q)
        if self.push_axis is not None:
            front = self._front()
            if front is None:
                self._behind = False
            else:
                gap = self._gap(front)
                if gap > 0 and self._behind:  # a push from behind; never from above or inside
                    block[self.push_axis] = front + self.push_sign * self.half
                    gap = 0.0
                self._behind = gap <= _FACE_TOLERANCE
        scene.data.mocap_pos[scene.block_mocap] = block
        _record(scene, self._out, t, block)
        self._out["fingers"][t] = q[7:9]
        self._out["external"][t] = self._moved
        self._moved = False
        self.t = t + 1

    def move_block(self, dx: float, dy: float) -> None:
        """Move the block by ``(dx, dy)`` on the table (m), not by the robot.

        The next step is flagged external. Whether the fingers are behind the block's
        trailing face is judged again at the moved block (with the arm where the last step
        left it), so a block put onto or in front of the fingers is not pushed by them.
        """
        self.block[0] += dx
        self.block[1] += dy
        self.scene.data.mocap_pos[self.scene.block_mocap] = self.block
        self._moved = True
        if self.push_axis is not None and self.t > 0:
            front = self._front()
            self._behind = front is not None and self._gap(front) <= _FACE_TOLERANCE

    def rollout(self) -> Rollout:
        """The :class:`Rollout` of the steps recorded so far (copies)."""
        n = self.t
        return Rollout(size=float(self.size), **{k: v[:n].copy() for k, v in self._out.items()})

    def _front(self) -> float | None:
        """The pusher's leading coordinate at the block's face (None: no finger overlaps it)."""
        block, half = self.block, self.half
        return pusher_front(self.scene, self._fingers, self.push_axis, self.push_sign, block - half, block + half)

    def _gap(self, front: float) -> float:
        """How far the pusher has passed the trailing face (``block - sign * half``)."""
        sign = self.push_sign
        return sign * (front - (self.block[self.push_axis] - sign * self.half))


def _record(scene: Scene, out: dict, t: int, block: np.ndarray) -> None:
    """Step ``t`` of :class:`BlockPusher` (joints and block already set): TCP, block and distances."""
    m, d = scene.model, scene.data
    fingers = scene.left_finger_geoms + scene.right_finger_geoms
    tip_geoms = (scene.left_finger_geoms[0], scene.right_finger_geoms[0])
    mujoco.mj_kinematics(m, d)
    out["tcp"][t] = d.site_xpos[scene.tcp]
    out["rotation"][t] = d.site_xmat[scene.tcp].reshape(3, 3)
    out["block"][t] = block
    bg, tg = scene.block_geom, scene.table_geom
    out["finger_distance"][t, 0] = min(
        mujoco.mj_geomDistance(m, d, g, bg, DIST_MAX, None) for g in scene.left_finger_geoms
    )
    out["finger_distance"][t, 1] = min(
        mujoco.mj_geomDistance(m, d, g, bg, DIST_MAX, None) for g in scene.right_finger_geoms
    )
    out["finger_side"][t] = [d.geom_xpos[g, 1] - block[1] for g in tip_geoms]
    out["arm_distance"][t] = min(mujoco.mj_geomDistance(m, d, g, bg, DIST_MAX, None) for g in scene.hand_geoms)
    out["table_distance"][t] = min(
        mujoco.mj_geomDistance(m, d, g, tg, DIST_MAX, None) for g in fingers + scene.hand_geoms
    )
