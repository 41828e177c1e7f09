"""The base class of a motion primitive: its name, label, script, criteria and metadata.

The paper (section "Artificial Data") defines each primitive by what the arm does after
approaching the block ("touch the block on top and stop", ...). A :class:`Primitive`
holds everything primspace knows about one of them, in one place:

- ``name``, ``label`` (its index in the data set's ``label_names``; never renumbered, data
  files store it) and a one-line ``description`` (the table in ``docs/simulator.md``);
- its **script** (:meth:`Primitive.key_poses`): the key poses of the TCP relative to the
  block, from which :meth:`Primitive.script` samples the path the generator solves;
- its **success criteria** (:meth:`Primitive.criteria`): the judge's checks on a replayed
  trajectory, run by :meth:`Primitive.judge` after the checks every primitive shares;
- metadata: ``push_axis`` and ``push_sign``, the direction in which the fingers may move
  the block (the kinematic block model of :mod:`primspace.sim.rollout`).

The registry (:mod:`primspace.sim.primitives.registry`) lists one instance of each
subclass in label order; generation, the judge and the documentation's test iterate it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

import numpy as np

from primspace.sim.primitives.geometry import FingerGeometry, finger_geometry
from primspace.sim.primitives.judging import TOLERANCES, Observed, SuccessResult, Tolerances, Verdict, mm
from primspace.sim.primitives.script import SCRIPT, KeyPath, Script, ScriptConstants

if TYPE_CHECKING:
    from primspace.sim.rollout import Rollout
    from primspace.sim.scene import Scene

__all__ = ["Primitive"]


class Primitive:
    """One motion primitive: script, success criteria and metadata (subclass per primitive).

    Attributes
    ----------
    name : str
        The name in ``label_names`` (``"touch"``, ...).
    label : int
        The label index stored in data files (0..6).
    description : str
        What the arm does after approaching the block, in one line.
    push_axis : int or None
        The world axis along which the fingers may move the block (None: it stays put).
    push_sign : int
        The direction of that move (+1 or -1).
    """

    name: ClassVar[str]
    label: ClassVar[int]
    description: ClassVar[str]
    push_axis: ClassVar[int | None] = None
    push_sign: ClassVar[int] = 1

    def __repr__(self) -> str:
        return f"{type(self).__name__}(label={self.label}, name={self.name!r})"

    # ------------------------------------------------------------------ script
    def script(
        self,
        scene: Scene,
        block_x: float,
        block_y: float,
        size: float,
        n_steps: int,
        c: ScriptConstants = SCRIPT,
        start=None,
    ) -> Script:
        """The scripted path of this primitive for a block at (x, y) of edge ``size``.

        Parameters
        ----------
        scene : Scene
            Measures the finger geometry (once per scene).
        block_x, block_y, size : float
            Block centre on the table and edge (m).
        n_steps : int
            T, the number of time steps (the motion lasts T - 1 steps of dt).
        c : ScriptConstants
        start : array-like, shape (3,), optional
            Where the TCP starts (m; fingers closed); default the home TCP
            ``c.home_tcp``. A long demonstration (:mod:`primspace.sim.composite`) starts
            each later primitive where the one before left the hand.

        Returns
        -------
        Script
        """
        geo = finger_geometry(scene)
        x, y, s = float(block_x), float(block_y), float(size)
        path = KeyPath(c.home_tcp if start is None else start, 0.0)
        contact_start = self.key_poses(path, geo, x, y, s, c)
        tcp, fingers = path.sample(n_steps)
        return Script(self.name, tcp, fingers, np.array([x, y]), s, contact_start, self.push_axis, self.push_sign)

    def key_poses(self, path: KeyPath, geo: FingerGeometry, x: float, y: float, s: float, c: ScriptConstants) -> float:
        """Add this primitive's key poses to ``path`` (which starts at home, fingers closed).

        Parameters
        ----------
        path : KeyPath
        geo : FingerGeometry
            The fingers' measured offsets.
        x, y, s : float
            Block centre and edge (m).
        c : ScriptConstants

        Returns
        -------
        float
            ``contact_start``: the fraction of the motion from which it acts on the block.
        """
        raise NotImplementedError

    # ---------------------------------------------------------------- criteria
    def judge(self, rollout: Rollout, tol: Tolerances = TOLERANCES) -> SuccessResult:
        """Apply this primitive's criteria to a replayed trajectory.

        First the criteria every primitive shares: ``no_penetration`` (no finger, hand or
        wrist goes more than ``tol.penetration`` into the block, at any step) and
        ``above_table`` (none goes more than ``tol.below_table`` below the table top);
        then :meth:`criteria`.
        """
        v = Verdict(self.name)
        r = rollout
        pen = float(r.penetration.max())
        v.check(
            "no_penetration",
            pen <= tol.penetration,
            pen,
            f"the robot goes {mm(pen)} into the block (at most {mm(tol.penetration)})",
        )
        low = float(-r.table_distance.min())
        v.check(
            "above_table",
            low <= tol.below_table,
            low,
            f"the robot goes {mm(low)} below the table top (at most {mm(tol.below_table)})",
        )
        self.criteria(v, Observed.of(r, tol), tol)
        return v.result()

    def criteria(self, v: Verdict, seen: Observed, tol: Tolerances) -> None:
        """Check this primitive's own criteria on ``seen``, recording each in ``v``."""
        raise NotImplementedError
