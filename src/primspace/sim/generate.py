"""Generate the simulated data set (the paper's "Artificial Data"): presets, shards, HDF5.

Every sample is one primitive performed on one block: ``label`` = primitive index,
``params`` = ``block_x, block_y, block_size`` (m), ``motor`` = the 9 joint values
(7 arm angles in rad, 2 finger positions in m) at T steps, ``images`` = the fixed
camera's frames. Samples are ordered primitive-major: index
``((p * n_x + i_x) * n_y + i_y) * n_sizes + i_size``.

A sample is made in four steps: script the TCP path (:mod:`~primspace.sim.primitives`),
solve it by inverse kinematics (:mod:`~primspace.sim.ik`; a miss of more than
``ik_tolerance`` is an error naming the sample, never written), replay it to move the
block (:mod:`~primspace.sim.rollout`; with ``verify`` the success judge must accept it),
render the frames (:mod:`~primspace.sim.render`).

**Seeds.** The seed only moves each block within its grid cell (uniform jitter of
``jitter`` times the grid spacing each way, per axis); sizes are exact. Sample ``i``
draws from ``np.random.SeedSequence([seed, i])``, so the arrays do not depend on how
the samples are split into shards or on the number of workers (or the backend).

**Parallelism.** Samples are split into shards of consecutive indices whose size
depends on N alone (:func:`shard_ranges`), run through :func:`primspace.parallel.run_jobs`.
In memory, ``generate_shard`` is the job and returns arrays. With ``out``,
``write_shard`` is the job: it writes its shard as a complete data set file (atomic)
into ``.<out name>.shards/`` beside ``out``, with a ``manifest.json`` naming the
generation (settings, seed, layout, versions); this process merges the shards into
``out`` as they finish, copying the compressed image chunks as they are
(:meth:`~primspace.data.DatasetWriter.copy_from`), publishes it atomically when complete
and removes the shard directory. A failed job stops no other; the failures are reported
together and a re-run with the same settings and seed generates only the missing shards.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from primspace.errors import DataError, UserError
from primspace.sim.primitives import PRIMITIVES, R_DOWN, finger_geometry, primitive_index, script_motion

__all__ = [
    "GenerationConfig",
    "PRESETS",
    "PARAM_NAMES",
    "resolve_config",
    "sample_params",
    "generate_shard",
    "write_shard",
    "generate_dataset",
    "shard_size",
    "shard_ranges",
    "shard_dir",
    "shard_manifest",
    "simulate_sample",
]

#: Names of the generative factors stored in ``params``.
PARAM_NAMES = ("block_x", "block_y", "block_size")

#: The shortest motion whose phases (three side touches) every step rate resolves.
MIN_LENGTH = 31


def _grid(lo: float, hi: float, n: int) -> tuple[float, ...]:
    return tuple(round(float(v), 6) for v in np.linspace(lo, hi, n))


@dataclass(frozen=True)
class GenerationConfig:
    """What to generate: block grid, sizes, primitives, length, images.

    Parameters
    ----------
    block_x, block_y : tuple of float
        Grid of block centres on the table (m); every (x, y) pair is used.
    block_size : tuple of float
        Cube edges (m).
    primitives : tuple of str
        Which primitives (labels stay their index in :data:`PRIMITIVES`).
    length : int
        T, time steps per motion (the paper: 61, one per second of a one-minute motion).
    height, width : int
        Frame size (the paper: 48 x 64).
    images : bool
        Render camera frames (False: joints only, much faster).
    jitter : float
        Block positions move uniformly within +- ``jitter`` x grid spacing (per axis),
        drawn from the seed; 0 keeps the exact grid.
    dt : float
        Seconds per step (the paper: a 61-step minute, dt = 1 s).
    ik_tolerance : float
        Largest allowed distance between the TCP and its scripted path (m).
    verify : bool
        Replay every generated motion through the success judge and refuse one that
        fails (a guard against silently writing a bad sample; costs ~10 ms a sample).
    """

    block_x: tuple[float, ...] = _grid(0.42, 0.60, 7)
    block_y: tuple[float, ...] = _grid(-0.15, 0.15, 7)
    block_size: tuple[float, ...] = _grid(0.035, 0.065, 5)
    primitives: tuple[str, ...] = PRIMITIVES
    length: int = 61
    height: int = 48
    width: int = 64
    images: bool = True
    jitter: float = 0.25
    dt: float = 1.0
    ik_tolerance: float = 0.002
    verify: bool = True

    def __post_init__(self) -> None:
        for name in ("block_x", "block_y", "block_size", "primitives"):
            object.__setattr__(self, name, tuple(getattr(self, name)))

    # --------------------------------------------------------------------- sizes
    @property
    def n_positions(self) -> int:
        return len(self.block_x) * len(self.block_y)

    @property
    def n_per_primitive(self) -> int:
        return self.n_positions * len(self.block_size)

    @property
    def n_samples(self) -> int:
        return len(self.primitives) * self.n_per_primitive

    @property
    def image_size(self) -> tuple[int, int] | None:
        return (self.height, self.width) if self.images else None

    def spacing(self, axis: str) -> float:
        """Grid spacing along ``block_x`` or ``block_y`` (0 for a single value)."""
        values = np.sort(np.asarray(getattr(self, axis), dtype=float))
        return float(np.min(np.diff(values))) if len(values) > 1 else 0.0

    # ---------------------------------------------------------------- validation
    def validate(self) -> "GenerationConfig":
        """Check every field; raise :class:`UserError` naming the field. Returns self."""
        from primspace.sim.render import MAX_IMAGE_SIZE
        from primspace.sim.scene import TABLE

        for name in self.primitives:
            primitive_index(name)
        if not self.primitives:
            raise UserError("primitives: at least one primitive is needed")
        if len(set(self.primitives)) != len(self.primitives):
            raise UserError(f"primitives: repeated names in {list(self.primitives)}")
        for name, (lo, hi) in (("block_x", TABLE.block_x), ("block_y", TABLE.block_y), ("block_size", TABLE.block_size)):
            values = np.asarray(getattr(self, name), dtype=float)
            if values.size == 0:
                raise UserError(f"{name}: at least one value is needed")
            if not np.isfinite(values).all():
                raise UserError(f"{name}: values must be finite numbers")
            if len(np.unique(values)) != len(values):
                raise UserError(f"{name}: repeated values in {values.tolist()}")
            reach = self.jitter * self.spacing(name) if name != "block_size" else 0.0
            bad = values[(values - reach < lo - 1e-9) | (values + reach > hi + 1e-9)]
            if bad.size:
                what = "block size" if name == "block_size" else "block position"
                extra = f" (with jitter +-{reach:.4g})" if reach else ""
                raise UserError(
                    f"{name} = {bad[0]:.4g} m{extra} is outside the table's {what} range [{lo}, {hi}] m"
                )
        if not (0.0 <= self.jitter <= 0.5):
            raise UserError(f"jitter = {self.jitter}: must be in [0, 0.5] (a fraction of the grid spacing)")
        if not (MIN_LENGTH <= self.length <= 100_000):
            raise UserError(f"length (T) = {self.length}: must be at least {MIN_LENGTH} (the phases need it)")
        if not (1 <= self.height <= MAX_IMAGE_SIZE[0] and 1 <= self.width <= MAX_IMAGE_SIZE[1]):
            raise UserError(
                f"image size {self.height}x{self.width}: height must be 1..{MAX_IMAGE_SIZE[0]}, width 1..{MAX_IMAGE_SIZE[1]}"
            )
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise UserError(f"dt = {self.dt}: must be a positive number of seconds")
        if not (self.ik_tolerance > 0):
            raise UserError(f"ik_tolerance = {self.ik_tolerance}: must be positive")
        return self

    # ---------------------------------------------------------------------- json
    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any], base: "GenerationConfig | None" = None) -> "GenerationConfig":
        """A configuration from JSON-like values (over ``base``'s, default: the defaults).

        Raises
        ------
        UserError
            For an unknown setting or a value of the wrong kind, naming the setting.
        """
        if not isinstance(d, dict):
            raise UserError(f"generation settings must be a JSON object, got {type(d).__name__}")
        kinds = {f.name: f.type for f in fields(cls)}
        unknown = sorted(set(d) - set(kinds))
        if unknown:
            raise UserError(f"unknown generation setting(s): {', '.join(unknown)}; known: {', '.join(kinds)}")
        values = {}
        for name, value in d.items():
            kind = kinds[name]
            try:
                if name == "primitives":
                    ok = isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)
                    values[name] = tuple(value) if ok else _bad()
                elif kind.startswith("tuple"):
                    ok = isinstance(value, (list, tuple)) and all(_is_number(v) for v in value)
                    values[name] = tuple(float(v) for v in value) if ok else _bad()
                elif kind == "bool":
                    values[name] = value if isinstance(value, bool) else _bad()
                elif kind == "int":
                    values[name] = int(value) if _is_number(value) and float(value).is_integer() else _bad()
                else:
                    values[name] = float(value) if _is_number(value) else _bad()
            except ValueError:
                raise UserError(f"generation setting {name}: {value!r} is not {_KIND_WORDS[kind]}") from None
        return replace(base if base is not None else cls(), **values)


_KIND_WORDS = {
    "tuple[float, ...]": "a list of numbers", "tuple[str, ...]": "a list of primitive names",
    "int": "an integer", "float": "a number", "bool": "true or false",
}


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _bad():
    raise ValueError


#: Named configurations. ``paper``: 7 x 7 positions x 5 sizes x 7 primitives = 1715
#: motions of T = 61 steps with 48 x 64 frames, as in the paper. ``demo``: 3 x 3
#: positions x 2 sizes x 7 primitives = 126 motions, the same T and frames, for the CPU demo.
PRESETS: dict[str, GenerationConfig] = {
    "paper": GenerationConfig(),
    "demo": GenerationConfig(block_x=_grid(0.44, 0.58, 3), block_y=_grid(-0.12, 0.12, 3), block_size=(0.04, 0.06)),
}


def resolve_config(config_or_preset) -> GenerationConfig:
    """A validated :class:`GenerationConfig` from a config, a preset name or a dict."""
    if isinstance(config_or_preset, GenerationConfig):
        config = config_or_preset
    elif isinstance(config_or_preset, str):
        if config_or_preset not in PRESETS:
            raise UserError(f"unknown preset {config_or_preset!r}; choose from {', '.join(PRESETS)}")
        config = PRESETS[config_or_preset]
    elif isinstance(config_or_preset, dict):
        config = GenerationConfig.from_dict(config_or_preset)
    else:
        raise UserError(f"expected a preset name or a GenerationConfig, got {type(config_or_preset).__name__}")
    return config.validate()


# ------------------------------------------------------------------------ samples


def sample_params(config: GenerationConfig, seed: int, index: int) -> tuple[int, float, float, float]:
    """``(label, block_x, block_y, block_size)`` of sample ``index`` (depends on seed and index only)."""
    n_y, n_s = len(config.block_y), len(config.block_size)
    per = config.n_per_primitive
    p, rest = divmod(int(index), per)
    ix, rest = divmod(rest, n_y * n_s)
    iy, isz = divmod(rest, n_s)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(index)]))
    jx, jy = rng.uniform(-1.0, 1.0, size=2) * config.jitter
    x = config.block_x[ix] + jx * config.spacing("block_x")
    y = config.block_y[iy] + jy * config.spacing("block_y")
    return primitive_index(config.primitives[p]), float(x), float(y), float(config.block_size[isz])


def simulate_sample(scene, camera, config: GenerationConfig, label: int, x: float, y: float, size: float, index: int):
    """Script, solve, replay (and judge) and render one motion.

    Returns
    -------
    motor : ndarray, shape (T, 9), float32
    images : ndarray, shape (T, H, W, 3), uint8, or None
    ik_error : float
        Largest TCP distance from the scripted path (m).

    Raises
    ------
    DataError
        If the inverse kinematics misses the path by more than ``ik_tolerance`` or (with
        ``verify``) the motion fails the success judge; the message names the sample.
    """
    from primspace.sim.ik import solve_path
    from primspace.sim.rollout import replay
    from primspace.sim.success import judge_rollout

    name = PRIMITIVES[label]
    what = f"{name}, block at x={x:.3f} y={y:.3f} m, size {size:.3f} m"
    script = script_motion(scene, name, x, y, size, config.length)
    ik = solve_path(scene, script.tcp, R_DOWN, finger_geometry(scene).home)
    err = ik.max_position_error
    if not err <= config.ik_tolerance:
        raise DataError(
            f"inverse kinematics misses the scripted path by {err * 1e3:.2f} mm at step {ik.worst_step} "
            f"(tolerance {config.ik_tolerance * 1e3:.2f} mm; {what})",
            field="motor", index=index,
        )
    motor = np.column_stack([ik.q, script.fingers, script.fingers])
    rollout = replay(scene, motor, (x, y), size, script.push_axis, script.push_sign)
    if config.verify:
        verdict = judge_rollout(name, rollout)
        if not verdict.success:
            raise DataError(f"the generated motion fails the success judge: {verdict.reason} ({what})", field="motor", index=index)
    images = None
    if camera is not None:
        images = np.empty((config.length, config.height, config.width, 3), dtype=np.uint8)
        for t in range(config.length):
            scene.set_joints(motor[t])
            scene.data.mocap_pos[scene.block_mocap] = rollout.block[t]
            camera.render(out=images[t])
    return motor.astype(np.float32), images, err


_SCENE = None


def _worker_scene():
    """One scene per process (the model is compiled once; the block size changes per sample)."""
    global _SCENE
    if _SCENE is None:
        from primspace.sim.scene import Scene

        _SCENE = Scene()
    return _SCENE


def generate_shard(config: GenerationConfig, seed: int, sample_indices) -> dict[str, np.ndarray]:
    """Generate the samples ``sample_indices`` (the job of :func:`generate_dataset`).

    Returns
    -------
    dict
        ``start`` (first index), ``motor`` (k, T, 9) float32, ``images`` (k, T, H, W, 3)
        uint8 or None, ``labels`` (k,) int32, ``params`` (k, 3) float32, ``ik_error`` (k,).
    """
    from primspace.sim.render import Camera

    indices = [int(i) for i in sample_indices]
    scene = _worker_scene()
    k, t_len = len(indices), config.length
    out = {
        "start": indices[0] if indices else 0,
        "motor": np.empty((k, t_len, 9), dtype=np.float32),
        "images": np.empty((k, t_len, config.height, config.width, 3), dtype=np.uint8) if config.images else None,
        "labels": np.empty(k, dtype=np.int32),
        "params": np.empty((k, 3), dtype=np.float32),
        "ik_error": np.empty(k),
    }
    camera = Camera(scene, config.height, config.width) if config.images else None
    try:
        for j, index in enumerate(indices):
            label, x, y, size = sample_params(config, seed, index)
            motor, images, err = simulate_sample(scene, camera, config, label, x, y, size, index)
            out["motor"][j], out["labels"][j], out["params"][j], out["ik_error"][j] = motor, label, (x, y, size), err
            if images is not None:
                out["images"][j] = images
    finally:
        if camera is not None:
            camera.close()
    return out


def write_shard(config: GenerationConfig, seed: int, start: int, stop: int, path: str | os.PathLike) -> dict:
    """Generate samples ``start .. stop - 1`` into their own data set file (a job of
    :func:`generate_dataset` with ``out``).

    The file is a complete :class:`~primspace.data.MotionDataset`, written atomically
    (:class:`~primspace.data.DatasetWriter`): it exists only once every sample is in it.

    Returns
    -------
    dict
        ``start``, ``stop``, ``path``, ``ik_error`` (k,) and ``reused`` (False).
    """
    from primspace.data import DatasetWriter

    shard = generate_shard(config, seed, range(start, stop))
    with DatasetWriter(path, overwrite=True, **_file_settings(config, seed, stop - start)) as writer:
        writer.write(0, motor=shard["motor"], images=shard["images"], labels=shard["labels"], params=shard["params"])
    return {"start": start, "stop": stop, "path": str(path), "ik_error": shard["ik_error"], "reused": False}


# ------------------------------------------------------------------------- shards

#: The file in a shard directory that says which generation its shards belong to.
MANIFEST_NAME = "manifest.json"


def shard_size(n_samples: int) -> int:
    """Samples per shard, from N alone (about N / 8, within 4..32).

    The layout never depends on the worker count or the backend, so the shard files of
    an interrupted run fit a re-run with any ``workers`` or ``backend``.
    """
    return max(4, min(32, math.ceil(n_samples / 8)))


def shard_ranges(n_samples: int) -> list[tuple[int, int]]:
    """``(start, stop)`` of every shard: consecutive sample indices of :func:`shard_size`."""
    size = shard_size(n_samples)
    return [(a, min(n_samples, a + size)) for a in range(0, n_samples, size)]


def shard_dir(out: str | os.PathLike) -> Path:
    """Where the shards of ``out`` are written: ``.<out name>.shards`` beside it."""
    out = Path(os.path.abspath(out))
    return out.parent / f".{out.name}.shards"


def shard_manifest(config: GenerationConfig, seed: int) -> dict[str, Any]:
    """What identifies a generation's shards: settings, seed, layout and versions (JSON)."""
    from primspace import __version__
    from primspace.data.dataset import SCHEMA_VERSION

    manifest = {
        "format": "primspace generation shards", "primspace_version": __version__,
        "schema_version": SCHEMA_VERSION, "seed": int(seed), "config": config.to_dict(),
        "n_samples": config.n_samples, "shard_size": shard_size(config.n_samples),
    }
    return json.loads(json.dumps(manifest))  # as it reads back from the file


def _prepare_shard_dir(directory: Path, manifest: dict, overwrite: bool) -> None:
    """Make ``directory`` ready for this generation's shards, keeping those it already holds.

    Shards of another generation (another seed, setting, layout or primspace version)
    are never reused: with ``overwrite`` they are removed, else :class:`UserError`.
    """
    from primspace.files import atomic_write_json

    file = directory / MANIFEST_NAME
    try:
        found = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        found = None
    if found == manifest:
        return
    if any(directory.glob("shard-*.h5")):
        if not overwrite:
            raise UserError(
                f"{directory}: holds shards of another generation ({_differences(found, manifest)}); "
                "re-run with their settings to resume, or pass --overwrite to discard them"
            )
        shutil.rmtree(directory)
    directory.mkdir(parents=True, exist_ok=True)
    atomic_write_json(file, manifest)


def _differences(found, manifest: dict) -> str:
    if not isinstance(found, dict):
        return "no readable manifest"
    keys = [k for k in manifest if k != "config" and found.get(k) != manifest[k]]
    old = found.get("config") if isinstance(found.get("config"), dict) else {}
    keys += [k for k in manifest["config"] if old.get(k) != manifest["config"][k]]
    return "different " + ", ".join(keys)


def _shard_path(directory: Path, start: int, stop: int) -> Path:
    return directory / f"shard-{start:06d}-{stop:06d}.h5"


def _generate_file(config: GenerationConfig, seed: int, out: Path, overwrite: bool, on_shard, run_options: dict) -> None:
    """Generate into ``out``: shard files by the jobs, merged by this process as they finish.

    Shards already in the shard directory (same manifest) are merged, not generated. A
    failed job does not stop the others; after the last one the failures are raised as
    one error and the finished shards stay for a re-run. ``out`` is published atomically
    when complete, then the shard directory is removed.
    """
    from primspace.data import DatasetWriter
    from primspace.parallel import run_jobs

    directory = shard_dir(out)
    _prepare_shard_dir(directory, shard_manifest(config, seed), overwrite)
    ranges = shard_ranges(config.n_samples)
    paths = [_shard_path(directory, a, b) for a, b in ranges]
    done = [path.exists() for path in paths]  # by an earlier run of this generation
    todo = [i for i, finished in enumerate(done) if not finished]
    failures = []
    published = False
    try:
        with DatasetWriter(out, overwrite=overwrite, **_file_settings(config, seed, config.n_samples)) as writer:

            def merge(i: int, info: dict) -> None:
                writer.copy_from(ranges[i][0], paths[i])
                if on_shard is not None:
                    on_shard(info)

            for i in (i for i, finished in enumerate(done) if finished):
                merge(i, {"start": ranges[i][0], "stop": ranges[i][1], "path": str(paths[i]), "ik_error": None, "reused": True})
            if todo:
                items = [(config, seed, *ranges[i], paths[i]) for i in todo]
                with contextlib.closing(run_jobs(write_shard, items, **run_options)) as jobs:
                    for outcome in jobs:
                        if outcome.ok:
                            merge(todo[outcome.index], outcome.value)
                        else:
                            failures.append((ranges[todo[outcome.index]], outcome))
            if failures:
                raise _failed_shards(failures, out, directory, len(ranges))
        published = True
    finally:
        if published or not any(directory.glob("shard-*.h5")):
            shutil.rmtree(directory, ignore_errors=True)


def _failed_shards(failures: list, out, directory: Path, n_shards: int) -> Exception:
    """One error for every failed shard: a :class:`DataError` line, or (a bug) a RuntimeError."""
    failures = sorted(failures, key=lambda f: f[0])
    kept = n_shards - len(failures)
    resume = f"the other {kept} are kept in {directory} and a re-run skips them" if kept else "none finished"
    unexpected = [o for _, o in failures if o.error.partition(": ")[0] not in ("DataError", "UserError")]
    if unexpected:
        return RuntimeError(f"a generation job failed ({resume}): {unexpected[0].error}\n{unexpected[0].traceback}")
    reasons = [o.error.partition(": ")[2] for _, o in failures]
    listed = "; ".join(reasons[:3]) + (f"; and {len(reasons) - 3} more" if len(reasons) > 3 else "")
    return DataError(f"{listed} ({len(failures)} of {n_shards} shards failed; {resume})", path=out)


def _source(config: GenerationConfig, seed: int) -> str:
    preset = next((name for name, cfg in PRESETS.items() if cfg == config), None)
    return "primspace.sim " + json.dumps({"preset": preset, "seed": seed, "config": config.to_dict()})


def _file_settings(config: GenerationConfig, seed: int, n_samples: int) -> dict[str, Any]:
    """:class:`~primspace.data.DatasetWriter` settings of a generated file of ``n_samples``."""
    return {
        "n_samples": n_samples, "length": config.length, "joint_names": _joint_names(),
        "image_size": config.image_size, "label_names": list(PRIMITIVES), "param_names": list(PARAM_NAMES),
        "dt": config.dt, "source": _source(config, seed),
    }


def generate_dataset(
    config_or_preset="demo",
    seed: int = 0,
    workers: int | None = 1,
    backend: str = "local",
    address: str | None = None,
    out: str | os.PathLike | None = None,
    overwrite: bool = False,
    progress: bool | None = None,
    on_shard: Callable[[dict], None] | None = None,
):
    """Generate the simulated data set.

    Parameters
    ----------
    config_or_preset : str, GenerationConfig or dict
        A preset name (:data:`PRESETS`: ``paper``, ``demo``) or a configuration.
    seed : int
        Moves the blocks within their grid cells (see the module docstring); the same
        seed gives identical arrays for any ``workers`` or ``backend``.
    workers : int or None
        Local processes (None: every usable core).
    backend : {"local", "ray"}
    address : str, optional
        Ray cluster address.
    out : path-like, optional
        HDF5 file to write. Each job writes its shard as a data set file into
        :func:`shard_dir` (``.<name>.shards`` beside ``out``, which must be shared by
        every node); this process merges them as they finish and publishes ``out``
        atomically when complete, then removes the shard directory. A re-run after a
        failure or a kill skips the shards already written (same settings and seed
        only). Without ``out`` the data set is built in memory.
    overwrite : bool
        Replace an existing ``out``, and discard shards of another generation.
    progress : bool, optional
        Progress bar (default: when stderr is a terminal).
    on_shard : callable, optional
        Called with each finished shard's dict (e.g. to collect IK errors). In memory:
        :func:`generate_shard`'s dict. With ``out``: :func:`write_shard`'s dict (for a
        shard reused from an earlier run, ``reused`` is True and ``ik_error`` None).

    Returns
    -------
    MotionDataset
        Read back from ``out`` (images stay on disk) or built in memory.

    Raises
    ------
    UserError
        Unknown preset or backend, settings out of range, an existing ``out`` without
        ``overwrite``, shards of another generation without ``overwrite``.
    DataError
        A sample whose inverse kinematics misses its path (named with its index and the
        error in mm). With ``out``: raised after every other job has finished, naming
        each failed sample; ``out`` is not written, finished shards are kept. In memory:
        the first failure stops the run.
    """
    from primspace.data import MotionDataset
    from primspace.files import check_output
    from primspace.parallel import BACKENDS, default_workers, run_jobs

    config = resolve_config(config_or_preset)
    seed = int(seed)
    if backend not in BACKENDS:
        raise UserError(f"unknown backend {backend!r}; choose from {', '.join(BACKENDS)}")
    if out is not None:
        check_output(out, overwrite)
    run_options = dict(
        backend=backend, workers=default_workers() if workers is None else max(1, int(workers)), address=address,
        description=f"generating {config.n_samples} motions", progress=progress,
    )
    if out is not None:
        _generate_file(config, seed, Path(out), overwrite, on_shard, run_options)
        return MotionDataset.load(out)
    jobs = run_jobs(generate_shard, [(config, seed, range(a, b)) for a, b in shard_ranges(config.n_samples)], **run_options)
    n, t_len = config.n_samples, config.length
    motor = np.empty((n, t_len, 9), dtype=np.float32)
    images = np.empty((n, t_len, config.height, config.width, 3), dtype=np.uint8) if config.images else None
    labels, params = np.empty(n, dtype=np.int32), np.empty((n, 3), dtype=np.float32)
    for shard in _finished(jobs):
        sl = slice(shard["start"], shard["start"] + len(shard["motor"]))
        motor[sl], labels[sl], params[sl] = shard["motor"], shard["labels"], shard["params"]
        if images is not None:
            images[sl] = shard["images"]
        if on_shard is not None:
            on_shard(shard)
    meta = _file_settings(config, seed, n)
    return MotionDataset(
        motor=motor, images=images, labels=labels, params=params, joint_names=meta["joint_names"],
        label_names=meta["label_names"], param_names=meta["param_names"], dt=config.dt, source=meta["source"],
    )


def _joint_names() -> list[str]:
    from primspace.sim.scene import JOINT_NAMES

    return list(JOINT_NAMES)


def _finished(jobs):
    """Shard dicts as jobs finish (in memory); the first failure becomes an error (closing the jobs)."""
    try:
        for outcome in jobs:
            if outcome.ok:
                yield outcome.value
                continue
            kind, _, message = outcome.error.partition(": ")
            if kind in ("DataError", "UserError"):
                raise DataError(message) if kind == "DataError" else UserError(message)
            raise RuntimeError(f"a generation job failed: {outcome.error}\n{outcome.traceback}")
    finally:
        jobs.close()
