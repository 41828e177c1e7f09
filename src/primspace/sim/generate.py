"""Generate the simulated data set (the paper's "Artificial Data"): samples, shards, HDF5.

Every sample is one primitive performed on one block: ``label`` = primitive index,
``params`` = ``block_x, block_y, block_size`` (m), ``motor`` = the 9 joint values
(7 arm angles in rad, 2 finger positions in m) at T steps, ``images`` = the fixed
camera's frames. What to generate (grid, sizes, primitives, length, frames), the presets,
the sample order and the seeds are :mod:`primspace.sim.config`.

A sample is made in four steps (:func:`simulate_sample`): script the TCP path (the
primitive's :meth:`~primspace.sim.primitives.Primitive.script`, found in the registry by
its label), solve it by inverse kinematics (:mod:`~primspace.sim.ik`; a miss of more than
``ik_tolerance`` is an error naming the sample, never written), replay it to move the
block (:mod:`~primspace.sim.rollout`; with ``verify`` the primitive's success criteria,
:meth:`~primspace.sim.primitives.Primitive.judge`, must accept it), render the frames
(:mod:`~primspace.sim.render`).

**Parallelism.** Samples are split into shards of consecutive indices whose size
depends on N alone (:func:`~primspace.sim.shards.shard_ranges`), run through
:func:`primspace.utils.parallel.run_jobs`. In memory, :func:`generate_shard` is the job and
returns arrays. With ``out``, :func:`write_shard` is the job: it writes its shard as a
complete data set file (atomic) into ``.<out name>.shards/`` beside ``out``, with a
``manifest.json`` naming the generation (settings, seed, layout, versions; the layout is
:mod:`primspace.sim.shards`); this process merges the shards into ``out`` as they
finish, copying the compressed image chunks as they are
(:meth:`~primspace.data.DatasetWriter.copy_from`), publishes it atomically when complete
and removes the shard directory. A failed job stops no other; the failures are reported
together and a re-run with the same settings and seed generates only the missing shards.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

from primspace.data.schema import arrays_of, empty_arrays
from primspace.sim.config import MIN_LENGTH, PARAM_NAMES, PRESETS, GenerationConfig, resolve_config, sample_params
from primspace.sim.primitives import R_DOWN, finger_geometry, get_primitive
from primspace.sim.shards import (
    MANIFEST_NAME,
    failed_shards_error,
    file_settings,
    prepare_shard_dir,
    shard_dir,
    shard_manifest,
    shard_path,
    shard_ranges,
    shard_size,
)
from primspace.utils.errors import DataError, UserError
from primspace.utils.seeds import check_seed

# The settings (primspace.sim.config) and the shard layout (primspace.sim.shards) are
# re-exported: the CLI, the experiments, tests and benchmarks import them from here.
__all__ = [
    "GenerationConfig",
    "PRESETS",
    "PARAM_NAMES",
    "MIN_LENGTH",
    "MANIFEST_NAME",
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
    "worker_scene",
    "finished_shards",
]

#: The name benchmarks/bench_merge.py imports (the settings of a generated file).
_file_settings = file_settings


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

    primitive = get_primitive(label)
    what = f"{primitive.name}, block at x={x:.3f} y={y:.3f} m, size {size:.3f} m"
    script = primitive.script(scene, x, y, size, config.length)
    ik = solve_path(scene, script.tcp, R_DOWN, finger_geometry(scene).home)
    err = ik.max_position_error
    if not err <= config.ik_tolerance:
        raise DataError(
            f"inverse kinematics misses the scripted path by {err * 1e3:.2f} mm at step {ik.worst_step} "
            f"(tolerance {config.ik_tolerance * 1e3:.2f} mm; {what})",
            field="motor",
            index=index,
        )
    motor = np.column_stack([ik.q, script.fingers, script.fingers])
    rollout = replay(scene, motor, (x, y), size, primitive.push_axis, primitive.push_sign)
    if config.verify:
        verdict = primitive.judge(rollout)
        if not verdict.success:
            raise DataError(
                f"the generated motion fails the success judge: {verdict.reason} ({what})", field="motor", index=index
            )
    images = None
    if camera is not None:
        images = np.empty((config.length, config.height, config.width, 3), dtype=np.uint8)
        for t in range(config.length):
            scene.set_joints(motor[t])
            scene.data.mocap_pos[scene.block_mocap] = rollout.block[t]
            camera.render(out=images[t])
    return motor.astype(np.float32), images, err


_SCENES: dict = {}


def worker_scene(distractor: bool = False):
    """One scene per process (the model is compiled once; the block size changes per sample),
    and one with the distractor body for the scenes that vary (:mod:`primspace.sim.variation`)."""
    if distractor not in _SCENES:
        from primspace.sim.scene import Scene

        _SCENES[distractor] = Scene(distractor=distractor)
    return _SCENES[distractor]


def generate_shard(config: GenerationConfig, seed: int, sample_indices) -> dict[str, np.ndarray]:
    """Generate the samples ``sample_indices`` (the job of :func:`generate_dataset`).

    Returns
    -------
    dict
        ``start`` (first index), ``motor`` (k, T, 9) float32, ``images`` (k, T, H, W, 3)
        uint8 or None, ``labels`` (k,) int32, ``params`` (k, 3) float32, ``ik_error`` (k,);
        in scenes that vary, ``scene`` (k, S) float32 (:func:`~primspace.sim.variation.draw_scene`,
        set in the scene before the sample is made).
    """
    from primspace.sim.render import Camera
    from primspace.sim.variation import apply_scene, draw_scene, resolve_variation

    indices = [int(i) for i in sample_indices]
    variation = resolve_variation(config.scene_variation)
    scene = worker_scene(variation.enabled)
    k = len(indices)
    out = {"start": indices[0] if indices else 0, **_buffers(config, k), "ik_error": np.empty(k)}
    camera = Camera(scene, config.height, config.width) if config.images else None
    try:
        for j, index in enumerate(indices):
            label, x, y, size = sample_params(config, seed, index)
            if variation.enabled:  # float32 as recorded: a recorded row re-renders its scene
                out["scene"][j] = draw_scene(variation, seed, index).astype(np.float32)
                apply_scene(scene, out["scene"][j])
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
    with DatasetWriter(path, overwrite=True, **file_settings(config, seed, stop - start)) as writer:
        writer.write(0, **arrays_of(shard))
    return {"start": start, "stop": stop, "path": str(path), "ik_error": shard["ik_error"], "reused": False}


# ------------------------------------------------------------------------- files


def _generate_file(
    config: GenerationConfig, seed: int, out: Path, overwrite: bool, on_shard, run_options: dict
) -> None:
    """Generate into ``out``: shard files by the jobs, merged by this process as they finish.

    Shards already in the shard directory (same manifest) are merged, not generated. A
    failed job does not stop the others; after the last one the failures are raised as
    one error and the finished shards stay for a re-run. ``out`` is published atomically
    when complete, then the shard directory is removed.
    """
    from primspace.data import DatasetWriter
    from primspace.utils.parallel import run_jobs

    directory = shard_dir(out)
    prepare_shard_dir(directory, shard_manifest(config, seed), overwrite)
    ranges = shard_ranges(config.n_samples)
    paths = [shard_path(directory, a, b) for a, b in ranges]
    done = [path.exists() for path in paths]  # by an earlier run of this generation
    todo = [i for i, finished in enumerate(done) if not finished]
    failures = []
    published = False
    try:
        with DatasetWriter(
            out, overwrite=overwrite, writer="primspace generate", **file_settings(config, seed, config.n_samples)
        ) as writer:

            def merge(i: int, info: dict) -> None:
                writer.copy_from(ranges[i][0], paths[i])
                if on_shard is not None:
                    on_shard(info)

            for i in (i for i, finished in enumerate(done) if finished):
                merge(
                    i,
                    {
                        "start": ranges[i][0],
                        "stop": ranges[i][1],
                        "path": str(paths[i]),
                        "ik_error": None,
                        "reused": True,
                    },
                )
            if todo:
                items = [(config, seed, *ranges[i], paths[i]) for i in todo]
                with contextlib.closing(run_jobs(write_shard, items, **run_options)) as jobs:
                    for outcome in jobs:
                        if outcome.ok:
                            merge(todo[outcome.index], outcome.value)
                        else:
                            failures.append((ranges[todo[outcome.index]], outcome))
            if failures:
                raise failed_shards_error(failures, out, directory, len(ranges))
        published = True
    finally:
        if published or not any(directory.glob("shard-*.h5")):
            shutil.rmtree(directory, ignore_errors=True)


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
        HDF5 file to write, through shard files in :func:`shard_dir` (which every node
        must share) merged as they finish and published atomically when complete; a
        re-run with the same settings and seed skips the shards already written (see
        the module docstring). Without ``out`` the data set is built in memory.
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

    Notes
    -----
    Over 60 lines only by this docstring, the reference of the generation API; the body
    is 20 lines.
    """
    from primspace.data import MotionDataset
    from primspace.utils.files import check_output
    from primspace.utils.parallel import BACKENDS, default_workers

    config = resolve_config(config_or_preset)
    seed = check_seed(seed)
    if backend not in BACKENDS:
        raise UserError(f"unknown backend {backend!r}; choose from {', '.join(BACKENDS)}")
    if out is not None:
        check_output(out, overwrite)
    run_options = dict(
        backend=backend,
        workers=default_workers() if workers is None else max(1, int(workers)),
        address=address,
        description=f"generating {config.n_samples} motions",
        progress=progress,
    )
    if out is not None:
        _generate_file(config, seed, Path(out), overwrite, on_shard, run_options)
        return MotionDataset.load(out)
    return _generate_in_memory(config, seed, on_shard, run_options)


def _generate_in_memory(config: GenerationConfig, seed: int, on_shard, run_options: dict):
    """The :class:`~primspace.data.MotionDataset` built in memory from the jobs' arrays (the
    first failure stops the run)."""
    from primspace.data import MotionDataset
    from primspace.utils.parallel import run_jobs

    jobs = run_jobs(
        generate_shard, [(config, seed, range(a, b)) for a, b in shard_ranges(config.n_samples)], **run_options
    )
    n = config.n_samples
    arrays = _buffers(config, n)
    for shard in finished_shards(jobs):
        sl = slice(shard["start"], shard["start"] + len(shard["motor"]))
        for name, values in arrays_of(shard).items():
            if values is not None:
                arrays[name][sl] = values
        if on_shard is not None:
            on_shard(shard)
    meta = file_settings(config, seed, n)
    return MotionDataset(
        **arrays,
        joint_names=meta["joint_names"],
        label_names=meta["label_names"],
        param_names=meta["param_names"],
        scene_names=meta.get("scene_names"),
        dt=config.dt,
        source=meta["source"],
    )


def _buffers(config: GenerationConfig, n: int) -> dict:
    """Empty arrays of the data set's fields (:mod:`primspace.data.schema`) for ``n`` motions
    of 9 joints and 3 generative factors (``images`` None without frames; ``scene`` in scenes
    that vary)."""
    from primspace.sim.variation import SCENE_NAMES

    dims = {"N": n, "T": config.length, "J": 9, "P": 3, "S": len(SCENE_NAMES)}
    names = ["motor", "labels", "params"] + (["scene"] if config.scene_variation != "none" else [])
    if config.images:
        dims |= {"H": config.height, "W": config.width}
        names.append("images")
    return {"images": None, **empty_arrays(dims, names)}


def finished_shards(jobs):
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
