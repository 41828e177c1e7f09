"""``primspace act``: one scene, the primitive asked for, executed in MuJoCo (docs/act.md).

The run's fitted demonstrations (its data file, or ``data=``) with their camera frames fit the
scene policy (:class:`~primspace.act.scene_policy.ScenePolicy`) and a ProMP of each
primitive. A scene is a data file's sample (``FILE:INDEX``: its block and its first joints)
or a block given as ``x,y,size`` in metres (the first joints: the mean first step of the
primitive's fitted demonstrations). Three planners execute it: the closed loop (the policy
asked every ``every`` steps with the camera frame), the open loop (its first plan replayed)
and ProMP re-conditioned on the executed joints; with ``perturb`` the block is moved by a
seeded 2-4 cm at 30 % of the motion, the same move for all three.

Outputs (written to a temporary directory, then renamed): ``executed.h5`` (the three executed
motions with their camera frames, as a data set), ``act.gif`` (the closed loop's camera
beside the open loop's, the joints traced) and ``result.json`` (last: the output is complete).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from primspace.act.episode import BlockMove, run_episode
from primspace.act.planner import DEFAULT_EVERY, check_every
from primspace.act.planners import PLANNERS, ProMPPlanner

CLOSED, OPEN, PROMP = PLANNERS
from primspace.utils.errors import UserError

__all__ = [
    "ACT_FILES",
    "ACT_MARK",
    "ActScene",
    "read_scene",
    "parse_scene",
    "fit_planners",
    "act",
    "write_outputs",
    "write_animation",
]

#: The mark ``act`` writes into its outputs (primspace.utils.outputs).
ACT_MARK = "primspace act"
#: The files of an ``act`` output directory (result.json last).
ACT_FILES = ("executed.h5", "act.gif", "result.json")


@dataclass(frozen=True)
class ActScene:
    """Where the block is and how the arm starts."""

    block_x: float
    block_y: float
    size: float
    first_joints: np.ndarray
    source: str

    def to_dict(self) -> dict:
        return {"block_x": self.block_x, "block_y": self.block_y, "size": self.size, "source": self.source}


def read_scene(text: str):
    """The block a ``--scene`` names, checked without the run: ``((x, y, size), None, None)`` for
    ``x,y,size``, ``((x, y, size), data, index)`` for ``FILE:INDEX``; one UserError otherwise (a file
    without block params, or whose params name the block's columns in another order, included)."""
    from primspace.data import MotionDataset
    from primspace.sim.config import PARAM_NAMES
    from primspace.sim.execute import check_block

    text = text.strip()
    parts = text.split(",")
    if len(parts) == 3:
        try:
            x, y, size = (float(p) for p in parts)
        except ValueError:
            raise UserError(f"--scene {text!r}: give x,y,size in metres (e.g. 0.5,0.0,0.05) or FILE:INDEX") from None
        return check_block(x, y, size), None, None
    path, _, index = text.rpartition(":")
    if not path or not index.strip().lstrip("-").isdigit():
        raise UserError(f"--scene {text!r}: give FILE:INDEX (a data file's sample) or x,y,size in metres")
    if not Path(path).is_file():
        raise UserError(f"--scene {path}: no such file")
    data = MotionDataset.load(path)
    i = int(index)
    if not 0 <= i < len(data):
        raise UserError(f"--scene {path}: sample {i} is outside 0..{len(data) - 1}")
    if data.params is None or data.params.shape[1] < 3:
        raise UserError(
            f"--scene {path}: the file has no block params (block_x, block_y, block_size) to place the block"
        )
    names = list(data.param_names or [])
    if set(PARAM_NAMES) & set(names) and tuple(names[:3]) != PARAM_NAMES:  # named, in another order
        raise UserError(
            f"--scene {path}: its params are ({', '.join(names)}); act reads the block from its first three, "
            f"{', '.join(PARAM_NAMES)}, in that order"
        )
    return check_block(*(float(v) for v in data.params[i, :3])), data, i


def parse_scene(text: str, fitted, primitive_rows: np.ndarray) -> ActScene:
    """``FILE:INDEX`` or ``x,y,size`` as a scene (module docstring; :func:`read_scene` checks it)."""
    (x, y, size), data, i = read_scene(text)
    if data is None:
        first = np.asarray(fitted.motor[primitive_rows, 0], dtype=np.float64).mean(axis=0)
        return ActScene(x, y, size, first, "given")
    return ActScene(
        x, y, size, np.asarray(data.motor[i, 0], dtype=np.float64), f"{text.strip().rpartition(':')[0]}:{i}"
    )


def fit_planners(run, fitted, every: int):
    """The scene policy (maps at steps ``0, every, 2·every, ...``) and the ProMP peer, fitted on
    ``fitted`` (the run's fitted demonstrations, with frames), scaled by the run's scaler."""
    from primspace.act.scene_policy import ScenePolicy
    from primspace.predict.peers import ProMPPeer

    motor = run.scaler.transform(fitted.motor)
    length = motor.shape[1]
    policy = ScenePolicy(
        steps=tuple(range(0, length - 1, every)),
        label_names=fitted.label_names,
        random_state=int(run.train_config.seed),
    ).fit(motor, fitted.labels, fitted.lengths, fitted.images)
    return policy, ProMPPeer().fit(motor, fitted.labels, fitted.lengths)


def _fitted(run, data):
    """The run's fitted demonstrations with their frames; one UserError when they cannot act."""
    from primspace.data import MotionDataset
    from primspace.sim.success import check_judgeable
    from primspace.train.starts import fitted_samples

    fitted = fitted_samples(run, None if data is None else MotionDataset.load(data))
    if not fitted.has_images:
        raise UserError(
            "act learns from the fitted demonstrations' camera frames, and the run's data has none "
            "(simulate with images, or give --data with frames)"
        )
    check_judgeable(fitted.without_images())
    return fitted.load_images()


def act(
    run, primitive, scene: str, perturb: bool = False, every: int = DEFAULT_EVERY, seed: int = 0, data=None
) -> dict:
    """Execute the scene with the three planners (module docstring): ``{"scene", "primitive",
    "move", "episodes": {planner: Episode}, "policy"}``."""
    from primspace.sim.execute import Executor, Perturbation
    from primspace.sim.scene import Scene
    from primspace.train.api import as_run

    run = as_run(run)
    every = check_every(every)
    fitted = _fitted(run, data)
    policy, promp = fit_planners(run, fitted, every)
    k = policy.primitives_.resolve(primitive)
    label = int(policy.primitives_.labels[k])
    where = parse_scene(scene, fitted, policy.primitives_.members(k))
    length = fitted.motor.shape[1]
    move = None
    if perturb:
        perturbation = Perturbation()
        _, dx, dy = perturbation.draw(np.random.default_rng([int(seed), 40]), where.block_x, where.block_y, where.size)
        move = BlockMove(perturbation.step_index(length), dx, dy)
    planners = {
        CLOSED: policy.planner(k, every),
        OPEN: policy.planner(k, None),
        PROMP: ProMPPlanner(promp, label, length, every),
    }
    shared = Scene()
    episodes = {}
    for name, planner in planners.items():
        with Executor(label, where.block_x, where.block_y, where.size, length, scene=shared) as executor:
            episodes[name] = run_episode(planner, executor, where.first_joints, run.scaler, length, move, True)
    return {
        "scene": where,
        "primitive": policy.primitives_.names[k],
        "label": label,
        "move": move,
        "episodes": episodes,
        "corrections": planners[CLOSED].corrections,
        "policy": policy.summary(),
        "fitted": fitted,
    }


def write_outputs(tmp: Path, outcome: dict, command: dict) -> dict:
    """executed.h5, act.gif and result.json of :func:`act`'s ``outcome`` into ``tmp``; the result's dict."""
    from primspace.data import MotionDataset

    episodes, fitted, where = outcome["episodes"], outcome["fitted"], outcome["scene"]
    names = list(episodes)
    executed = MotionDataset(
        motor=np.stack([e.motor for e in episodes.values()]).astype(np.float32),
        images=np.stack([e.frames for e in episodes.values()]),
        labels=np.full(len(names), outcome["label"], dtype=np.int64),
        params=np.tile([where.block_x, where.block_y, where.size], (len(names), 1)).astype(np.float32),
        source_ids=np.array(names),
        joint_names=fitted.joint_names,
        label_names=fitted.label_names,
        param_names=fitted.param_names,
        dt=fitted.dt,
    )
    executed.save(tmp / "executed.h5", writer=ACT_MARK)
    write_animation(tmp / "act.gif", outcome)
    moved = outcome["move"]
    result = {
        "writer": ACT_MARK,
        "command": command,
        "primitive": outcome["primitive"],
        "scene": where.to_dict(),
        "move": None if moved is None else moved.to_dict(),
        "every": command.get("every"),
        "corrections": outcome["corrections"],
        "episodes": {n: e.summary() for n, e in episodes.items()},
        "policy": outcome["policy"],
    }
    (tmp / "result.json").write_text(json.dumps(result, indent=2))
    return result


def write_animation(path, outcome: dict, overwrite: bool = True) -> Path:
    """The closed loop's camera beside the open loop's, the joints traced (solid: closed loop,
    dashed: open loop), titled with the primitive, the move and each planner's verdict."""
    from primspace.plots import draw_animation

    episodes, fitted = outcome["episodes"], outcome["fitted"]
    closed, open_ = episodes[CLOSED], episodes[OPEN]
    verdict = ", ".join(f"{n}: {'success' if e.success else 'failure'}" for n, e in episodes.items())
    moved = outcome["move"]
    how = "" if moved is None else f"; block moved {100 * np.hypot(moved.dx, moved.dy):.1f} cm at step {moved.step}"
    return draw_animation(
        path,
        closed.motor,
        open_.motor,
        images=closed.frames,
        replay_images=open_.frames,
        panel_titles=(CLOSED, OPEN),
        joint_names=fitted.joint_names,
        dt=fitted.dt,
        title=f"{outcome['primitive']}{how} — {verdict}",
        writer=ACT_MARK,
        overwrite=overwrite,
    )
