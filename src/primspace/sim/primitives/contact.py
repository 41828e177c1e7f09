"""Touch, grasp and touch_right: reach the block and touch or hold it; it stays where it is.

The paper (section "Artificial Data"): "Touch the block on top and stop", "Grasp the
block with two fingers and stop", "Repeatedly touch the block from the right". Times are
fractions of the motion; the grip height ``h`` is :func:`~primspace.sim.primitives.grip_height`.
"""

from __future__ import annotations

import numpy as np

from primspace.sim.primitives.base import Primitive
from primspace.sim.primitives.geometry import FingerGeometry
from primspace.sim.primitives.judging import Observed, Tolerances, Verdict, mm
from primspace.sim.primitives.script import SCRIPT, KeyPath, ScriptConstants, grip_height
from primspace.sim.scene import FINGER_MAX, FINGERTIP_RADIUS

__all__ = ["Touch", "Grasp", "TouchRight"]


class Touch(Primitive):
    """Touch the block on top and stop.

    **Script.** Above the block (fingertips ``hover`` = 5 cm over it) at 0.30; down until
    the fingertips rest on the top face's centre at 0.55; hold.

    **Criteria.** In the hold window: ``touching`` (closer finger within [-5, 4] mm of the
    block), ``on_top`` (TCP within 10 mm of the top face's centre, horizontally),
    ``height`` (TCP z within 10 mm of ``z_top``: the fingertips rest on the top face),
    ``stopped`` (TCP moves less than 5 mm); at every step: ``from_above`` (whenever the
    closer finger is within 10 mm of the block, the TCP is at most 10 mm below ``z_top``:
    the hand comes down onto the top face, not beside it).
    """

    name = "touch"
    label = 0
    description = "touch the block on top and stop"

    def key_poses(self, path: KeyPath, geo: FingerGeometry, x: float, y: float, s: float, c: ScriptConstants) -> float:
        z_hover = s + FINGERTIP_RADIUS + c.hover
        path.move(c.approach_end, (x, y, z_hover)).move(c.descend_end, (x, y, s + FINGERTIP_RADIUS)).move(1.0)
        return c.descend_end

    def criteria(self, v: Verdict, seen: Observed, tol: Tolerances) -> None:
        r, hold, z_top = seen.rollout, seen.hold, seen.z_top
        gap = float(r.contact_distance[hold].max())
        v.check(
            "touching",
            gap <= tol.touch_gap,
            gap,
            f"fingertips {mm(gap)} from the block while holding (touch: at most {mm(tol.touch_gap)})",
        )
        off = float(np.hypot(*seen.offset[hold].T).max())
        v.check(
            "on_top", off <= tol.position, off, f"TCP {mm(off)} from the top face's centre (at most {mm(tol.position)})"
        )
        dz = float(np.abs(r.tcp[hold, 2] - z_top).max())
        v.check(
            "height", dz <= tol.position, dz, f"TCP {mm(dz)} off the top-face touch height (at most {mm(tol.position)})"
        )
        near = r.contact_distance <= tol.separation
        low = float((z_top - r.tcp[near, 2]).max()) if near.any() else 0.0
        v.check(
            "from_above",
            low <= tol.position,
            low,
            f"near the block the TCP goes {mm(low)} below the top-face touch height (at most {mm(tol.position)})",
        )
        travel = float(np.ptp(r.tcp[hold], axis=0).max())
        v.check(
            "stopped",
            travel <= tol.stopped,
            travel,
            f"the gripper moves {mm(travel)} while it should stay (at most {mm(tol.stopped)})",
        )


class Grasp(Primitive):
    """Grasp the block with the two fingers and stop.

    **Script.** Above the block, fingers opening fully, at 0.30; down to ``h`` at 0.55;
    the fingers close onto the block's faces (``grip_squeeze`` = 1 mm past the pads'
    measured contact) by 0.70; hold.

    **Criteria.** In the hold window: ``closed`` (each finger within [-5, 4] mm of the
    block), ``opposite_sides`` (one fingertip on each side of the block's centre),
    ``around`` (each fingertip's centre, the finger's lowest capsule, at least size/2
    from the block's centre in y: the fingers are open around the block and hold it by
    its side faces, not closed on top of it), ``centred`` (TCP within 10 mm of the
    block's centre horizontally), ``height`` (TCP within 10 mm of ``h``).
    """

    name = "grasp"
    label = 1
    description = "grasp the block with the two fingers and stop"

    def key_poses(self, path: KeyPath, geo: FingerGeometry, x: float, y: float, s: float, c: ScriptConstants) -> float:
        z_hover, z_grip = s + FINGERTIP_RADIUS + c.hover, grip_height(s, c)
        grip = geo.grip_opening(s, z_grip) - c.grip_squeeze
        path.move(c.approach_end, (x, y, z_hover), finger=FINGER_MAX).move(c.descend_end, (x, y, z_grip))
        path.move(c.close_end, finger=grip).move(1.0)
        return c.descend_end

    def criteria(self, v: Verdict, seen: Observed, tol: Tolerances) -> None:
        r, hold = seen.rollout, seen.hold
        gap = float(r.finger_distance[hold].max())
        v.check(
            "closed",
            gap <= tol.touch_gap,
            gap,
            f"a finger is {mm(gap)} from the block while holding (at most {mm(tol.touch_gap)})",
        )
        straddle = float((r.finger_side[hold, 0] * r.finger_side[hold, 1]).max())
        v.check("opposite_sides", straddle < 0, straddle, "the fingertips are not on opposite sides of the block")
        inside = float((seen.half - np.abs(r.finger_side[hold])).max())
        v.check(
            "around",
            inside <= 0.0,
            inside,
            f"a fingertip is {mm(inside)} inside the block's side faces (the fingers must hold it by its sides, not rest on top)",
        )
        off = float(np.hypot(*seen.offset[hold].T).max())
        v.check(
            "centred", off <= tol.position, off, f"grip {mm(off)} off the block's centre (at most {mm(tol.position)})"
        )
        dz = float(np.abs(r.tcp[hold, 2] - seen.z_grip).max())
        v.check("height", dz <= tol.position, dz, f"grips {mm(dz)} off the grip height (at most {mm(tol.position)})")


class TouchRight(Primitive):
    """Touch the block repeatedly from the right (three touches).

    **Script.** ``standoff`` = 3 cm right (-y) of where the closed fingers touch the
    right face (measured, :meth:`~primspace.sim.primitives.FingerGeometry.touch_reach`),
    fingertips ``hover`` = 5 cm above the block's top, at 0.30; down to ``h`` at 0.40;
    then ``touches`` = 3 equal periods in [0.40, 1], each: in to the touch, hold, out,
    rest.

    **Criteria.** ``touches``: exactly 3 touches (closer finger within 4 mm; a new touch
    needs the fingers to have left the block by at least 10 mm); at every touching step:
    ``right_side`` (TCP on the block's right, -y, beyond its face), ``centred`` (TCP x
    within 10 mm of the block's) and ``height`` (TCP within 10 mm of ``h``).
    """

    name = "touch_right"
    label = 4
    description = "touch the block repeatedly from the right (three touches)"

    def key_poses(self, path: KeyPath, geo: FingerGeometry, x: float, y: float, s: float, c: ScriptConstants) -> float:
        z_hover, z_grip = s + FINGERTIP_RADIUS + c.hover, grip_height(s, c)
        reach = geo.touch_reach(1, 1, s, z_grip)  # the fingers move +y towards the block's right face
        y_touch = y - 0.5 * s - reach
        y_out = y_touch - c.standoff
        path.move(c.approach_end, (x, y_out, z_hover)).move(c.touches_start, (x, y_out, z_grip))
        period = (1.0 - c.touches_start) / c.touches
        for k in range(c.touches):
            t0 = c.touches_start + k * period
            path.move(t0 + 0.35 * period, (x, y_touch, z_grip)).move(t0 + 0.55 * period)
            path.move(t0 + 0.90 * period, (x, y_out, z_grip)).move(t0 + period)
        return c.touches_start

    def criteria(self, v: Verdict, seen: Observed, tol: Tolerances) -> None:
        r, offset = seen.rollout, seen.offset
        d = r.contact_distance
        touching = d <= tol.touch_gap
        count, armed = 0, True
        for k in range(len(d)):
            if touching[k] and armed:
                count, armed = count + 1, False
            elif d[k] >= tol.separation:
                armed = True
        v.check("touches", count == SCRIPT.touches, count, f"{count} touches (wanted {SCRIPT.touches})")
        if touching.any():
            beyond = float((r.tcp[touching, 1] - (r.block[touching, 1] - seen.half)).max())
            off = float(np.abs(offset[touching, 0]).max())
            dz = float(np.abs(r.tcp[touching, 2] - seen.z_grip).max())
        else:
            beyond = off = dz = 0.0
        v.check("right_side", beyond < 0, beyond, "touches the block elsewhere than on its right (-y) face")
        v.check(
            "centred", off <= tol.position, off, f"touches {mm(off)} off the face's centre (at most {mm(tol.position)})"
        )
        v.check("height", dz <= tol.position, dz, f"touches {mm(dz)} off the touch height (at most {mm(tol.position)})")
