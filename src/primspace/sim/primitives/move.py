"""Push and pull: move the block along x to the far or the near side of the table.

The paper (section "Artificial Data"): "Push the block to the furthest side of the table",
"Pull the block to the closest side of the table". The two differ only in direction
(``push_sign``) and target, so they share :class:`MoveBlock`.

No separate "hand starts behind the block" or "monotone displacement" criterion is
needed: the kinematic block model (:mod:`primspace.sim.rollout`) moves the block only
along the primitive's direction, only when the fingers come from behind its trailing
face, and never back; a hand that comes from the wrong side goes through the block
(``no_penetration``) and leaves it where it was (``on_target``).
"""

from __future__ import annotations

import numpy as np

from primspace.sim.primitives.base import Primitive
from primspace.sim.primitives.geometry import FingerGeometry
from primspace.sim.primitives.judging import Observed, Tolerances, Verdict, mm
from primspace.sim.primitives.script import SCRIPT, KeyPath, ScriptConstants, grip_height
from primspace.sim.scene import FINGERTIP_RADIUS

__all__ = ["MoveBlock", "Push", "Pull"]


class MoveBlock(Primitive):
    """Move the block along x (``push_axis`` 0) in direction ``push_sign`` to a target x.

    **Script.** Above a point ``standoff`` = 3 cm before the block's trailing face (from
    where the closed fingers' measured reach touches it) at 0.30; down to the grip height
    ``h`` at 0.45; along ``push_sign * x`` until the block's centre is at the target x at
    0.90; hold.

    **Criteria.** ``on_target``: the block ends within 10 mm of its target x; while the
    robot moves the block (steps where its x changes, except a step flagged
    :attr:`~primspace.sim.rollout.Rollout.external`: moved by something else):
    ``centred`` (TCP within 10 mm of the block's centre line; an off-centre push would
    turn it) and ``height`` (TCP within 10 mm of ``h``; a push high on the block would
    tip it over); in the hold window: ``held`` (closer finger at most 10 mm
    from the block: the hand has not left the block it delivered; 10 mm is the judge's
    rule for "left the block", as for touch_right).
    """

    push_axis = 0

    def target_x(self, c: ScriptConstants) -> float:
        """Where the block's centre ends (m)."""
        raise NotImplementedError

    def key_poses(self, path: KeyPath, geo: FingerGeometry, x: float, y: float, s: float, c: ScriptConstants) -> float:
        sign = self.push_sign
        z_hover, z_grip = s + FINGERTIP_RADIUS + c.hover, grip_height(s, c)
        reach = geo.reach(self.push_axis, sign, s, z_grip)
        start_x = x - sign * (0.5 * s + reach + c.standoff)
        end_x = self.target_x(c) - sign * (0.5 * s + reach)
        path.move(c.approach_end, (start_x, y, z_hover)).move(c.push_start, (start_x, y, z_grip))
        path.move(c.push_end, (end_x, y, z_grip)).move(1.0)
        return c.push_start

    def criteria(self, v: Verdict, seen: Observed, tol: Tolerances) -> None:
        r = seen.rollout
        target = self.target_x(SCRIPT)
        miss = float(abs(r.block[-1, 0] - target))
        v.check(
            "on_target",
            miss <= tol.position,
            miss,
            f"the block ends {mm(miss)} from its target x = {target} m (at most {mm(tol.position)})",
        )
        # the robot moves the block at a step where its x changes, unless it was moved
        # externally before that step (a perturbation; Rollout.external)
        moving = np.r_[False, np.abs(np.diff(r.block[:, 0])) > 1e-9] & ~r.external
        if moving.any():
            off = float(np.abs(seen.offset[moving, 1]).max())
            dz = float(np.abs(r.tcp[moving, 2] - seen.z_grip).max())
        else:
            off = dz = 0.0
        v.check(
            "centred",
            off <= tol.position,
            off,
            f"pushes {mm(off)} off the block's centre line (at most {mm(tol.position)})",
        )
        v.check("height", dz <= tol.position, dz, f"pushes {mm(dz)} off the push height (at most {mm(tol.position)})")
        gap = float(r.contact_distance[seen.hold].max())
        v.check(
            "held",
            gap <= tol.separation,
            gap,
            f"the fingers are {mm(gap)} from the block while holding (at most {mm(tol.separation)}: the hand stays at the block it delivered)",
        )


class Push(MoveBlock):
    """Push the block to the far side of the table: along +x until its centre is at
    ``push_target_x`` = 0.70 m (see :class:`MoveBlock`)."""

    name = "push"
    label = 2
    description = "push the block to the far side of the table"
    push_sign = 1

    def target_x(self, c: ScriptConstants) -> float:
        return c.push_target_x


class Pull(MoveBlock):
    """Pull the block to the near side of the table: the hand goes over the block to behind
    its far face, then along -x until its centre is at ``pull_target_x`` = 0.32 m (see
    :class:`MoveBlock`)."""

    name = "pull"
    label = 3
    description = "pull the block to the near side of the table"
    push_sign = -1

    def target_x(self, c: ScriptConstants) -> float:
        return c.pull_target_x
