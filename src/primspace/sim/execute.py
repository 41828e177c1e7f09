"""Execute a joint trajectory step by step in the scene, with the block moved during it.

A closed loop in the simulator: :class:`Executor` runs one primitive's joint
values one step at a time, as a controller would send them, and the block may be moved
between two steps by something other than the robot (:meth:`Executor.move_block`, a
perturbation). Each step is the kinematic model of :func:`primspace.sim.rollout.replay`
(:class:`~primspace.sim.rollout.BlockPusher`): executed without moves, a trajectory gives
exactly the replay's :class:`~primspace.sim.rollout.Rollout`. The camera's frame of the
scene as it is now (:meth:`Executor.frame`) is what a policy would see; the judge
(:meth:`Executor.judge`) reads the block where it is at every step, so a motion planned
for the block's old place fails and one planned for its new place can succeed.

**Workspace.** A block (at the start or after a move) must lie where the ``paper``
preset places blocks (:data:`WORKSPACE`): its grid of centres extended by the jitter's
reach (x 0.4125..0.6075 m, y -0.1625..0.1625 m), edges 0.035..0.065 m
(:func:`check_block`). :class:`Perturbation` draws seeded moves that stay inside it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from primspace.sim.config import PRESETS
from primspace.sim.primitives import get_primitive
from primspace.sim.primitives.judging import TOLERANCES, SuccessResult, Tolerances
from primspace.sim.render import MAX_IMAGE_SIZE, Camera
from primspace.sim.rollout import BlockPusher, Rollout
from primspace.sim.scene import JOINT_NAMES, Scene
from primspace.utils.errors import UserError

__all__ = ["Executor", "Perturbation", "WORKSPACE", "check_block"]


def _workspace() -> dict[str, tuple[float, float]]:
    config = PRESETS["paper"]
    out = {}
    for name in ("block_x", "block_y"):
        values, reach = getattr(config, name), config.jitter * config.spacing(name)
        out[name] = (round(min(values) - reach, 9), round(max(values) + reach, 9))
    out["block_size"] = (min(config.block_size), max(config.block_size))
    return out


#: Where a block may be (m): ``{"block_x": (lo, hi), "block_y": ..., "block_size": ...}``,
#: the ``paper`` preset's grid of block centres extended by its jitter's reach, and its sizes.
WORKSPACE: dict[str, tuple[float, float]] = _workspace()

_EDGE = 1e-9  # a value this far outside a range still counts as inside (rounding)


def check_block(block_x: float, block_y: float, size: float) -> tuple[float, float, float]:
    """Check a block lies in the workspace (:data:`WORKSPACE`); return it as floats.

    Raises
    ------
    UserError
        Naming the field, e.g. ``block_y = 0.31 is outside the workspace -0.1625..0.1625 m``.
    """
    values = {"block_x": block_x, "block_y": block_y, "block_size": size}
    for name, value in values.items():
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise UserError(f"{name} = {value!r} is not a number") from None
        if not math.isfinite(v):
            raise UserError(f"{name} = {v} is not a finite number")
        lo, hi = WORKSPACE[name]
        if not lo - _EDGE <= v <= hi + _EDGE:
            what = "block sizes" if name == "block_size" else "workspace"
            raise UserError(f"{name} = {v:.4g} is outside the {what} {lo:.4g}..{hi:.4g} m")
        values[name] = v
    return values["block_x"], values["block_y"], values["block_size"]


def _inside(x: float, y: float) -> bool:
    (xlo, xhi), (ylo, yhi) = WORKSPACE["block_x"], WORKSPACE["block_y"]
    return xlo <= x <= xhi and ylo <= y <= yhi


class Executor:
    """Run one primitive in the scene step by step; the block may be moved between steps.

    Use it as a context manager (or call :meth:`close`) when it renders frames: it keeps
    one :class:`~primspace.sim.render.Camera` (an OpenGL context) open, made at the first
    :meth:`frame`.

    Parameters
    ----------
    primitive : str or int
        The primitive's name or label index: whether and which way the fingers push the
        block, and whose criteria :meth:`judge` applies.
    block_x, block_y, size : float
        Where the block starts (its centre, m) and its edge (m); inside :data:`WORKSPACE`.
    steps : int
        T, the number of steps to execute (at least 2).
    image_size : (int, int) or None
        ``(height, width)`` of :meth:`frame` (the paper: 48 x 64); None: no frames.
    scene : Scene, optional
        A scene to use (building one takes ~0.7 s); a new one by default. It is the
        executor's while it runs (the block is placed and sized in it).

    Attributes
    ----------
    primitive : Primitive
    steps : int
    scene : Scene

    Raises
    ------
    UserError
        For an unknown primitive (listing them), a block outside the workspace (naming the
        field), fewer than 2 steps or a bad image size.
    """

    def __init__(
        self,
        primitive,
        block_x: float,
        block_y: float,
        size: float,
        steps: int,
        *,
        image_size: tuple[int, int] | None = (48, 64),
        scene: Scene | None = None,
    ) -> None:
        self.primitive = get_primitive(primitive)
        x, y, size = check_block(block_x, block_y, size)
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 2:
            raise UserError(f"steps = {steps!r}: must be an integer of at least 2")
        if image_size is not None:
            h, w = (int(v) for v in image_size)
            if not (1 <= h <= MAX_IMAGE_SIZE[0] and 1 <= w <= MAX_IMAGE_SIZE[1]):
                raise UserError(
                    f"image_size {h}x{w} out of range: height 1..{MAX_IMAGE_SIZE[0]}, width 1..{MAX_IMAGE_SIZE[1]}"
                )
            image_size = (h, w)
        self.steps = int(steps)
        self.image_size = image_size
        self.scene = Scene() if scene is None else scene
        prim = self.primitive
        self._pusher = BlockPusher(self.scene, (x, y), size, self.steps, prim.push_axis, prim.push_sign)
        self._camera: Camera | None = None

    @property
    def t(self) -> int:
        """The number of executed steps."""
        return self._pusher.t

    @property
    def block(self) -> np.ndarray:
        """The block's centre now, ``(x, y, z)`` (m; a copy)."""
        return self._pusher.block.copy()

    @property
    def size(self) -> float:
        """The block's edge (m)."""
        return float(self._pusher.size)

    def step(self, joints) -> None:
        """Execute the next step: the arm goes to ``joints``, its fingers may push the block.

        Parameters
        ----------
        joints : array-like, shape (9,)
            7 arm angles (rad) and 2 finger positions (m), in the order of
            :data:`~primspace.sim.scene.JOINT_NAMES`.

        Raises
        ------
        UserError
            For joints of the wrong shape or not finite, or when all steps are executed.
        """
        q = np.asarray(joints, dtype=float)
        if q.shape != (len(JOINT_NAMES),) or not np.isfinite(q).all():
            raise UserError(f"joints must be {len(JOINT_NAMES)} finite values, got shape {q.shape}")
        if self.t >= self.steps:
            raise UserError(f"all {self.steps} steps are executed")
        self._pusher.step(q)

    def move_block(self, dx: float, dy: float) -> None:
        """Move the block by ``(dx, dy)`` (m) on the table, by something other than the robot.

        The move happens before the next step, which is recorded as external
        (:attr:`~primspace.sim.rollout.Rollout.external`); moves before one step add up.
        Nothing checks that the block is clear of the hand: a block put into the fingers
        is a penetration the judge sees.

        Raises
        ------
        UserError
            When the moved block would leave the workspace (naming the field; the block
            stays where it is), or when all steps are executed (no step would see it).
        """
        if self.t >= self.steps:
            raise UserError(f"all {self.steps} steps are executed: a move now is seen by no step")
        dx, dy = float(dx), float(dy)
        if not (math.isfinite(dx) and math.isfinite(dy)):
            raise UserError(f"move ({dx}, {dy}) m: dx and dy must be finite")
        block = self._pusher.block
        try:
            check_block(block[0] + dx, block[1] + dy, self.size)
        except UserError as exc:
            raise UserError(f"moving the block by ({dx:+.4g}, {dy:+.4g}) m: {exc}") from None
        self._pusher.move_block(dx, dy)

    def run(self, joints, moves: Mapping[int, tuple[float, float]] | None = None) -> Rollout:
        """Execute the remaining steps of ``joints``; move the block before the steps in ``moves``.

        Parameters
        ----------
        joints : array-like, shape (T, 9)
            The whole trajectory; rows ``t`` .. ``T - 1`` are executed.
        moves : mapping of int to (float, float), optional
            ``{step: (dx, dy)}``: the block is moved by ``(dx, dy)`` just before ``step``.

        Returns
        -------
        Rollout
            Of every executed step (:meth:`rollout`).
        """
        joints = np.asarray(joints, dtype=float)
        if joints.ndim != 2 or len(joints) != self.steps:
            raise UserError(f"joints must have shape ({self.steps}, {len(JOINT_NAMES)}), got {joints.shape}")
        moves = dict(moves or {})
        bad = [k for k in moves if not self.t <= k < self.steps]
        if bad:
            raise UserError(f"moves at steps {sorted(bad)}: must be steps {self.t}..{self.steps - 1}")
        for k in range(self.t, self.steps):
            if k in moves:
                self.move_block(*moves[k])
            self.step(joints[k])
        return self.rollout()

    def frame(self, out: np.ndarray | None = None) -> np.ndarray:
        """The camera's view of the scene now: the arm at the last executed joints, the
        block where it is (after any move since).

        Returns
        -------
        ndarray, shape (H, W, 3), uint8

        Raises
        ------
        UserError
            Before the first step (the arm has no joints yet), without ``image_size``, or
            when no offscreen OpenGL context can be made.
        """
        if self.image_size is None:
            raise UserError("this executor renders no frames (image_size=None)")
        if self.t == 0:
            raise UserError("no step is executed yet: the first frame follows the first step")
        if self._camera is None:
            self._camera = Camera(self.scene, *self.image_size)
        return self._camera.render(out=out)

    def rollout(self) -> Rollout:
        """The :class:`~primspace.sim.rollout.Rollout` of the steps executed so far."""
        return self._pusher.rollout()

    def judge(self, tolerances: Tolerances = TOLERANCES) -> SuccessResult:
        """The primitive's success judge on the executed steps (at least 2).

        Raises
        ------
        UserError
            With fewer than 2 steps executed.
        """
        if self.t < 2:
            raise UserError(f"judging needs at least 2 executed steps, {self.t} so far")
        return self.primitive.judge(self.rollout(), tolerances)

    def close(self) -> None:
        """Release the camera's OpenGL context (if a frame was rendered)."""
        if self._camera is not None:
            self._camera.close()
            self._camera = None

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass(frozen=True)
class Perturbation:
    """A seeded external move of the block during a motion.

    Parameters
    ----------
    at : float
        When, as a fraction of the motion: the block is moved just before step
        ``round(at * (T - 1))`` (:meth:`step_index`).
    distance : (float, float)
        The range of the move's length (m), drawn uniformly.

    Raises
    ------
    UserError
        For ``at`` outside [0, 1] or a distance range that is not ``0 <= lo <= hi``.
    """

    at: float = 0.3
    distance: tuple[float, float] = (0.02, 0.04)

    def __post_init__(self) -> None:
        object.__setattr__(self, "distance", tuple(float(v) for v in self.distance))
        if not (math.isfinite(self.at) and 0.0 <= self.at <= 1.0):
            raise UserError(f"at = {self.at}: must be a fraction of the motion in [0, 1]")
        lo, hi = self.distance if len(self.distance) == 2 else (math.nan, math.nan)
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi):
            raise UserError(f"distance = {self.distance}: must be (lo, hi) m with 0 <= lo <= hi")

    def step_index(self, steps: int) -> int:
        """The step before which the block is moved in a motion of ``steps`` steps."""
        return int(round(self.at * (int(steps) - 1)))

    def draw(
        self, rng: np.random.Generator, block_x: float, block_y: float, size: float, tries: int = 100
    ) -> tuple[float, float, float]:
        """Draw a move of the block at ``(block_x, block_y)`` that keeps it in the workspace.

        The direction is uniform on the circle and the length uniform in ``distance``,
        redrawn until the moved block lies in :data:`WORKSPACE` (at most ``tries`` times;
        then the last draw is shortened to the workspace's edge along its direction, the
        one case where the length may fall below ``distance``).

        Parameters
        ----------
        rng : numpy.random.Generator
            The same seed gives the same move.
        block_x, block_y, size : float
            The block before the move (inside the workspace).

        Returns
        -------
        (float, float, float)
            ``(at, dx, dy)``: when (fraction of the motion) and how far (m).

        Raises
        ------
        UserError
            For a block outside the workspace.
        """
        x, y, _ = check_block(block_x, block_y, size)
        lo, hi = self.distance
        for _ in range(max(1, int(tries))):
            angle = rng.uniform(0.0, 2.0 * math.pi)
            length = rng.uniform(lo, hi) if hi > lo else lo
            dx, dy = length * math.cos(angle), length * math.sin(angle)
            if _inside(x + dx, y + dy):
                return self.at, dx, dy
        scale = min(1.0, *(_room(p, d, WORKSPACE[n]) for p, d, n in ((x, dx, "block_x"), (y, dy, "block_y"))))
        return self.at, dx * scale, dy * scale


def _room(position: float, delta: float, bounds: tuple[float, float]) -> float:
    """The largest fraction of ``delta`` that keeps ``position`` within ``bounds``."""
    if delta > 0:
        return max(0.0, (bounds[1] - position) / delta)
    if delta < 0:
        return max(0.0, (bounds[0] - position) / delta)
    return 1.0
