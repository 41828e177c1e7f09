"""The closed loop's settings chosen on the fitted demonstrations only (docs/act.md).

The closed loop (:class:`~primspace.act.planners.PolicyPlanner`) has five settings: the surprise
``threshold``, the continuity ``horizon``, the steps between two looks ``every``, the surprise's
``floor`` (its smallest scale) and ``visible`` (the share of the block a frame must show to be
compared). :class:`LoopTuner` chooses them without any evaluation scene: the fitted
demonstrations are split into K folds (stratified by primitive); for each fold the scene policy
is fitted on the other folds, and some of the fold's demonstrations are replayed as scenes in
MuJoCo (their block and first joints), with the block moved at each declared fraction of the
motion (:data:`~primspace.act.episode.MOVE_AT`) and left still. Every point of the grid runs
every such episode; a point's score is its mean success over them, and the chosen point is the
best, the earlier point of :meth:`LoopTuner.points` on a tie (the centre first: the settings
that were the defaults before tuning). Every point's score is recorded (:meth:`LoopTuning.to_dict`).

The tuner is given only the fitted demonstrations (a :class:`~primspace.data.MotionDataset`
with frames and block params) and their indices in the data file, which the record names; it
reads nothing else.
"""

from __future__ import annotations

import copy
import itertools
import time
from dataclasses import dataclass, field

import numpy as np

from primspace.act.episode import MOVE_AT, drawn_move
from primspace.act.planner import DEFAULT_EVERY
from primspace.utils.errors import UserError

__all__ = ["LOOP_CENTRE", "LOOP_GRID", "LoopTuner", "LoopTuning", "configured"]

#: The settings before tuning (hand-picked on evaluation scenes before 0.10): the grid's centre.
LOOP_CENTRE = {"threshold": 3.0, "horizon": 4, "every": DEFAULT_EVERY, "floor": 0.25, "visible": 0.6}
#: The values each setting may take.
LOOP_GRID = {
    "threshold": (2.0, 3.0, 4.5),
    "horizon": (2, 4, 8),
    "every": (2, 3, 5),
    "floor": (0.1, 0.25, 0.5),
    "visible": (0.4, 0.6, 0.8),
}
#: :attr:`LoopTuner.search`: ``"star"``: the centre, then each setting moved alone; ``"full"``: every combination.
SEARCHES = ("star", "full")
STILL = "still"


def configured(policy, settings: dict):
    """A shallow copy of the fitted ``policy`` with ``threshold``, ``horizon``, ``floor`` and ``visible``
    of ``settings`` (``every`` is the planner's); the fitted maps are shared."""
    out = copy.copy(policy)
    for name in ("threshold", "horizon", "floor", "visible"):
        if name in settings:
            setattr(out, name, type(LOOP_CENTRE[name])(settings[name]))
    return out


@dataclass
class LoopTuning:
    """What :meth:`LoopTuner.tune` measured: every point's score and the chosen one."""

    chosen: dict
    points: list
    scores: list
    by_condition: list
    replayed: list
    folds: int
    episodes: int
    seconds: float
    move_at: tuple = field(default=MOVE_AT)

    def to_dict(self) -> dict:
        """JSON-ready: the chosen settings, every point with its score, what was replayed, the cost."""
        return {
            "chosen": dict(self.chosen),
            "grid": [
                {"settings": dict(p), "success": float(s), "by_condition": dict(c)}
                for p, s, c in zip(self.points, self.scores, self.by_condition)
            ],
            "replayed_indices": [int(i) for i in self.replayed],
            "folds": int(self.folds),
            "episodes": int(self.episodes),
            "seconds": float(self.seconds),
            "move_at": [float(a) for a in self.move_at],
        }


@dataclass
class LoopTuner:
    """Choose the closed loop's settings on the fitted demonstrations (module docstring).

    Parameters
    ----------
    grid : dict
        Setting -> the values it may take (:data:`LOOP_GRID`).
    centre : dict
        The point tried first, ties going to it (:data:`LOOP_CENTRE`).
    search : {"star", "full"}
        The points tried (:data:`SEARCHES`).
    move_at : tuple of float
        The fractions of the motion at which the block is moved in the replayed episodes.
    folds : int
        K of the split (at most the fewest demonstrations of a primitive).
    per_primitive : int
        Demonstrations of each primitive replayed as scenes (over all folds).
    seed : int
        Seed of the folds, the replayed demonstrations and the moves.
    """

    grid: dict = field(default_factory=lambda: dict(LOOP_GRID))
    centre: dict = field(default_factory=lambda: dict(LOOP_CENTRE))
    search: str = "star"
    move_at: tuple = MOVE_AT
    folds: int = 5
    per_primitive: int = 3
    seed: int = 0

    def points(self) -> list[dict]:
        """The settings tried, the centre first."""
        if self.search not in SEARCHES:
            raise UserError(f"search must be one of {', '.join(SEARCHES)}, got {self.search!r}")
        names = list(self.centre)
        if self.search == "full":
            combos = [
                dict(zip(names, v)) for v in itertools.product(*(self.grid.get(n, (self.centre[n],)) for n in names))
            ]
        else:
            combos = [dict(self.centre, **{n: v}) for n in names for v in self.grid.get(n, ())]
        out = [dict(self.centre)]
        for point in combos:
            if point not in out:
                out.append(point)
        return out

    def split(self, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The fold of every demonstration (stratified by label) and the replayed ones (positions)."""
        labels = np.asarray(labels)
        rng = np.random.default_rng([int(self.seed), 52])
        fewest = min(int((labels == k).sum()) for k in np.unique(labels))
        k_folds = min(int(self.folds), fewest)
        if k_folds < 2:
            raise UserError(f"tuning the closed loop needs at least 2 demonstrations per primitive, got {fewest}")
        fold, replayed = np.empty(len(labels), dtype=np.int64), []
        for k in np.unique(labels):
            rows = rng.permutation(np.flatnonzero(labels == k))
            fold[rows] = np.arange(len(rows)) % k_folds
            replayed.extend(rows[: int(self.per_primitive)].tolist())
        return fold, np.array(sorted(replayed), dtype=np.int64)

    def tune(self, fitted, scaler, fit_policy, indices=None, runner=None) -> LoopTuning:
        """Score every point (module docstring) and return the record.

        Parameters
        ----------
        fitted : MotionDataset
            The fitted demonstrations with frames (loaded) and block params.
        scaler : the run's scaler
        fit_policy : callable
            ``fit_policy(motor_scaled, labels, frames, steps) -> ScenePolicy``, fitted on the
            demonstrations given, with maps at ``steps``.
        indices : array-like, optional
            The demonstrations' indices in the data file (the record's ``replayed_indices``).
        runner : callable, optional
            ``runner(policy, settings, position, move) -> bool``: one episode of the closed loop
            with ``settings`` on the demonstration at ``position`` of ``fitted``, the block moved
            by ``move`` (None: still). Default: MuJoCo (:func:`mujoco_runner`).
        """
        start = time.perf_counter()
        points = self.points()
        labels = np.asarray(fitted.labels)
        fold, replayed = self.split(labels)
        length = fitted.motor.shape[1]
        steps = sorted({t for p in points for t in range(0, length - 1, int(p["every"]))})
        runner = runner or mujoco_runner(fitted, scaler)
        motor = scaler.transform(fitted.motor).astype(np.float64)
        conditions = [*(f"move at {a:g}" for a in self.move_at), STILL]
        wins = np.zeros((len(points), len(conditions)))
        episodes = 0
        for f in np.unique(fold[replayed]):
            train = np.flatnonzero(fold != f)
            policy = fit_policy(motor[train], labels[train], fitted.images[train], tuple(steps))
            for i in replayed[fold[replayed] == f]:
                x, y, size = (float(v) for v in fitted.params[i, :3])
                rng = [int(self.seed), 52, int(i)]
                moves = [drawn_move(a, np.random.default_rng(rng), x, y, size, length) for a in self.move_at]
                for c, move in enumerate([*moves, None]):
                    for p, point in enumerate(points):
                        wins[p, c] += bool(runner(policy, point, int(i), move))
                        episodes += 1
        rates = wins / max(len(replayed), 1)
        scores = rates.mean(axis=1)
        best = int(np.flatnonzero(scores == scores.max())[0])
        where = np.arange(len(labels)) if indices is None else np.asarray(indices)
        return LoopTuning(
            chosen=dict(points[best]),
            points=points,
            scores=scores.tolist(),
            by_condition=[dict(zip(conditions, r.tolist())) for r in rates],
            replayed=[int(where[i]) for i in replayed],
            folds=int(len(np.unique(fold))),
            episodes=episodes,
            seconds=time.perf_counter() - start,
            move_at=tuple(self.move_at),
        )


def mujoco_runner(fitted, scaler):
    """The default episode of :meth:`LoopTuner.tune`: the closed loop on a fitted demonstration's scene
    in MuJoCo (:func:`~primspace.act.episode.run_episode`), its success."""
    from primspace.act.episode import run_episode
    from primspace.act.planners import PolicyPlanner
    from primspace.sim.execute import Executor
    from primspace.sim.scene import Scene

    scene, length = Scene(), fitted.motor.shape[1]

    def run(policy, settings: dict, i: int, move) -> bool:
        label = int(fitted.labels[i])
        x, y, size = (float(v) for v in fitted.params[i, :3])
        k = int(policy.primitives_.for_labels(np.array([label]))[0])
        planner = PolicyPlanner(configured(policy, settings), k, int(settings["every"]))
        with Executor(label, x, y, size, length, scene=scene) as executor:
            return bool(run_episode(planner, executor, fitted.motor[i, 0], scaler, length, move).success)

    return run
