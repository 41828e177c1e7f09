"""The run directory: its file names, the checkpoint format version, and the checks and
readers of a run's files (config, checkpoint, metrics). train.py builds the runs: the
checkpoint's contents are still assembled by its session and unpacked by ``load_run``
(moving those here is part of the package reshape, issue 12).

A run directory holds::

    config.json       kind (fit / infer), init, model and train configs, data (path,
                      sample indices, SHA-1 of the samples' joints), parent run, scaler
    metrics.jsonl     one line per epoch
    checkpoint.pt     model, optimiser, codes and their optimiser, scaler, initialiser,
                      RNG states, epoch (written atomically)
    latents.npy       the codes at the last checkpoint
    latents_init.npy  the codes as initialised

Anything else in the directory is not the run's: ``--overwrite`` removes only the files
above, and only when the new run starts writing (:func:`start_run_dir`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from primspace.data import MotionDataset
from primspace.errors import OutputExistsError, UserError
from primspace.files import atomic_path, check_outside_inputs, os_error

if TYPE_CHECKING:  # the run type lives with fit/infer; only its attributes are read here
    from primspace.train import TrainedRun

__all__ = [
    "CHECKPOINT_FORMAT", "CONFIG_NAME", "METRICS_NAME", "CHECKPOINT_NAME", "LATENTS_NAME", "LATENTS_INIT_NAME",
    "RUN_FILES", "RESUMABLE_CHANGES", "run_config", "prepare_run_dir", "start_run_dir", "read_config",
    "read_checkpoint", "read_metrics", "save_npy", "fingerprint", "check_run_data",
]

CHECKPOINT_FORMAT = 1
CONFIG_NAME, METRICS_NAME, CHECKPOINT_NAME = "config.json", "metrics.jsonl", "checkpoint.pt"
LATENTS_NAME, LATENTS_INIT_NAME = "latents.npy", "latents_init.npy"
RUN_FILES = (CONFIG_NAME, METRICS_NAME, CHECKPOINT_NAME, LATENTS_NAME, LATENTS_INIT_NAME)

# Train-config fields that may change when a run is resumed (they do not change the numbers).
RESUMABLE_CHANGES = {"epochs", "checkpoint_every", "checkpoint_seconds", "threads", "tune_malloc"}


def fingerprint(data: MotionDataset) -> str:
    return hashlib.sha1(np.ascontiguousarray(data.motor, dtype=np.float32).tobytes()).hexdigest()


def run_config(kind, init, mc, tc, data, idx, use_images, parent) -> dict:
    from primspace import __version__

    return {
        "kind": kind,
        "init": init,
        "model": mc.to_dict(),
        "train": tc.to_dict(),
        "data": {
            "path": None if data.path is None else str(Path(data.path).resolve()),
            "n_samples": len(data),
            "indices": idx.tolist(),
            "images": bool(use_images),
            "joint_names": list(data.joint_names),
            "dt": data.dt,
            "motor_sha1": fingerprint(data),
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
    Refused: ``resume`` with ``overwrite``; an ``out_dir`` that is, contains or lies inside
    one of ``inputs``; a non-empty directory that is not a run of the same kind
    (``fit`` / ``infer``); a resume past ``epochs``.
    """
    if resume and overwrite:
        raise UserError(f"{out_dir}: --resume continues the run and --overwrite replaces it; give one of them")
    check_outside_inputs(out_dir, inputs)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"{out_dir}: exists and is not a directory")
    existing = out_dir.is_dir() and any(out_dir.iterdir())
    is_run = (out_dir / CONFIG_NAME).is_file() or (out_dir / CHECKPOINT_NAME).is_file()
    if existing and not is_run:
        raise UserError(f"{out_dir}: exists and is not a primspace run directory; choose another --out")
    if is_run and (out_dir / CONFIG_NAME).is_file():
        kind = read_config(out_dir).get("kind")
        if kind != config["kind"]:
            verb = "train" if config["kind"] == "fit" else "infer"
            raise UserError(
                f"{out_dir}: is a{'n' if kind == 'infer' else ''} {kind} run; {verb} only resumes or replaces "
                f"its own ({config['kind']}) runs: choose another --out"
            )
    if resume and (out_dir / CHECKPOINT_NAME).is_file():
        ckpt = read_checkpoint(out_dir / CHECKPOINT_NAME, "cpu")
        _check_compatible(out_dir, ckpt["config"], config)
        done = int(ckpt["epoch"])
        if epochs is not None and done > epochs:
            raise UserError(
                f"{out_dir}: has trained {done} epochs, more than the {epochs} asked for; resume with "
                f"--epochs {done} or more (more extends the run)"
            )
        return ckpt
    if existing and not resume and not overwrite:
        raise OutputExistsError(out_dir, hint="--resume or --overwrite")
    return None


def start_run_dir(out_dir: Path) -> None:
    """Make ``out_dir`` ready for a new run: remove an earlier run's files (only those a
    run writes: anything else in the directory stays) and create it."""
    try:
        if out_dir.is_dir():
            for name in RUN_FILES:
                with contextlib.suppress(FileNotFoundError):
                    (out_dir / name).unlink()
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise os_error(exc, out_dir) from None


def _check_compatible(out_dir: Path, saved: dict, given: dict) -> None:
    def fail(what: str, a, b) -> None:
        raise UserError(f"{out_dir}: cannot resume: {what} differs (saved {a}, given {b})")

    for key in ("kind", "init", "parent", "scaler"):
        if saved.get(key) != given.get(key):
            fail(key, saved.get(key), given.get(key))
    for key, value in given["model"].items():
        if saved["model"].get(key) != value:
            fail(f"model {key}", saved["model"].get(key), value)
    for key, value in given["train"].items():
        if key not in RESUMABLE_CHANGES and saved["train"].get(key) != value:
            fail(f"train {key}", saved["train"].get(key), value)
    sd, gd = saved["data"], given["data"]
    for key in ("n_samples", "images", "motor_sha1"):
        if sd.get(key) != gd.get(key):
            fail("data" if key == "motor_sha1" else f"data {key}", sd.get(key), gd.get(key))
    if sd.get("indices") != gd.get("indices"):
        fail("data indices", f"{len(sd.get('indices', []))} samples", f"{len(gd['indices'])} samples")


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


def read_checkpoint(path: Path, map_location) -> dict | None:
    if not path.is_file():
        return None
    try:
        ckpt = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # torch raises many kinds for a damaged file
        raise UserError(f"{path}: cannot read the checkpoint ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
        raise UserError(f"{path}: not a primspace checkpoint (format {ckpt.get('format') if isinstance(ckpt, dict) else '?'})")
    return ckpt


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


def check_run_data(run: TrainedRun, dataset: MotionDataset) -> None:
    """Refuse a data set that is not the one ``run`` was trained or inferred on.

    Compares what a resume compares: joints and steps, the run's sample indices, and the
    SHA-1 of those samples' joint values (``config.json`` ``data.motor_sha1``).
    """
    where = str(dataset.path) if dataset.path is not None else "the data set"
    mc = run.model_config
    if dataset.n_joints != mc.n_joints or dataset.length != mc.length:
        raise UserError(
            f"{where}: has T={dataset.length} steps x J={dataset.n_joints} joints; run {run.run_dir} "
            f"was trained on T={mc.length} x J={mc.n_joints}: not its data"
        )
    if len(run.indices) and int(run.indices.max()) >= len(dataset):
        raise UserError(f"{where}: has {len(dataset)} samples, run {run.run_dir} used sample {int(run.indices.max())}: not its data")
    saved = run.config.get("data", {}).get("motor_sha1")
    if saved is not None and fingerprint(dataset.subset(run.indices)) != saved:
        raise UserError(f"{where}: its joint values differ from those run {run.run_dir} used (SHA-1 of the run's samples): not its data")
