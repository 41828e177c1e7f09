"""Circle_cw and circle_ccw: one turn around the block without touching it.

The paper (section "Artificial Data"): "Do circular motion around the block in clockwise
direction" and "... in counter-clockwise direction". The two differ only in direction, so
they share :class:`Circle`. Directions are seen from above (+z looking down).
"""

from __future__ import annotations

import numpy as np

from primspace.sim.primitives.base import Primitive
from primspace.sim.primitives.geometry import FingerGeometry
from primspace.sim.primitives.judging import Observed, Tolerances, Verdict, mm
from primspace.sim.primitives.script import SCRIPT, KeyPath, ScriptConstants, circle_radius, grip_height

__all__ = ["Circle", "CircleCW", "CircleCCW"]


class Circle(Primitive):
    """One full turn around the block's centre in ``direction`` (+1 counter-clockwise).

    **Script.** To the near side (-x) of the block at radius
    :func:`~primspace.sim.primitives.circle_radius` = size/2 + 6 cm and the grip height
    ``h``, at 0.30; one full turn around the block's centre, its angle following the
    minimum-jerk profile, in [0.30, 0.95]; hold.

    **Criteria.** During the circle (t in [0.30, 0.95]): ``radius`` (TCP's horizontal
    distance to the block's centre within 10 mm of size/2 + 6 cm), ``height`` (TCP z
    within 10 mm of ``h``), ``turn`` (swept angle at least 300 degrees in this
    primitive's direction), ``no_touch`` (fingers stay at least 4 mm from the block).
    """

    direction: int

    def key_poses(self, path: KeyPath, geo: FingerGeometry, x: float, y: float, s: float, c: ScriptConstants) -> float:
        radius, z_grip = circle_radius(s, c), grip_height(s, c)
        path.move(c.approach_end, (x - radius, y, z_grip))
        path.circle(c.circle_end, (x, y), self.direction).move(1.0)
        return c.approach_end

    def criteria(self, v: Verdict, seen: Observed, tol: Tolerances) -> None:
        r, t, offset = seen.rollout, seen.t, seen.offset
        phase = (t >= SCRIPT.approach_end - 1e-12) & (t <= SCRIPT.circle_end + 1e-12)
        radius = circle_radius(seen.size)
        rho = np.hypot(*offset[phase].T)
        dev = float(np.abs(rho - radius).max())
        v.check(
            "radius",
            dev <= tol.position,
            dev,
            f"radius off by {mm(dev)} from {mm(radius)} (at most {mm(tol.position)})",
        )
        dz = float(np.abs(r.tcp[phase, 2] - seen.z_grip).max())
        v.check("height", dz <= tol.position, dz, f"circles {mm(dz)} off its height (at most {mm(tol.position)})")
        angle = np.unwrap(np.arctan2(offset[phase, 1], offset[phase, 0]))
        swept = float(np.degrees(angle[-1] - angle[0]))
        want = float(self.direction)
        v.check(
            "turn",
            want * swept >= tol.min_turn_deg,
            swept,
            f"turns {swept:+.0f} degrees (wanted at least {tol.min_turn_deg:.0f} "
            f"{'clockwise' if want < 0 else 'counter-clockwise'})",
        )
        near = float(r.contact_distance[phase].min())
        v.check(
            "no_touch",
            near >= tol.touch_gap,
            near,
            f"comes within {mm(near)} of the block (at least {mm(tol.touch_gap)})",
        )


class CircleCW(Circle):
    """Circle around the block clockwise, seen from above (see :class:`Circle`)."""

    name = "circle_cw"
    label = 5
    description = "circle around the block clockwise (seen from above)"
    direction = -1


class CircleCCW(Circle):
    """Circle around the block counter-clockwise, seen from above (see :class:`Circle`)."""

    name = "circle_ccw"
    label = 6
    description = "circle around the block counter-clockwise (seen from above)"
    direction = 1
