"""The seven motion primitives, one class each: script, success criteria and metadata.

The paper (section "Artificial Data") scripts the tip of the manipulator: every motion
starts from the same home posture, first approaches the block, then (label: name, class)

==  ==============  ============  ===========================================================
0   ``touch``        Touch         touch the block on top and stop
1   ``grasp``        Grasp         grasp the block with the two fingers and stop
2   ``push``         Push          push the block to the far side of the table
3   ``pull``         Pull          pull the block to the near side of the table
4   ``touch_right``  TouchRight    touch the block repeatedly from the right (three touches)
5   ``circle_cw``    CircleCW      circle around the block clockwise (seen from above)
6   ``circle_ccw``   CircleCCW     circle around the block counter-clockwise (seen from above)
==  ==============  ============  ===========================================================

Modules:

- :mod:`~primspace.sim.primitives.base`      :class:`Primitive`, the base class
- :mod:`~primspace.sim.primitives.contact`   :class:`Touch`, :class:`Grasp`, :class:`TouchRight`
- :mod:`~primspace.sim.primitives.move`      :class:`Push`, :class:`Pull`
- :mod:`~primspace.sim.primitives.circle`    :class:`CircleCW`, :class:`CircleCCW`
- :mod:`~primspace.sim.primitives.registry`  :data:`REGISTRY` (label order), :func:`get_primitive`
- :mod:`~primspace.sim.primitives.script`    key-pose paths, :class:`Script`, :data:`SCRIPT`
- :mod:`~primspace.sim.primitives.geometry`  the fingers' measured offsets, the home posture
- :mod:`~primspace.sim.primitives.judging`   tolerances and verdicts of the success judge

Usage::

    from primspace.sim.primitives import REGISTRY, get_primitive
    for p in REGISTRY:                                   # label order
        print(p.label, p.name, p.description)
    script = get_primitive("push").script(scene, 0.5, 0.0, 0.05, n_steps=61)
    verdict = get_primitive("push").judge(rollout)       # a SuccessResult
"""

from __future__ import annotations

from primspace.sim.primitives.base import Primitive
from primspace.sim.primitives.circle import Circle, CircleCCW, CircleCW
from primspace.sim.primitives.contact import Grasp, Touch, TouchRight
from primspace.sim.primitives.geometry import FingerGeometry, finger_geometry, home_posture
from primspace.sim.primitives.move import MoveBlock, Pull, Push
from primspace.sim.primitives.registry import (
    PRIMITIVES,
    PUSH_AXIS,
    REGISTRY,
    get_primitive,
    primitive_index,
    script_motion,
)
from primspace.sim.primitives.script import (
    R_DOWN,
    SCRIPT,
    KeyPath,
    Script,
    ScriptConstants,
    circle_radius,
    grip_height,
    min_jerk,
)

__all__ = [
    "Primitive",
    "REGISTRY",
    "get_primitive",
    "PRIMITIVES",
    "primitive_index",
    "Touch",
    "Grasp",
    "Push",
    "Pull",
    "TouchRight",
    "CircleCW",
    "CircleCCW",
    "MoveBlock",
    "Circle",
    "ScriptConstants",
    "SCRIPT",
    "R_DOWN",
    "FingerGeometry",
    "finger_geometry",
    "PUSH_AXIS",
    "KeyPath",
    "Script",
    "script_motion",
    "home_posture",
    "grip_height",
    "circle_radius",
    "min_jerk",
]
