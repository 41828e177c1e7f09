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
cannot do everything). The rules, labels and presets: docs/simulator.md, section
"Long demonstrations (composite)".
"""

from __future__ import annotations

import itertools
import json
import math
import os
from dataclasses import asdict, dataclass, fields
from functools import lru_cache
from pathlib import Path

import numpy as np

from primspace.errors import DataError, UserError
from primspace.sim.config import MIN_LENGTH, PARAM_NAMES
from primspace.sim.primitives import (
    PRIMITIVES,
    R_DOWN,
    SCRIPT,
    KeyPath,
    finger_geometry,
    get_primitive,
    primitive_index,
)
from primspace.sim.primitives.judging import TOLERANCES, mm
from primspace.sim.scene import FINGER_MAX, FINGERTIP_RADIUS, TABLE

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

#: Where push and pull leave the block: the zone it is in afterwards (others leave it in place).
MOVES_TO = {"push": "far", "pull": "near"}

#: The primitives that may act on the block in each zone. ``start``: where it started (every
#: primitive works on the whole start area); ``far``: pushed to x = 0.70 m (circles there pass
#: beyond the arm's reach for large blocks off the centre line; push has nothing to do);
#: ``near``: pulled to x = 0.32 m (push and circles would need the hand behind or around the
#: block within 25 cm of the robot's base: the IK misses by 1-13 cm; pull has nothing to do).
ALLOWED = {
    "start": PRIMITIVES,
    "far": ("touch", "grasp", "pull", "touch_right"),
    "near": ("touch", "grasp", "touch_right"),
}


#: How far open fingers (a grasp's) open further as the hand lifts off the block (m).
_RELEASE = 0.005


@dataclass(frozen=True)
class CompositeConfig:
    """What long demonstrations to generate.

    Parameters
    ----------
    n_sequences : int
        N, the number of sequences.
    min_primitives, max_primitives : int
        Primitives per sequence, uniform in [min, max] (2..4).
    duration : (int, int)
        Steps of each primitive's script, uniform in [lo, hi] (lo >= ``MIN_LENGTH`` = 31).
    transition_steps : int
        Steps of the transition before each primitive after the first.
    primitives : tuple of str
        What chains are made of (labels stay their index in ``PRIMITIVES``).
    block_x, block_y, block_size : (float, float)
        Uniform ranges of the block's start (m); default: the ``paper`` grid's span.
    image_size : (int, int) or None
        Frame size (H, W); None: joints only.
    dt, ik_tolerance : float
        Seconds per step; the largest allowed TCP miss of the scripted path (m).
    verify : bool
        Judge each primitive's steps by its success criteria and each transition for
        entering the block; refuse a sequence that fails.
    """

    n_sequences: int = 600
    min_primitives: int = 2
    max_primitives: int = 4
    duration: tuple[int, int] = (40, 70)
    transition_steps: int = 12
    primitives: tuple[str, ...] = PRIMITIVES
    block_x: tuple[float, float] = (0.42, 0.60)
    block_y: tuple[float, float] = (-0.15, 0.15)
    block_size: tuple[float, float] = (0.035, 0.065)
    image_size: tuple[int, int] | None = None
    dt: float = 1.0
    ik_tolerance: float = 0.002
    verify: bool = True

    def __post_init__(self) -> None:
        for name in ("duration", "primitives", "block_x", "block_y", "block_size", "image_size"):
            value = getattr(self, name)
            object.__setattr__(self, name, None if value is None else tuple(value))

    @property
    def length(self) -> int:
        """T: the longest possible sequence (max primitives of the longest duration)."""
        return self.max_primitives * self.duration[1] + (self.max_primitives - 1) * self.transition_steps

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def validate(self) -> "CompositeConfig":
        """Check every field; raise :class:`UserError` naming the field. Returns self."""
        from primspace.sim.render import MAX_IMAGE_SIZE

        for name in self.primitives:
            primitive_index(name)
        checks = [
            ("n_sequences", self.n_sequences >= 1, "at least 1"),
            ("min_primitives", 2 <= self.min_primitives <= self.max_primitives <= 4, "2 <= min <= max <= 4"),
            (
                "duration",
                len(self.duration) == 2 and MIN_LENGTH <= self.duration[0] <= self.duration[1],
                f"(lo, hi) with {MIN_LENGTH} <= lo <= hi",
            ),
            ("transition_steps", self.transition_steps >= 2, "at least 2"),
            ("primitives", len(set(self.primitives)) == len(self.primitives) >= 2, "at least 2 distinct names"),
            (
                "image_size",
                self.image_size is None
                or (
                    len(self.image_size) == 2
                    and 1 <= self.image_size[0] <= MAX_IMAGE_SIZE[0]
                    and 1 <= self.image_size[1] <= MAX_IMAGE_SIZE[1]
                ),
                "None or (H, W)",
            ),
            ("dt", math.isfinite(self.dt) and self.dt > 0, "positive"),
            ("ik_tolerance", self.ik_tolerance > 0, "positive"),
        ]
        for name, (lo, hi) in (
            ("block_x", TABLE.block_x),
            ("block_y", TABLE.block_y),
            ("block_size", TABLE.block_size),
        ):
            v = getattr(self, name)
            checks.append(
                (name, len(v) == 2 and lo - 1e-9 <= v[0] <= v[1] <= hi + 1e-9, f"(lo, hi) within [{lo}, {hi}]")
            )
        for name, ok, want in checks:
            if not ok:
                raise UserError(f"composite setting {name} = {getattr(self, name)!r}: must be {want}")
        for k in range(self.min_primitives, self.max_primitives + 1):
            if not valid_chains(self.primitives, k):
                raise UserError(
                    f"composite setting primitives = {list(self.primitives)}: no allowed chain of {k} "
                    "(see ALLOWED: push and pull restrict what may follow)"
                )
        return self


#: ``composite-demo``: 72 sequences of 2-3 primitives, 31-40 steps each, joints only (CPU demo).
#: ``composite``: 600 sequences of 2-4 primitives, 40-70 steps each, joints only.
COMPOSITE_PRESETS: dict[str, CompositeConfig] = {
    "composite-demo": CompositeConfig(n_sequences=72, max_primitives=3, duration=(31, 40), transition_steps=8),
    "composite": CompositeConfig(),
}


def resolve_composite(config_or_preset) -> CompositeConfig:
    """A validated :class:`CompositeConfig` from a config, a preset name or a dict of fields."""
    if isinstance(config_or_preset, str):
        if config_or_preset not in COMPOSITE_PRESETS:
            raise UserError(
                f"unknown composite preset {config_or_preset!r}; choose from {', '.join(COMPOSITE_PRESETS)}"
            )
        config_or_preset = COMPOSITE_PRESETS[config_or_preset]
    elif isinstance(config_or_preset, dict):
        unknown = sorted(set(config_or_preset) - {f.name for f in fields(CompositeConfig)})
        if unknown:
            raise UserError(f"unknown composite setting(s): {', '.join(unknown)}")
        config_or_preset = CompositeConfig(**config_or_preset)
    if not isinstance(config_or_preset, CompositeConfig):
        raise UserError(f"expected a composite preset name or a CompositeConfig, got {type(config_or_preset).__name__}")
    try:
        return config_or_preset.validate()
    except (TypeError, ValueError) as exc:  # a value of the wrong kind (UserError passes through as it is)
        if isinstance(exc, UserError):
            raise
        raise UserError(f"composite settings: a value of the wrong kind ({exc})") from None


# ------------------------------------------------------------------------- plans


@lru_cache(maxsize=None)
def valid_chains(primitives: tuple[str, ...], k: int) -> tuple[tuple[str, ...], ...]:
    """Every chain of ``k`` names from ``primitives`` with no immediate repeat that
    :data:`ALLOWED` permits (the block's zone follows :data:`MOVES_TO`), in a fixed order."""
    chains = []
    for chain in itertools.product(primitives, repeat=k):
        zone, ok = "start", True
        for prev, name in zip((None,) + chain, chain):
            ok = ok and name != prev and name in ALLOWED[zone]
            zone = MOVES_TO.get(name, zone)
        if ok:
            chains.append(chain)
    return tuple(chains)


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
        (:func:`~primspace.sim.shards.shard_ranges`) run through :func:`primspace.parallel.run_jobs`.

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
    from primspace.files import check_output
    from primspace.parallel import default_workers, run_jobs
    from primspace.sim.generate import finished_shards
    from primspace.sim.shards import shard_ranges

    config, seed = resolve_composite(config_or_preset), int(seed)
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
