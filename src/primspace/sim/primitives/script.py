"""What every primitive's script is made of: constants, key-pose paths and the :class:`Script`.

The paper (section "Artificial Data") scripts the tip of the manipulator. Here a path is
a sequence of key poses of the tool centre point (TCP, between the fingertips; see
:mod:`primspace.sim.scene`) at fixed fractions of the motion's duration, joined by
minimum-jerk segments ``s(u) = 10u^3 - 15u^4 + 6u^5`` (zero velocity and acceleration at
every key pose), so a path is smooth in time and the same fraction of every sample of a
primitive is the same phase. The gripper always points down with its fingers opening
along the world y axis (:data:`R_DOWN`). Circles sweep their angle with the same
minimum-jerk profile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from primspace.sim.scene import FINGERTIP_RADIUS

__all__ = ["R_DOWN", "ScriptConstants", "SCRIPT", "min_jerk", "grip_height", "circle_radius", "KeyPath", "Script"]

#: TCP orientation: gripper pointing down (TCP z = world -z), fingers opening along world y
#: (TCP x = world x, TCP y = world -y).
R_DOWN = np.diag([1.0, -1.0, -1.0])


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


class KeyPath:
    """Key poses of the TCP (and the finger command) joined by minimum-jerk segments and arcs.

    Parameters
    ----------
    pos : array-like, shape (3,)
        Where the path starts (m).
    finger : float
        The finger joints' value at the start (m).

    Each call adds a segment ending at time ``t1`` (a fraction of the motion) and returns
    the path, so a script reads as a chain: ``path.move(0.3, above).move(0.55, on_top)``.
    """

    def __init__(self, pos, finger: float) -> None:
        self.pos = np.asarray(pos, dtype=float)
        self.finger = float(finger)
        self.t = 0.0
        self.segments: list = []  # (t0, t1, f(u) -> (pos, finger))

    def move(self, t1: float, pos=None, finger: float | None = None) -> KeyPath:
        """Straight to ``pos`` with the fingers to ``finger`` by ``t1`` (None: stay)."""
        p0, p1 = self.pos, self.pos if pos is None else np.asarray(pos, dtype=float)
        f0, f1 = self.finger, self.finger if finger is None else float(finger)
        self.segments.append((self.t, t1, lambda s: (p0 + (p1 - p0) * s[:, None], f0 + (f1 - f0) * s)))
        self.t, self.pos, self.finger = t1, p1, f1
        return self

    def circle(self, t1: float, centre, direction: int) -> KeyPath:
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
        """TCP positions (T, 3) and finger values (T,) at ``n_steps`` equally spaced times."""
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

    def displaced(self, offset, ramp: float = 0.1) -> Script:
        """The same script with its contact phase moved by ``offset`` (3,) metres.

        The offset is blended in with a minimum-jerk ramp over the ``ramp`` fraction of
        the motion before the contact phase, so the path stays smooth. Used to check
        that the success judge rejects a motion that misses the block.
        """
        t = np.linspace(0.0, 1.0, len(self.tcp))
        weight = min_jerk((t - (self.contact_start - ramp)) / ramp)
        tcp = self.tcp + weight[:, None] * np.asarray(offset, dtype=float)[None]
        return Script(
            self.primitive,
            tcp,
            self.fingers.copy(),
            self.block_xy.copy(),
            self.size,
            self.contact_start,
            self.push_axis,
            self.push_sign,
        )
