"""The seven motion primitives: end-effector paths scripted relative to the block.

The paper (section "Artificial Data") scripts the tip of the manipulator: every motion
starts from the same home posture, first approaches the block, then

==============  =============================================================
``touch``        touch the block on top and stop
``grasp``        grasp it with the two fingers and stop
``push``         push it to the far side of the table
``pull``         pull it to the near side of the table
``touch_right``  repeatedly touch it from the right (three touches)
``circle_cw``    circle around it clockwise (seen from above)
``circle_ccw``   circle around it counter-clockwise
==============  =============================================================

A path is a sequence of key poses of the tool centre point (TCP, between the fingertips;
see :mod:`primspace.sim.scene`) at fixed fractions of the motion's duration, joined by
minimum-jerk segments ``s(u) = 10u^3 - 15u^4 + 6u^5`` (zero velocity and acceleration at
every key pose), so a path is smooth in time and the same fraction of every sample of a
primitive is the same phase. The gripper always points down with its fingers opening
along the world y axis. Circles sweep their angle with the same minimum-jerk profile.

Offsets that depend on the fingers' shape (how far the closed fingers reach ahead of the
TCP, where the finger pads meet a block) are measured once on the model
(:class:`FingerGeometry`), so a push starts exactly at the block's face.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from primspace.errors import UserError
from primspace.sim.scene import FINGER_MAX, FINGERTIP_RADIUS, Scene

__all__ = [
    "PRIMITIVES",
    "primitive_index",
    "ScriptConstants",
    "SCRIPT",
    "R_DOWN",
    "FingerGeometry",
    "finger_geometry",
    "PUSH_AXIS",
    "Script",
    "script_motion",
    "home_posture",
    "grip_height",
    "circle_radius",
    "min_jerk",
]

#: Primitive names in label order (label i is PRIMITIVES[i]).
PRIMITIVES = ("touch", "grasp", "push", "pull", "touch_right", "circle_cw", "circle_ccw")

#: TCP orientation: gripper pointing down (TCP z = world -z), fingers opening along world y
#: (TCP x = world x, TCP y = world -y).
R_DOWN = np.diag([1.0, -1.0, -1.0])

#: The arm's "ready" posture (the Panda's usual one; joint 6 in this model's convention,
#: standard q6 - pi/2): the start of the search for the home posture.
_READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 0.0, 0.0])


def primitive_index(primitive) -> int:
    """Label index of a primitive given by name or index.

    Raises
    ------
    UserError
        For an unknown name or an index out of range.
    """
    if isinstance(primitive, (int, np.integer)) and not isinstance(primitive, bool):
        if 0 <= int(primitive) < len(PRIMITIVES):
            return int(primitive)
        raise UserError(f"primitive index {int(primitive)} out of range 0..{len(PRIMITIVES) - 1}")
    name = str(primitive)
    if name not in PRIMITIVES:
        raise UserError(f"unknown primitive {name!r}; choose from {', '.join(PRIMITIVES)}")
    return PRIMITIVES.index(name)


@dataclass(frozen=True)
class ScriptConstants:
    """Distances (m) and times (fractions of the motion) shared by the scripts and the judge."""

    home_tcp: tuple[float, float, float] = (0.35, 0.0, 0.25)
    push_target_x: float = 0.70  # block centre at the end of a push ("far side")
    pull_target_x: float = 0.32  # block centre at the end of a pull ("near side")
    hover: float = 0.05  # fingertips this far above the block's top when above it
    standoff: float = 0.03  # gap to a face before a push, pull or touch starts
    grip_below_centre: float = 0.005  # TCP this far below the block's mid-height ...
    table_clearance: float = 0.006  # ... but the fingertips at least this far above the table
    grip_squeeze: float = 0.001  # fingers commanded this far past the pads' contact
    circle_clearance: float = 0.06  # circle radius = size / 2 + this
    touches: int = 3  # touch_right
    approach_end: float = 0.30  # every primitive: home -> first key pose in [0, 0.30]
    descend_end: float = 0.55  # touch, grasp: reach the block
    close_end: float = 0.70  # grasp: fingers closed
    push_start: float = 0.45  # push, pull: at the push height, standoff from the face
    push_end: float = 0.90  # push, pull: block at its target
    touches_start: float = 0.40  # touch_right: first touch starts
    circle_end: float = 0.95  # circles: one full turn in [approach_end, circle_end]


SCRIPT = ScriptConstants()


def min_jerk(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile ``10u^3 - 15u^4 + 6u^5`` on [0, 1] (clipped outside)."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10.0 + u * (-15.0 + 6.0 * u))


def grip_height(size: float, c: ScriptConstants = SCRIPT) -> float:
    """TCP height for pushing, pulling, grasping, side touches and circles (m)."""
    return max(0.5 * size - c.grip_below_centre, FINGERTIP_RADIUS + c.table_clearance)


def circle_radius(size: float, c: ScriptConstants = SCRIPT) -> float:
    """Radius of the TCP's circle around the block's centre (m)."""
    return 0.5 * size + c.circle_clearance


# ---------------------------------------------------------------------------- geometry


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
            front = pusher_front(self.scene, self.scene.left_finger_geoms + self.scene.right_finger_geoms, axis, sign, lo, hi)
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


# ------------------------------------------------------------------------------- paths


class _Path:
    """Key poses joined by minimum-jerk segments (and circular arcs)."""

    def __init__(self, pos, finger: float) -> None:
        self.pos = np.asarray(pos, dtype=float)
        self.finger = float(finger)
        self.t = 0.0
        self.segments: list = []  # (t0, t1, f(u) -> (pos, finger))

    def move(self, t1: float, pos=None, finger: float | None = None) -> "_Path":
        p0, p1 = self.pos, self.pos if pos is None else np.asarray(pos, dtype=float)
        f0, f1 = self.finger, self.finger if finger is None else float(finger)
        self.segments.append((self.t, t1, lambda s: (p0 + (p1 - p0) * s[:, None], f0 + (f1 - f0) * s)))
        self.t, self.pos, self.finger = t1, p1, f1
        return self

    def circle(self, t1: float, centre, direction: int) -> "_Path":
        """One full turn around ``centre`` (x, y) from the current point; +1 counter-clockwise."""
        c = np.asarray(centre, dtype=float)
        rel = self.pos[:2] - c
        radius, theta0 = float(np.hypot(*rel)), float(np.arctan2(rel[1], rel[0]))
        z, f = self.pos[2], self.finger

        def arc(s):
            theta = theta0 + direction * 2.0 * np.pi * s
            xy = c + radius * np.column_stack([np.cos(theta), np.sin(theta)])
            return np.column_stack([xy, np.full(len(s), z)]), np.full(len(s), f)

        self.segments.append((self.t, t1, arc))
        self.t = t1
        self.pos = np.array([*(c + radius * np.array([np.cos(theta0), np.sin(theta0)])), z])
        return self

    def sample(self, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        times = np.linspace(0.0, 1.0, n_steps)
        pos = np.repeat(self.pos[None], n_steps, axis=0)
        finger = np.full(n_steps, self.finger)
        # fill from the last segment back so each time takes the segment it ends in
        for t0, t1, f in reversed(self.segments):
            sel = times <= t1 + 1e-12
            p, g = f(min_jerk((times[sel] - t0) / (t1 - t0)))
            pos[sel], finger[sel] = p, g
        return pos, finger


@dataclass
class Script:
    """A scripted motion: TCP path, finger command and how the block may move.

    Attributes
    ----------
    primitive : str
    tcp : ndarray, shape (T, 3)
        TCP positions (m); the orientation is :data:`R_DOWN` throughout.
    fingers : ndarray, shape (T,)
        Each finger joint's value (m): 0 closed, 0.04 open.
    block_xy : ndarray, shape (2,)
    size : float
    contact_start : float
        Fraction of the motion from which the primitive acts on the block (its contact
        phase: touching, gripping, pushing, touching again, circling).
    push_axis, push_sign : int or None, int
        The axis and direction along which the fingers may move the block.
    """

    primitive: str
    tcp: np.ndarray
    fingers: np.ndarray
    block_xy: np.ndarray
    size: float
    contact_start: float
    push_axis: int | None = None
    push_sign: int = 1

    @property
    def rotation(self) -> np.ndarray:
        return R_DOWN

    def contact_mask(self) -> np.ndarray:
        """(T,) bool: steps in the contact phase."""
        return np.linspace(0.0, 1.0, len(self.tcp)) >= self.contact_start - 1e-12

    def displaced(self, offset, ramp: float = 0.1) -> "Script":
        """The same script with its contact phase moved by ``offset`` (3,) metres.

        The offset is blended in with a minimum-jerk ramp over the ``ramp`` fraction of
        the motion before the contact phase, so the path stays smooth. Used to check
        that the success judge rejects a motion that misses the block.
        """
        t = np.linspace(0.0, 1.0, len(self.tcp))
        weight = min_jerk((t - (self.contact_start - ramp)) / ramp)
        tcp = self.tcp + weight[:, None] * np.asarray(offset, dtype=float)[None]
        return Script(self.primitive, tcp, self.fingers.copy(), self.block_xy.copy(), self.size,
                      self.contact_start, self.push_axis, self.push_sign)


#: The axis and direction along which each primitive moves the block (None: it stays).
PUSH_AXIS = {"push": (0, 1), "pull": (0, -1)}


def script_motion(scene: Scene, primitive, block_x: float, block_y: float, size: float, n_steps: int, c: ScriptConstants = SCRIPT) -> Script:
    """The scripted path of one primitive for a block at (x, y) of edge ``size``.

    Parameters
    ----------
    scene : Scene
        Measures the finger geometry (once).
    primitive : str or int
    block_x, block_y, size : float
        Block centre on the table and edge (m).
    n_steps : int
        T, the number of time steps (the motion lasts T - 1 steps of dt).

    Returns
    -------
    Script
    """
    name = PRIMITIVES[primitive_index(primitive)]
    geo = finger_geometry(scene)
    x, y, s = float(block_x), float(block_y), float(size)
    r = FINGERTIP_RADIUS
    z_hover = s + r + c.hover
    z_grip = grip_height(s, c)
    path = _Path(c.home_tcp, 0.0)
    contact_start = c.approach_end
    if name == "touch":
        path.move(c.approach_end, (x, y, z_hover)).move(c.descend_end, (x, y, s + r)).move(1.0)
        contact_start = c.descend_end
    elif name == "grasp":
        grip = geo.grip_opening(s, z_grip) - c.grip_squeeze
        path.move(c.approach_end, (x, y, z_hover), finger=FINGER_MAX).move(c.descend_end, (x, y, z_grip))
        path.move(c.close_end, finger=grip).move(1.0)
        contact_start = c.descend_end
    elif name in ("push", "pull"):
        sign = 1 if name == "push" else -1
        reach = geo.reach(0, sign, s, z_grip)
        start_x = x - sign * (0.5 * s + reach + c.standoff)
        target = c.push_target_x if name == "push" else c.pull_target_x
        end_x = target - sign * (0.5 * s + reach)
        path.move(c.approach_end, (start_x, y, z_hover)).move(c.push_start, (start_x, y, z_grip))
        path.move(c.push_end, (end_x, y, z_grip)).move(1.0)
        contact_start = c.push_start
    elif name == "touch_right":
        reach = geo.touch_reach(1, 1, s, z_grip)  # the fingers move +y towards the block's right face
        y_touch = y - 0.5 * s - reach
        y_out = y_touch - c.standoff
        path.move(c.approach_end, (x, y_out, z_hover)).move(c.touches_start, (x, y_out, z_grip))
        period = (1.0 - c.touches_start) / c.touches
        for k in range(c.touches):
            t0 = c.touches_start + k * period
            path.move(t0 + 0.35 * period, (x, y_touch, z_grip)).move(t0 + 0.55 * period)
            path.move(t0 + 0.90 * period, (x, y_out, z_grip)).move(t0 + period)
        contact_start = c.touches_start
    else:  # circles start on the near side of the block (-x) at the grip height
        radius = circle_radius(s, c)
        path.move(c.approach_end, (x - radius, y, z_grip))
        path.circle(c.circle_end, (x, y), -1 if name == "circle_cw" else 1).move(1.0)
    tcp, fingers = path.sample(n_steps)
    axis, sign = PUSH_AXIS.get(name, (None, 1))
    return Script(name, tcp, fingers, np.array([x, y]), s, contact_start, axis, sign)
