"""One episode in the simulator: plan from the scene, execute step by step, observe, re-plan.

The paper's framing is predictive coding: "Predicted information is compared with the real
one and internal state is corrected based on the error." Here the arm executes the plan one
step at a time in MuJoCo (:class:`~primspace.sim.execute.Executor`, the same kinematics and
block model as the success judge); after each step the planner is asked again when it is
due (:meth:`~primspace.act.planner.Planner.due`) with the camera frame of that step
and the joints executed so far, and the arm follows the new plan. A perturbation moves the
block on the table before one step (``move``: the step and the displacement), as a person
would push it aside while the arm approaches; the judge then checks the primitive against
where the block is.

Latency is the wall time of each plan (features, map, continuity; not the rendering, which
the camera does), measured with ``time.perf_counter`` in this process.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Episode", "BlockMove", "MOVE_AT", "drawn_move", "run_episode"]

#: When the closed loop's block is moved, as fractions of the motion, declared before any run: 20 %
#: (before any primitive's judged phase begins) and 30 % (where the circles' judged phase begins).
MOVE_AT = (0.2, 0.3)


@dataclass(frozen=True)
class BlockMove:
    """The block moved by ``(dx, dy)`` metres on the table before step ``step`` executes."""

    step: int
    dx: float
    dy: float

    def to_dict(self) -> dict:
        return {"step": int(self.step), "dx": float(self.dx), "dy": float(self.dy)}


@dataclass
class Episode:
    """What :func:`run_episode` did.

    Attributes
    ----------
    motor : ndarray (T, J)
        The executed joints, physical units.
    first_plan : ndarray (T, J)
        The plan made at step 0 (physical): what the open loop executes.
    success : bool
    verdict : SuccessResult
        The judge's criteria (:mod:`primspace.sim.success`).
    plan_steps : list of int
        The steps after which the planner was asked (it may keep its plan).
    latencies_ms : list of float
        The wall time of each ask.
    frames : ndarray (T, H, W, 3) uint8 or None
        The camera after each executed step (``record_frames``).
    move : BlockMove or None
    """

    motor: np.ndarray
    first_plan: np.ndarray
    success: bool
    verdict: object
    plan_steps: list = field(default_factory=list)
    latencies_ms: list = field(default_factory=list)
    frames: np.ndarray | None = None
    move: BlockMove | None = None

    def summary(self) -> dict:
        """JSON-ready: success, the failed criteria, plans and their latency."""
        lat = np.asarray(self.latencies_ms, dtype=float)
        return {
            "success": bool(self.success),
            "reason": str(self.verdict.reason),
            "looks": [int(s) for s in self.plan_steps],
            "latency_ms": {
                "median": float(np.median(lat)) if lat.size else None,
                "max": float(lat.max()) if lat.size else None,
            },
            "move": None if self.move is None else self.move.to_dict(),
        }


def drawn_move(at: float, rng: np.random.Generator, x: float, y: float, size: float, length: int) -> BlockMove:
    """A seeded 2-4 cm move of the block at ``(x, y)`` (edge ``size``) before step ``round(at (length - 1))``
    (:class:`~primspace.sim.execute.Perturbation`), drawn from ``rng``."""
    from primspace.sim.execute import Perturbation

    perturbation = Perturbation(at=float(at))
    _, dx, dy = perturbation.draw(rng, x, y, size)
    return BlockMove(perturbation.step_index(length), dx, dy)


def run_episode(
    planner,
    executor,
    first_joints: np.ndarray,
    scaler,
    length: int,
    move: BlockMove | None = None,
    record_frames: bool = False,
) -> Episode:
    """Execute one motion of ``length`` steps with ``planner`` in ``executor`` (module docstring).

    Parameters
    ----------
    planner : Planner
        Its :meth:`~primspace.act.planner.Planner.reset` is called first.
    executor : Executor
        A fresh executor of the scene (nothing executed yet).
    first_joints : ndarray (J,)
        The arm's joints at step 0 (physical units).
    scaler : the run's scaler (``transform`` / ``inverse_transform`` of (n, T, J) arrays)
    length : int
    move : BlockMove, optional
    record_frames : bool
        Keep the camera frame after every step (for the animation).
    """
    if move is not None and not 1 <= int(move.step) < int(length):
        from primspace.utils.errors import UserError

        raise UserError(f"the block can be moved before steps 1..{int(length) - 1}, got step {move.step}")
    planner.reset()
    first = np.asarray(first_joints, dtype=np.float64).reshape(1, 1, -1)
    executor.step(first[0, 0])
    executed = [scaler.transform(first)[0, 0].astype(np.float64)]
    frames = [executor.frame()] if record_frames else None
    plan_steps, latencies, plan, first_plan = [], [], None, None
    for s in range(length - 1):
        if planner.due(s):
            frame = frames[-1] if record_frames else executor.frame()
            start = time.perf_counter()
            plan = planner.plan(s, frame, np.stack(executed))
            latencies.append(1e3 * (time.perf_counter() - start))
            plan_steps.append(s)
            if first_plan is None:
                first_plan = plan
        if move is not None and move.step == s + 1:
            executor.move_block(move.dx, move.dy)
        joints = scaler.inverse_transform(plan[s + 1].reshape(1, 1, -1))[0, 0]
        executor.step(joints)
        executed.append(plan[s + 1].astype(np.float64))
        if record_frames:
            frames.append(executor.frame())
    verdict = executor.judge()
    motor = scaler.inverse_transform(np.stack(executed)[None])[0]
    return Episode(
        motor=motor,
        first_plan=scaler.inverse_transform(first_plan[None])[0],
        success=bool(verdict.success),
        verdict=verdict,
        plan_steps=plan_steps,
        latencies_ms=latencies,
        frames=None if frames is None else np.stack(frames),
        move=move,
    )
