"""The registry of primitives, in label order: what generation, judging and docs iterate.

The paper (section "Artificial Data") has seven primitives; their label indices are stored
in every data file (``labels`` with ``label_names``), so the order here never changes:
a new primitive gets the next label.
"""

from __future__ import annotations

import numpy as np

from primspace.sim.primitives.base import Primitive
from primspace.sim.primitives.circle import CircleCCW, CircleCW
from primspace.sim.primitives.contact import Grasp, Touch, TouchRight
from primspace.sim.primitives.move import Pull, Push
from primspace.sim.primitives.script import SCRIPT, Script, ScriptConstants
from primspace.sim.scene import Scene
from primspace.utils.errors import UserError

__all__ = ["REGISTRY", "PRIMITIVES", "PUSH_AXIS", "get_primitive", "primitive_index", "script_motion"]


def _in_label_order(*primitives: Primitive) -> tuple[Primitive, ...]:
    """The primitives as given, after checking that label i is the i-th and names are unique."""
    for i, p in enumerate(primitives):
        if p.label != i:
            raise RuntimeError(f"{p!r} is registered at position {i}: labels must be 0, 1, ... in order")
    names = [p.name for p in primitives]
    if len(set(names)) != len(names):
        raise RuntimeError(f"primitive names repeat: {names}")
    return primitives


#: One instance of every primitive, in label order (``REGISTRY[i].label == i``).
REGISTRY: tuple[Primitive, ...] = _in_label_order(
    Touch(), Grasp(), Push(), Pull(), TouchRight(), CircleCW(), CircleCCW()
)

#: Primitive names in label order (label i is PRIMITIVES[i]).
PRIMITIVES: tuple[str, ...] = tuple(p.name for p in REGISTRY)

#: The axis and direction along which each primitive moves the block (absent: it stays).
PUSH_AXIS: dict[str, tuple[int, int]] = {
    p.name: (p.push_axis, p.push_sign) for p in REGISTRY if p.push_axis is not None
}


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


def get_primitive(primitive) -> Primitive:
    """The registered :class:`Primitive` given by name, label index or itself.

    Raises
    ------
    UserError
        For an unknown name or an index out of range.
    """
    if isinstance(primitive, Primitive):
        return REGISTRY[primitive_index(primitive.name)]
    return REGISTRY[primitive_index(primitive)]


def script_motion(
    scene: Scene, primitive, block_x: float, block_y: float, size: float, n_steps: int, c: ScriptConstants = SCRIPT
) -> Script:
    """The scripted path of one primitive (name or index) for a block at (x, y) of edge ``size``:
    :meth:`Primitive.script` of :func:`get_primitive` ``(primitive)``."""
    return get_primitive(primitive).script(scene, block_x, block_y, size, n_steps, c)
