"""The checkpoint format: the one module that packs a run's state into a checkpoint's keys
(:func:`checkpoint_state`), checks a checkpoint file (:func:`read_checkpoint`) and unpacks
its parts (:func:`unpack_checkpoint`, :func:`restore_rng`).

A checkpoint (``checkpoint.pt`` of a run directory, or the ``state`` of a run trained in
memory) holds the model, the optimiser of θ, the codes and their optimiser, the scaler,
the initialiser, the calibration map, the RNG states, the epoch and the run's config, so
that a resumed run continues bit-identically. The run directory that holds it is
:mod:`primspace.train.rundir`'s; the training loop (:mod:`primspace.train.loop`) packs its
state here and restores it from here.
"""

from __future__ import annotations

import random
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from primspace.data import JointScaler
from primspace.model.calibration import CodeCalibration
from primspace.model.latent import LatentInitializer
from primspace.train.vision_start import initializer_from_state
from primspace.utils.errors import UserError

__all__ = [
    "CHECKPOINT_FORMAT",
    "Checkpoint",
    "checkpoint_state",
    "unpack_checkpoint",
    "restore_rng",
    "read_checkpoint",
]

CHECKPOINT_FORMAT = 1


def checkpoint_state(
    *,
    config: dict,
    epoch: int,
    model: torch.nn.Module,
    theta_opt,
    table,
    initial_codes: torch.Tensor,
    scaler: JointScaler,
    initializer: LatentInitializer,
    generator: torch.Generator,
    frame_generator: torch.Generator | None = None,
    calibration: CodeCalibration | None = None,
) -> dict:
    """Everything a run needs to continue bit-identically, as one dict (``checkpoint.pt``).

    ``theta_opt`` is None while inferring (θ frozen). The RNG states are the batch-order
    generator's, the frame-drawing generator's (``vision_frames`` runs only) and the
    process's global torch, Python and NumPy generators. ``calibration``: the run's map
    from initial to fitted codes, or the one an inferred run carries from its trained run.
    """
    rng = {
        "shuffle": generator.get_state(),
        "torch": torch.get_rng_state(),
        "python": random.getstate(),
        "numpy": _numpy_state(),
    }
    if frame_generator is not None:
        rng["frames"] = frame_generator.get_state()
    return {
        "format": CHECKPOINT_FORMAT,
        "kind": config["kind"],
        "epoch": epoch,
        "model": model.state_dict(),
        "theta_optimizer": None if theta_opt is None else theta_opt.state_dict(),
        "latents": table.state_dict(),
        "initial_codes": initial_codes,
        "scaler": scaler.to_dict(),
        "initializer": initializer.state_dict(),
        "calibration": None if calibration is None else calibration.state_dict(),
        "rng": rng,
        "config": config,
    }


@dataclass
class Checkpoint:
    """A checkpoint's parts, unpacked and checked (:func:`unpack_checkpoint`)."""

    epoch: int
    model: dict  # state dict of the MTRNNDecoder
    theta_optimizer: dict | None
    latents: dict  # LatentTable state dict
    initial_codes: torch.Tensor
    scaler: JointScaler
    initializer: LatentInitializer
    rng: dict
    config: dict
    calibration: CodeCalibration | None = None


def unpack_checkpoint(state: dict, where: str | Path = "checkpoint") -> Checkpoint:
    """The parts of a checkpoint dict; one clear :class:`UserError` naming ``where`` if a part is missing."""
    try:
        return Checkpoint(
            epoch=int(state["epoch"]),
            model=state["model"],
            theta_optimizer=state["theta_optimizer"],
            latents=state["latents"],
            initial_codes=state["initial_codes"],
            scaler=JointScaler.from_dict(state["scaler"]),
            initializer=initializer_from_state(state["initializer"]),
            rng=state["rng"],
            config=state["config"],
            calibration=None
            if state.get("calibration") is None
            else CodeCalibration.from_state_dict(state["calibration"]),
        )
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise UserError(f"{where}: not a primspace checkpoint ({str(exc).splitlines()[0]})") from None


def restore_rng(rng: dict, generator: torch.Generator, frame_generator: torch.Generator | None = None) -> None:
    """Put the batch-order and frame-drawing generators and the global generators back where a checkpoint saved them."""
    generator.set_state(rng["shuffle"])
    if frame_generator is not None:
        frame_generator.set_state(rng["frames"])
    torch.set_rng_state(rng["torch"])
    random.setstate(_to_tuple(rng["python"]))
    _set_numpy_state(rng["numpy"])


def read_checkpoint(path: Path, map_location) -> dict | None:
    if not path.is_file():
        return None
    try:
        ckpt = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # torch raises many kinds for a damaged file
        raise UserError(
            f"{path}: cannot read the checkpoint ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
        ) from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
        raise UserError(
            f"{path}: not a primspace checkpoint (format {ckpt.get('format') if isinstance(ckpt, dict) else '?'})"
        )
    return ckpt


def _numpy_state() -> dict:
    name, keys, pos, has_gauss, cached = np.random.get_state()
    return {
        "name": name,
        "keys": torch.from_numpy(keys.astype(np.int64)),
        "pos": int(pos),
        "has_gauss": int(has_gauss),
        "cached": float(cached),
    }


def _set_numpy_state(s: dict) -> None:
    np.random.set_state((s["name"], s["keys"].numpy().astype(np.uint32), s["pos"], s["has_gauss"], s["cached"]))


def _to_tuple(x):
    return tuple(_to_tuple(v) for v in x) if isinstance(x, (list, tuple)) else x
