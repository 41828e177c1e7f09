"""A run on disk: the one module that names a run's files (the checkpoint's keys are
:mod:`primspace.train.checkpoint`'s).

A run directory holds::

    config.json       kind (fit / infer), init, model and train configs, data (path,
                      sample indices, SHA-1 of the samples' joints, and the samples'
                      source ids when the data set has them), parent run, scaler,
                      the observation rule of an inference from a prefix (``observe``)
    metrics.jsonl     one line per epoch
    checkpoint.pt     model, optimiser, codes and their optimiser, scaler, initialiser,
                      RNG states, epoch (written atomically)
    latents.npy       the codes at the last checkpoint
    latents_init.npy  the codes as initialised
    calibration.json  the diagnostics of the calibration map (runs that have one; the map
                      itself is in the checkpoint)

Anything else in the directory is not the run's: an overwrite removes only the files
above, and only when the new run starts writing (:meth:`RunDirectory.begin`).

The training loop (:mod:`primspace.train.loop`) hands its state to
:func:`~primspace.train.checkpoint.checkpoint_state` and its files to a
:class:`RunDirectory`; everything that reads a checkpoint goes through
:func:`~primspace.train.checkpoint.unpack_checkpoint` (resume) or :func:`run_from_state`
(:func:`load_run`, and a run trained in memory).
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

import numpy as np
import torch

from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.train.checkpoint import read_checkpoint, unpack_checkpoint
from primspace.train.config import TrainConfig
from primspace.train.run import TrainedRun
from primspace.train.rundata import check_run_data, fingerprint
from primspace.utils.errors import OutputExistsError, UserError
from primspace.utils.files import (
    atomic_path,
    atomic_write_json,
    atomic_write_text,
    check_outside_inputs,
    check_writable_directory,
    os_error,
)
from primspace.utils.folders import lock_exclusively

__all__ = [
    "CONFIG_NAME",
    "METRICS_NAME",
    "CHECKPOINT_NAME",
    "LATENTS_NAME",
    "LATENTS_INIT_NAME",
    "CALIBRATION_NAME",
    "RUN_FILES",
    "RESUMABLE_CHANGES",
    "RunDirectory",
    "WriterLock",
    "LOCK_NAME",
    "check_same_run",
    "run_config",
    "prepare_run_dir",
    "open_run_dir",
    "run_from_state",
    "load_run",
    "write_run",
    "read_config",
    "read_metrics",
    "fingerprint",
    "check_run_data",
]

CONFIG_NAME, METRICS_NAME, CHECKPOINT_NAME = "config.json", "metrics.jsonl", "checkpoint.pt"
LATENTS_NAME, LATENTS_INIT_NAME = "latents.npy", "latents_init.npy"
CALIBRATION_NAME = "calibration.json"
RUN_FILES = (CONFIG_NAME, METRICS_NAME, CHECKPOINT_NAME, LATENTS_NAME, LATENTS_INIT_NAME, CALIBRATION_NAME)

# Train-config fields that may change when a run is resumed: they do not change the numbers
# (micro_batches, like the number of processes, changes only the rounding: docs/scale.md).
RESUMABLE_CHANGES = {
    "epochs",
    "checkpoint_every",
    "checkpoint_seconds",
    "threads",
    "tune_malloc",
    "stream_frames",
    "frames_memory_gb",
    "loader_workers",
    "micro_batches",
    "step",
}


def run_config(kind, init, mc, tc, data, use_images, parent) -> dict:
    """config.json of a run on ``data``, the selected samples: they are recorded by their
    numbers in the data file (:attr:`~primspace.data.MotionDataset.file_indices`), so a run
    fitted on ``data.subset(...)`` finds its samples in the file again."""
    from primspace import __version__

    return {
        "kind": kind,
        "init": init,
        "model": mc.to_dict(),
        "train": tc.to_dict(),
        "data": {
            "path": None if data.path is None else str(Path(data.path).resolve()),
            "n_samples": len(data),
            "indices": data.file_indices.tolist(),
            "images": bool(use_images),
            "joint_names": list(data.joint_names),
            "dt": data.dt,
            "motor_sha1": fingerprint(data),
            **(
                {} if data.source_ids is None else {"source_ids": [str(v) for v in data.source_ids]}
            ),  # data: the selected samples
        },
        "parent": parent,
        "primspace_version": __version__,
    }


def prepare_run_dir(
    out_dir: Path, config: dict, resume: bool, overwrite: bool, inputs: tuple = (), epochs: int | None = None
) -> dict | None:
    """Check the run directory; return the checkpoint to resume from (or None).

    Writes nothing: an ``overwrite`` only takes effect when the new run starts writing
    (:func:`start_run_dir`), so a run that fails while loading its data loses nothing.
    Errors name the Python parameters (``resume=True``); the command line says its flags
    instead (:func:`primspace.cli.app.main`). Refused: ``resume`` with ``overwrite``; an ``out_dir`` that is, contains or lies inside
    one of ``inputs``; a non-empty directory that is not a run of the same kind
    (``fit`` / ``infer``); a resume past ``epochs``.
    """
    if resume and overwrite:
        raise UserError(f"{out_dir}: resume=True continues the run and overwrite=True replaces it; give one of them")
    check_outside_inputs(out_dir, inputs)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"{out_dir}: exists and is not a directory")
    if out_dir.is_dir():
        check_writable_directory(out_dir)  # used in place (never replaced): refused now, not after loading
    existing = out_dir.is_dir() and any(p.name != LOCK_NAME for p in out_dir.iterdir())
    is_run = (out_dir / CONFIG_NAME).is_file() or (out_dir / CHECKPOINT_NAME).is_file()
    if existing and not is_run:
        raise UserError(f"{out_dir}: exists and is not a primspace run directory; choose another out_dir")
    if is_run and (out_dir / CONFIG_NAME).is_file():
        kind = read_config(out_dir).get("kind")
        if kind != config["kind"]:
            verb = "train" if config["kind"] == "fit" else "infer"
            raise UserError(
                f"{out_dir}: is a{'n' if kind == 'infer' else ''} {kind} run; {verb} only resumes or replaces "
                f"its own ({config['kind']}) runs: choose another out_dir"
            )
    if resume and (out_dir / CHECKPOINT_NAME).is_file():
        ckpt = read_checkpoint(out_dir / CHECKPOINT_NAME, "cpu")
        _check_compatible(out_dir, ckpt["config"], config)
        done = int(ckpt["epoch"])
        if epochs is not None and done > epochs:
            raise UserError(
                f"{out_dir}: has trained {done} epochs, more than the {epochs} asked for; resume with "
                f"epochs={done} or more (more extends the run)"
            )
        return ckpt
    if existing and not resume and not overwrite:
        raise OutputExistsError(out_dir, hint="resume=True or overwrite=True")
    return None


#: The file a run's writer holds locked (``flock``) from the check of the directory to the run's
#: end: a second writer (``--overwrite`` or ``--resume`` while one runs) is refused at once. The
#: kernel releases the lock when the process ends, however it ends: a kill leaves none behind.
LOCK_NAME = ".writer.lock"


class WriterLock:
    """The exclusive lock of the one process writing ``run_dir`` (:data:`LOCK_NAME`)."""

    def __init__(self, run_dir: Path) -> None:
        self.run_dir, self.handle = Path(run_dir), None

    def acquire(self) -> WriterLock:
        """Take the lock (a no-op when held, or while the folder does not exist yet); one
        UserError when another process holds it."""

        if self.handle is not None or not self.run_dir.is_dir():
            return self
        try:
            handle = open(self.run_dir / LOCK_NAME, "a+", encoding="utf-8")
        except OSError as exc:
            raise os_error(exc, self.run_dir) from None
        lock_exclusively(handle, self.run_dir, "run", "wait for it to end or choose another out_dir")
        handle.seek(0)
        handle.truncate()
        handle.write(str(os.getpid()))
        handle.flush()
        self.handle = handle
        return self

    def __getstate__(self) -> dict:  # handed to other processes (distributed training): they hold nothing
        return {"run_dir": self.run_dir, "handle": None}

    def release(self) -> None:
        """Let go of the lock (closing the file releases it)."""
        if self.handle is not None:
            self.handle.close()
            self.handle = None


def open_run_dir(out_dir: Path, config: dict, resume: bool, overwrite: bool, inputs: tuple = (), epochs=None):
    """The :class:`RunDirectory` to write, holding the writer's lock until the run ends
    (:meth:`RunDirectory.close`), and the checkpoint to resume from (:func:`prepare_run_dir`)."""
    lock = WriterLock(out_dir).acquire()
    try:
        ckpt = prepare_run_dir(out_dir, config, resume, overwrite, inputs=inputs, epochs=epochs)
    except BaseException:
        lock.release()
        raise
    store = RunDirectory(out_dir, lock)
    store.resume_asked = resume
    return store, ckpt


def start_run_dir(out_dir: Path, remove: bool = True) -> None:
    """Make ``out_dir`` ready for a new run: with ``remove``, remove an earlier run's files
    (only those a run writes: anything else in the directory stays); create it (an
    existing folder is used in place)."""
    try:
        if remove and out_dir.is_dir():
            for name in RUN_FILES:
                with contextlib.suppress(FileNotFoundError):
                    (out_dir / name).unlink()
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise os_error(exc, out_dir) from None


def _check_compatible(out_dir: Path, saved: dict, given: dict) -> None:
    found = first_difference(saved, given)
    if found is not None:
        what, a, b = found
        raise UserError(f"{out_dir}: cannot resume: {what} differs (saved {a}, given {b})")


def first_difference(saved: dict, given: dict) -> tuple | None:
    """``(what, saved value, given value)`` of the first setting in which two run configs differ
    beyond what a resume may change (:data:`RESUMABLE_CHANGES`); None when they are one run's."""
    # a run saved before a field existed has that field's default (which gives its numbers)
    saved = saved | {
        "model": ModelConfig.from_dict(saved["model"]).to_dict(),
        "train": TrainConfig.from_dict(saved["train"]).to_dict(),
    }
    for key in ("kind", "init", "parent", "scaler", "observe"):  # observe: the rule of an inference from a prefix
        if saved.get(key) != given.get(key):
            return key, saved.get(key), given.get(key)
    for key, value in given["model"].items():
        if saved["model"].get(key) != value:
            return f"model {key}", saved["model"].get(key), value
    for key, value in given["train"].items():
        if key not in RESUMABLE_CHANGES and saved["train"].get(key) != value:
            return f"train {key}", saved["train"].get(key), value
    sd, gd = saved["data"], given["data"]
    for key in ("n_samples", "images", "motor_sha1"):
        if sd.get(key) != gd.get(key):
            return ("data" if key == "motor_sha1" else f"data {key}"), sd.get(key), gd.get(key)
    if sd.get("indices") != gd.get("indices"):
        return "data indices", f"{len(sd.get('indices', []))} samples", f"{len(gd['indices'])} samples"
    return None


def read_config(run_dir: Path) -> dict:
    path = run_dir / CONFIG_NAME
    if not path.is_file():
        raise UserError(f"{run_dir}: not a primspace run directory (no {CONFIG_NAME})")
    try:
        config = json.loads(path.read_text(encoding="utf-8"))
        for key in ("kind", "init", "model", "train", "data"):
            config[key]
    except (ValueError, KeyError, TypeError) as exc:
        raise UserError(f"{path}: not a primspace run config ({exc})") from None
    return config


def read_metrics(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.strip():
            try:
                out.append(json.loads(line))
            except ValueError:
                break  # a line cut short by a kill: ignore it and what follows
    return out


def save_npy(path: Path, array: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.save(f, array)


def run_from_state(state: dict, history: list[dict], run_dir: Path | None) -> TrainedRun:
    """A :class:`TrainedRun` (its own model, on the CPU, in eval mode) from a checkpoint dict."""
    where = run_dir / CHECKPOINT_NAME if run_dir is not None else "checkpoint"
    ckpt = unpack_checkpoint(state, where)
    config = ckpt.config
    try:
        mc = ModelConfig.from_dict(config["model"]).validate()
        tc = TrainConfig.from_dict(config["train"])
        model = MTRNNDecoder(mc)
        model.load_state_dict(ckpt.model)
        model.eval()
        latents = ckpt.latents["codes"].detach().cpu().numpy().astype(np.float32)
        initial = ckpt.initial_codes.cpu().numpy().astype(np.float32)
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise UserError(f"{where}: not a primspace checkpoint ({str(exc).splitlines()[0]})") from None
    data = config.get("data", {})
    return TrainedRun(
        run_dir=run_dir,
        kind=config["kind"],
        init=config["init"],
        model=model,
        model_config=mc,
        train_config=tc,
        scaler=ckpt.scaler,
        initializer=ckpt.initializer,
        latents=latents,
        initial_latents=initial,
        history=[h for h in history if h["epoch"] <= ckpt.epoch],
        indices=np.asarray(data.get("indices", []), dtype=np.int64),
        data_path=data.get("path"),
        parent=config.get("parent"),
        epoch=ckpt.epoch,
        config=config,
        state=state,
        calibration=ckpt.calibration,
    )


def load_run(run_dir: str | Path, *, map_location: str | torch.device = "cpu") -> TrainedRun:
    """Read a run directory written by ``fit`` or ``infer`` (or :func:`write_run`).

    Raises
    ------
    UserError
        If the directory is not a run or its files are unreadable.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UserError(f"{run_dir}: no such run directory")
    config = read_config(run_dir)
    state = read_checkpoint(run_dir / CHECKPOINT_NAME, map_location)
    if state is None:
        raise UserError(f"{run_dir}: has no {CHECKPOINT_NAME} (the run never completed an epoch)")
    check_same_run(run_dir, config, state)
    return run_from_state(state, read_metrics(run_dir / METRICS_NAME), run_dir)


def check_same_run(run_dir: Path, config: dict, state: dict) -> None:
    """One UserError when the checkpoint belongs to another run than ``config.json`` (two
    writers mixed the folder): the checkpoint names the config it was written with."""
    saved = state.get("config")
    found = None if saved is None else first_difference(saved, config)
    if found is not None:
        raise UserError(
            f"{run_dir}: its {CHECKPOINT_NAME} belongs to another run than its {CONFIG_NAME} ({found[0]} differs: "
            "two runs wrote this folder); train it again in another out_dir"
        )


def write_run(out_dir: str | Path, run: TrainedRun, *, overwrite: bool = False, inputs: tuple = ()) -> Path:
    """Save a run (e.g. one trained in memory) as a run directory that :func:`load_run`
    reads and ``fit`` / ``infer`` can resume. Refuses what :func:`prepare_run_dir` refuses."""
    out_dir = Path(out_dir)
    if run.state is None:
        raise UserError("this run holds no checkpoint state to save")
    lock = WriterLock(out_dir).acquire()
    try:
        prepare_run_dir(out_dir, run.config, resume=False, overwrite=overwrite, inputs=inputs)
        store = RunDirectory(out_dir, lock)
        store.begin(run.config, run.initial_latents)
        for line in run.history:
            store.log(line)
        store.save(run.state, run.latents)
    finally:
        lock.release()
    return out_dir


# ------------------------------------------------------------------------ the files


def _run_identity(out_dir: Path) -> tuple:
    """Which run ``out_dir`` holds now: the inode and modification time of its config and checkpoint."""
    found = []
    for name in (CONFIG_NAME, CHECKPOINT_NAME):
        try:
            st = (out_dir / name).stat()
            found.append((st.st_ino, st.st_mtime_ns))
        except OSError:
            found.append(None)
    return tuple(found)


class RunDirectory:
    """The files of one run as training writes them (config, metrics, checkpoint, codes).

    Made right after :func:`prepare_run_dir` approved ``path``, it remembers which run
    was there (none, or the earlier run an overwrite replaces): :meth:`begin` refuses to
    start if another run appeared or changed meanwhile, and never removes files of a run
    it was not asked to replace.
    """

    def __init__(self, path: str | Path, lock: WriterLock | None = None) -> None:
        self.path = Path(path)
        self.lock = WriterLock(self.path) if lock is None else lock
        self._found = _run_identity(self.path)
        self.resume_asked = False  # the run was asked to resume (whether or not it found a checkpoint)
        self.dropped = 0  # metrics lines past the checkpoint resumed from, dropped (:meth:`history_through`)

    def close(self) -> None:
        """The run is over: release the writer's lock."""
        self.lock.release()

    def begin(self, config: dict, initial_codes: np.ndarray) -> None:
        """Start a new run: remove the earlier run's files (only those of the run that was
        there when this object was made), write the config (never over one that appeared
        meanwhile) and the initial codes."""
        if _run_identity(self.path) != self._found:
            raise UserError(f"{self.path}: another run started writing here meanwhile; choose another out_dir")
        start_run_dir(self.path, remove=self._found != (None, None))
        self.lock.acquire()  # a folder made just now: locked before the first file is written
        try:
            atomic_write_json(self.path / CONFIG_NAME, config, overwrite=False)
        except OutputExistsError:
            raise UserError(
                f"{self.path}: another run started writing here meanwhile; choose another out_dir"
            ) from None
        save_npy(self.path / LATENTS_INIT_NAME, np.asarray(initial_codes))
        atomic_write_text(self.path / METRICS_NAME, "")

    def log(self, line: dict) -> None:
        """Append one epoch's metrics."""
        with open(self.path / METRICS_NAME, "a", encoding="utf-8") as f:
            f.write(json.dumps(line) + "\n")

    def save(self, state: dict, codes: np.ndarray) -> None:
        """Write the checkpoint (atomically) and the codes it holds."""
        with atomic_path(self.path / CHECKPOINT_NAME) as tmp:
            torch.save(state, tmp)
        save_npy(self.path / LATENTS_NAME, codes)
        calibration = state.get("calibration")
        if calibration is not None and state.get("kind") == "fit":  # an inferred run only carries its parent's
            diagnostics = {k: v for k, v in calibration.items() if not isinstance(v, torch.Tensor)}
            atomic_write_json(self.path / CALIBRATION_NAME, diagnostics)

    def history_through(self, epoch: int) -> list[dict]:
        """The metrics up to ``epoch``; lines past it (written before a kill) are dropped from the file."""
        lines = read_metrics(self.path / METRICS_NAME)
        kept = [h for h in lines if h["epoch"] <= epoch]
        self.dropped = len(lines) - len(kept)
        atomic_write_text(self.path / METRICS_NAME, "".join(json.dumps(h) + "\n" for h in kept))
        return kept
