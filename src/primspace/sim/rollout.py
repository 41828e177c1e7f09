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

from dataclasses import dataclass

import primspace.sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from primspace.sim.scene import Scene  # noqa: E402

__all__ = ["Rollout", "replay", "geom_interval", "pusher_front"]

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
    t_len = len(joints)
    scene.set_block(float(block_xy[0]), float(block_xy[1]), float(size))
    half = 0.5 * size
    block = np.array([block_xy[0], block_xy[1], half], dtype=float)
    fingers = scene.left_finger_geoms + scene.right_finger_geoms
    out = {
        "tcp": np.empty((t_len, 3)),
        "rotation": np.empty((t_len, 3, 3)),
        "block": np.empty((t_len, 3)),
        "finger_distance": np.empty((t_len, 2)),
        "finger_side": np.empty((t_len, 2)),
        "arm_distance": np.empty(t_len),
        "table_distance": np.empty(t_len),
    }
    behind = False  # was the pusher at or behind the block's trailing face at the last step?
    for t in range(t_len):
        scene.set_joints(joints[t])
        if push_axis is not None:
            front = pusher_front(scene, fingers, push_axis, push_sign, block - half, block + half)
            if front is None:
                behind = False
            else:
                # how far the pusher has passed the trailing face (block - sign * half)
                gap = push_sign * (front - (block[push_axis] - push_sign * half))
                if gap > 0 and behind:  # a push from behind; never from above or inside
                    block[push_axis] = front + push_sign * half
                    gap = 0.0
                behind = gap <= _FACE_TOLERANCE
        scene.data.mocap_pos[scene.block_mocap] = block
        _record(scene, out, t, block)
    return Rollout(fingers=joints[:, 7:9].copy(), size=float(size), **out)


def _record(scene: Scene, out: dict, t: int, block: np.ndarray) -> None:
    """Step ``t`` of :func:`replay` (joints and block already set): TCP, block and distances."""
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
