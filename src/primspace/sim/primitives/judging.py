"""The success judge's vocabulary: tolerances, the verdict, and what a criterion reads.

Each primitive's criteria (:meth:`primspace.sim.primitives.Primitive.criteria`) are
checks on a replayed trajectory (:class:`~primspace.sim.rollout.Rollout`) seen through
:class:`Observed`, collected in order by a :class:`Verdict` into a :class:`SuccessResult`.
The judge as a whole (entry points, the reasons behind the criteria) is
:mod:`primspace.sim.success`. The paper (section "Intra-primitive generalisation", Table
"Success rates") judged grasps, pushes and pulls by watching video; these criteria make
that judgement objective.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from primspace.sim.primitives.script import grip_height
from primspace.sim.scene import FINGERTIP_RADIUS

if TYPE_CHECKING:
    from primspace.sim.rollout import Rollout

__all__ = ["Tolerances", "TOLERANCES", "SuccessResult", "Verdict", "Observed", "mm"]


@dataclass(frozen=True)
class Tolerances:
    """The judge's tolerances (m, degrees); see :mod:`primspace.sim.success`."""

    touch_gap: float = 0.004
    penetration: float = 0.005
    below_table: float = 0.003
    position: float = 0.010
    stopped: float = 0.005
    separation: float = 0.010
    min_turn_deg: float = 300.0
    hold_from: float = 0.80


TOLERANCES = Tolerances()


@dataclass
class SuccessResult:
    """The judge's verdict on one trajectory.

    Attributes
    ----------
    primitive : str
    success : bool
        Every criterion holds.
    reason : str
        ``"ok"``, or the first failed criterion with its measured value.
    criteria : dict of str to bool
        Each criterion's verdict.
    measures : dict of str to float
        The measured value behind each criterion (metres, degrees, counts).
    """

    primitive: str
    success: bool
    reason: str
    criteria: dict[str, bool] = field(default_factory=dict)
    measures: dict[str, float] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return self.success


class Verdict:
    """Collects criteria in order; the first failure names the reason.

    Parameters
    ----------
    primitive : str
        The name the reason starts with (``"push: the block ends ..."``).
    """

    def __init__(self, primitive: str) -> None:
        self.primitive = primitive
        self.criteria: dict[str, bool] = {}
        self.measures: dict[str, float] = {}
        self.reason = ""

    def check(self, name: str, ok: bool, value: float, why: str) -> None:
        """Record criterion ``name``: its verdict ``ok``, its measured ``value`` and, if it
        is the first to fail, the reason ``why``."""
        self.criteria[name] = bool(ok)
        self.measures[name] = float(value)
        if not ok and not self.reason:
            self.reason = f"{self.primitive}: {why}"

    def result(self) -> SuccessResult:
        """The :class:`SuccessResult`: a success when every recorded criterion holds."""
        ok = all(self.criteria.values())
        return SuccessResult(self.primitive, ok, "ok" if ok else self.reason, self.criteria, self.measures)


@dataclass(frozen=True)
class Observed:
    """What every primitive's criteria read off one replayed trajectory.

    Attributes
    ----------
    rollout : Rollout
        The replay: TCP, block, signed distances.
    t : ndarray, shape (T,)
        Time as a fraction of the motion, ``step / (T - 1)``.
    hold : ndarray, shape (T,), bool
        The hold window, ``t >= hold_from`` (the last 20 %).
    offset : ndarray, shape (T, 2)
        TCP minus block centre, horizontally (m).
    size, half : float
        The block's edge and half its edge (m).
    z_grip : float
        The scripted TCP height of grasps, pushes, pulls, side touches and circles,
        :func:`~primspace.sim.primitives.grip_height` (m).
    z_top : float
        The TCP height with the fingertips resting on the top face: ``size`` +
        :data:`~primspace.sim.scene.FINGERTIP_RADIUS` (m).
    """

    rollout: Rollout
    t: np.ndarray
    hold: np.ndarray
    offset: np.ndarray
    size: float
    half: float
    z_grip: float
    z_top: float

    @classmethod
    def of(cls, r: Rollout, tol: Tolerances) -> Observed:
        """Observe the replay ``r`` with the hold window of ``tol``."""
        t = np.linspace(0.0, 1.0, len(r.tcp))
        return cls(
            rollout=r,
            t=t,
            hold=t >= tol.hold_from - 1e-12,
            offset=r.tcp[:, :2] - r.block[:, :2],
            size=r.size,
            half=0.5 * r.size,
            z_grip=grip_height(r.size),
            z_top=r.size + FINGERTIP_RADIUS,
        )


def mm(v: float) -> str:
    """A distance in metres written in millimetres: ``"12.3 mm"``."""
    return f"{v * 1e3:.1f} mm"
