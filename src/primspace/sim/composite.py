"""Long demonstrations: chains of 2-4 primitives on one block, with per-step ground truth.

The paper (section "Summary and Discussion") names the next step: behaviours made of
several consecutive primitives. A *sequence* is one block at a random (x, y, size) and
a random chain of 2-4 primitives, no primitive twice in a row, each with its own
duration. Primitive 1 is its single-primitive script from home; primitive k > 1 starts
where k - 1 ended, after a transition (:func:`transition_path`: lift straight up to a
safe height, fingers to closed, over the next first key pose if that is low) and acts
on the block where the replay left it. Every piece is solved by the same inverse
kinematics and replayed by the same block model as single primitives; with ``verify``
each script passes its success judge and no transition enters the block. A primitive
acts only where :data:`ALLOWED` says (push and pull move the block to where the arm
cannot do everything). The settings, their presets and the chains allowed live in
:mod:`primspace.sim.composite_config` (imported here too). The rules, labels and
presets: docs/simulator.md, section "Long demonstrations (composite)".
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from primspace.sim.composite_config import (
    ALLOWED,
    COMPOSITE_PRESETS,
    MOVES_TO,
    CompositeConfig,
    resolve_composite,
    valid_chains,
)
from primspace.sim.config import PARAM_NAMES
from primspace.sim.primitives import PRIMITIVES, R_DOWN, SCRIPT, KeyPath, finger_geometry, get_primitive
from primspace.sim.primitives.judging import TOLERANCES, mm
from primspace.sim.scene import FINGER_MAX, FINGERTIP_RADIUS
from primspace.utils.errors import DataError
from primspace.utils.seeds import check_seed

__all__ = [
    "CompositeConfig",
    "COMPOSITE_PRESETS",
    "ALLOWED",
    "MOVES_TO",
    "resolve_composite",
    "valid_chains",
    "SequencePlan",
    "draw_plan",
    "transition_path",
    "transition_steps",
    "simulate_sequence",
    "generate_chunk",
    "generate_composite",
]

#: How far open fingers (a grasp's) open further as the hand lifts off the block (m).
_RELEASE = 0.005


# ------------------------------------------------------------------------- plans


@dataclass(frozen=True)
class SequencePlan:
    """One sequence's draws: the block's start ``(x, y, size)``, the chain of primitive
    names and each one's script duration (steps)."""

    block: tuple[float, float, float]
    chain: tuple[str, ...]
    durations: tuple[int, ...]


def draw_plan(config: CompositeConfig, seed: int, index: int) -> SequencePlan:
    """The plan of sequence ``index``: uniform block, number of primitives, chain among
    :func:`valid_chains` and durations, from ``SeedSequence([seed, index])`` alone."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(index)]))
    block = tuple(float(rng.uniform(*getattr(config, name))) for name in ("block_x", "block_y", "block_size"))
    k = int(rng.integers(config.min_primitives, config.max_primitives + 1))
    chains = valid_chains(config.primitives, k)
    chain = chains[int(rng.integers(len(chains)))]
    durations = tuple(int(d) for d in rng.integers(config.duration[0], config.duration[1] + 1, size=k))
    return SequencePlan(block, chain, durations)


# ------------------------------------------------------------------- simulation


def transition_path(
    start, finger: float, size: float, first_key, n_steps: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The transition from where a primitive ended to where the next one's script starts.

    In [0, 0.5] the TCP lifts straight up from ``start`` to the safe height (fingertips
    ``hover`` over the top of a block of edge ``size``; open fingers, a grasp's, open 5
    mm more); in [0.5, 1] the fingers close (every script starts closed) and, if the
    next script's ``first_key`` pose is below the safe height (circles), the TCP moves
    over it at that height. Minimum-jerk segments (:class:`KeyPath`), ``n_steps``
    samples with both ends excluded (they are the scripts' own steps).

    Returns
    -------
    tcp : ndarray, shape (n_steps, 3)
    fingers : ndarray, shape (n_steps,)
    end : ndarray, shape (3,)
        Where the next script starts.
    """
    start, first_key = np.asarray(start, dtype=float), np.asarray(first_key, dtype=float)
    z_safe = max(size + FINGERTIP_RADIUS + SCRIPT.hover, float(start[2]))
    lifted = np.array([start[0], start[1], z_safe])
    end = lifted if first_key[2] >= z_safe - 1e-9 else np.array([first_key[0], first_key[1], z_safe])
    release = min(finger + _RELEASE, FINGER_MAX) if finger > 0 else 0.0  # a grasp lets go as it lifts
    path = KeyPath(start, finger).move(0.5, lifted, finger=release).move(1.0, end, finger=0.0)
    tcp, fingers = path.sample(n_steps + 2)
    return tcp[1:-1], fingers[1:-1], end


def _first_key_pose(scene, primitive, x: float, y: float, size: float) -> np.ndarray:
    """The end of ``primitive``'s approach: its first key pose for a block at (x, y)."""
    path = KeyPath(SCRIPT.home_tcp, 0.0)
    primitive.key_poses(path, finger_geometry(scene), x, y, size, SCRIPT)
    return path.segments[0][2](np.ones(1))[0][0]


def _piece(scene, primitive, block, size: float, duration: int, n_transition: int, end):
    """TCP path (n, 3), finger command (n,) and transition steps of one primitive's piece;
    ``end`` is ``(tcp, finger)`` where the last piece ended (None: the first, from home)."""
    x, y = float(block[0]), float(block[1])
    if end is None:
        script = primitive.script(scene, x, y, size, duration)
        return script.tcp, script.fingers, 0
    key = _first_key_pose(scene, primitive, x, y, size)
    tcp, fingers, start = transition_path(end[0], end[1], size, key, n_transition)
    script = primitive.script(scene, x, y, size, duration, start=start)
    return np.vstack([tcp, script.tcp]), np.concatenate([fingers, script.fingers]), n_transition


def _check(primitive, rollout, n_transition: int, config: CompositeConfig, what: str, index: int) -> None:
    """With ``verify``: the script steps pass the primitive's judge; the transition stays out of the block."""
    from primspace.sim.rollout import Rollout

    if not config.verify:
        return
    pen = float(rollout.penetration[:n_transition].max(initial=0.0))
    if pen > TOLERANCES.penetration:
        raise DataError(
            f"the transition before {primitive.name} goes {mm(pen)} into the block ({what})", field="motor", index=index
        )
    script = Rollout(
        **{
            f.name: getattr(rollout, f.name)[n_transition:] if f.name != "size" else rollout.size
            for f in fields(Rollout)
        }
    )
    verdict = primitive.judge(script)
    if not verdict.success:
        raise DataError(
            f"the generated motion fails the success judge: {verdict.reason} ({what})", field="motor", index=index
        )


def simulate_sequence(scene, config: CompositeConfig, plan: SequencePlan, index: int) -> dict:
    """Script, solve, replay and check one long demonstration (see the module docstring).

    Returns
    -------
    dict
        ``motor`` (L, 9) float64, ``block`` (L, 3) the block at each step, ``step_labels``
        and ``step_segments`` (L,) int32, ``ik_error`` (largest TCP miss, m).

    Raises
    ------
    DataError
        An IK miss over ``ik_tolerance`` or (``verify``) a failed check, naming the sample.
    """
    from primspace.sim.ik import solve_path
    from primspace.sim.rollout import replay

    home, (x, y, size) = finger_geometry(scene).home, plan.block
    block, end, err, parts = np.array([x, y]), None, 0.0, []
    what = f"chain {'-'.join(plan.chain)}, block at x={x:.3f} y={y:.3f} m, size {size:.3f} m"
    for k, (name, duration) in enumerate(zip(plan.chain, plan.durations)):
        primitive = get_primitive(name)
        tcp, fingers, n_tr = _piece(scene, primitive, block, size, duration, config.transition_steps, end)
        ik = solve_path(scene, tcp, R_DOWN, home)
        if not ik.max_position_error <= config.ik_tolerance:
            raise DataError(
                f"inverse kinematics misses the scripted path of {name} (primitive {k + 1}) by "
                f"{ik.max_position_error * 1e3:.2f} mm (tolerance {config.ik_tolerance * 1e3:.2f} mm; {what})",
                field="motor",
                index=index,
            )
        joints = np.column_stack([ik.q, fingers, fingers])
        rollout = replay(scene, joints, block, size, primitive.push_axis, primitive.push_sign)
        _check(primitive, rollout, n_tr, config, what, index)
        parts.append((joints, rollout.block, np.full(len(tcp), primitive.label), np.full(len(tcp), k)))
        block, end, err = rollout.block[-1, :2], (tcp[-1], fingers[-1]), max(err, ik.max_position_error)
    motor, blocks, labels, segments = (np.concatenate(a) for a in zip(*parts))
    return {
        "motor": motor,
        "block": blocks,
        "step_labels": labels.astype(np.int32),
        "step_segments": segments.astype(np.int32),
        "ik_error": err,
    }


def _render(scene, camera, motor: np.ndarray, blocks: np.ndarray, size: float, out: np.ndarray) -> None:
    """Frames of the valid steps into ``out[:L]``; the padding repeats the last frame."""
    scene.set_block(blocks[0, 0], blocks[0, 1], size)
    for t in range(len(motor)):
        scene.set_joints(motor[t])
        scene.data.mocap_pos[scene.block_mocap] = blocks[t]
        camera.render(out=out[t])
    out[len(motor) :] = out[len(motor) - 1]


# ------------------------------------------------------------------------ files


def _arrays(config: CompositeConfig, n: int) -> dict:
    """Empty arrays of the data set's fields for ``n`` sequences (step fields -1, labels -1)."""
    from primspace.data.schema import empty_arrays

    dims = {"N": n, "T": config.length, "J": 9, "P": 3}
    names = ["motor", "labels", "params", "lengths", "step_labels", "step_segments"]
    if config.image_size is not None:
        dims |= {"H": config.image_size[0], "W": config.image_size[1]}
        names.insert(1, "images")
    arrays = {"images": None, **empty_arrays(dims, names)}
    for name in ("labels", "step_labels", "step_segments"):
        arrays[name][...] = -1
    return arrays


def generate_chunk(config: CompositeConfig, seed: int, start: int, stop: int) -> dict:
    """Sequences ``start .. stop - 1`` (a job of :func:`generate_composite`).

    Returns
    -------
    dict
        ``start``, the data set's arrays (``motor`` (k, T, 9) float32 padded with the
        last valid value, ``images`` or None, ``labels`` -1, ``params`` the block's start,
        ``lengths``, ``step_labels``, ``step_segments``) and ``ik_error`` (k,).
    """
    from primspace.sim.generate import worker_scene
    from primspace.sim.render import Camera

    scene, k = worker_scene(), stop - start
    out = {"start": start, **_arrays(config, k), "ik_error": np.empty(k)}
    camera = Camera(scene, *config.image_size) if config.image_size is not None else None
    try:
        for j, index in enumerate(range(start, stop)):
            plan = draw_plan(config, seed, index)
            seq = simulate_sequence(scene, config, plan, index)
            n = len(seq["motor"])
            out["motor"][j, :n], out["motor"][j, n:] = seq["motor"], seq["motor"][-1]
            out["step_labels"][j, :n], out["step_segments"][j, :n] = seq["step_labels"], seq["step_segments"]
            out["lengths"][j], out["params"][j], out["ik_error"][j] = n, plan.block, seq["ik_error"]
            if camera is not None:
                _render(scene, camera, seq["motor"], seq["block"], plan.block[2], out["images"][j])
    finally:
        if camera is not None:
            camera.close()
    return out


def _file_settings(config: CompositeConfig, seed: int) -> dict:
    """The data set's names and attributes (the ``source`` records preset, seed and config)."""
    from primspace.sim.scene import JOINT_NAMES

    preset = next((name for name, cfg in COMPOSITE_PRESETS.items() if cfg == config), None)
    source = "primspace.sim.composite " + json.dumps({"preset": preset, "seed": int(seed), "config": config.to_dict()})
    return {
        "joint_names": list(JOINT_NAMES),
        "label_names": list(PRIMITIVES),
        "param_names": list(PARAM_NAMES),
        "dt": config.dt,
        "source": source,
    }


def generate_composite(
    config_or_preset="composite-demo",
    seed: int = 0,
    out: str | os.PathLike | None = None,
    *,
    overwrite: bool = False,
    progress: bool | None = None,
    workers: int | None = 1,
):
    """Generate long demonstrations (see the module docstring).

    Parameters
    ----------
    config_or_preset : str, CompositeConfig or dict
        A preset name (:data:`COMPOSITE_PRESETS`) or a configuration.
    seed : int
        Same seed, same arrays (for any ``workers``).
    out : path-like, optional
        HDF5 file, written atomically (:class:`~primspace.data.DatasetWriter`); None: in memory.
    overwrite : bool
        Replace an existing ``out``.
    progress : bool, optional
        Progress bar (default: when stderr is a terminal).
    workers : int or None
        Local processes (None: every usable core); chunks of consecutive sequences
        (:func:`~primspace.sim.shards.shard_ranges`) run through :func:`primspace.utils.parallel.run_jobs`.

    Returns
    -------
    MotionDataset or Path
        The data set in memory, or the written file's path.

    Raises
    ------
    UserError
        Unknown preset, settings out of range, an existing ``out`` without ``overwrite``.
    DataError
        A sequence that misses its path or fails its checks (named by index); nothing is written.
    """
    from primspace.data import DatasetWriter, MotionDataset
    from primspace.data.schema import arrays_of
    from primspace.sim.generate import finished_shards
    from primspace.sim.shards import shard_ranges
    from primspace.utils.files import check_output
    from primspace.utils.parallel import default_workers, run_jobs

    config, seed = resolve_composite(config_or_preset), check_seed(seed)
    if out is not None:
        check_output(out, overwrite)
    items = [(config, seed, a, b) for a, b in shard_ranges(config.n_sequences)]
    jobs = run_jobs(
        generate_chunk,
        items,
        workers=default_workers() if workers is None else max(1, int(workers)),
        description=f"generating {config.n_sequences} long demonstrations",
        progress=progress,
    )
    settings = _file_settings(config, seed)
    if out is not None:
        try:
            with DatasetWriter(
                out,
                n_samples=config.n_sequences,
                length=config.length,
                image_size=config.image_size,
                with_labels=True,
                with_params=True,
                with_steps=True,
                overwrite=overwrite,
                writer="primspace generate",
                **settings,
            ) as writer:
                for chunk in finished_shards(jobs):
                    writer.write(chunk["start"], **arrays_of(chunk))
        except DataError as exc:
            raise exc.located(path=out) from None
        return Path(out)
    arrays = _arrays(config, config.n_sequences)
    for chunk in finished_shards(jobs):
        sl = slice(chunk["start"], chunk["start"] + len(chunk["motor"]))
        for name, values in arrays_of(chunk).items():
            if values is not None:
                arrays[name][sl] = values
    return MotionDataset(**arrays, **settings)


def transition_steps(data) -> int:
    """The steps of the transition that begins each primitive after the first in ``data``, as
    the generator recorded them in its ``source`` (:func:`generate_composite`); 0 for data it
    did not make (LASA chains, imports: a boundary is one step)."""
    source = str(getattr(data, "source", "") or "")
    prefix = "primspace.sim.composite "
    if not source.startswith(prefix):
        return 0
    try:
        return int(json.loads(source[len(prefix) :])["config"]["transition_steps"])
    except (ValueError, KeyError, TypeError):
        return 0
