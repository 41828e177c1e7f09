"""Training the decoder and its latent codes (``fit``), codes for new data (``infer``),
and decoding codes back to motion (``reconstruct``).

Paper, *Main Results* and *Experimental Results*: the loss

.. math::  L(θ, z_1..z_n) = Σ_i ‖d(θ, z_i) − o_i‖²

is minimised over θ and the codes jointly ("train"), then over fresh codes with θ fixed
for new samples ("evaluation"). Here the loss is a weighted sum of per-element means,

.. math::  L = w_m · mean((m̂ − m)²) + w_v · mean((ŝ − s)²),

with ``m`` the motor sequence scaled per joint to [-1, 1] and ``s`` the frames in [0, 1]
(``uint8 / 255``). Means rather than the paper's sum, so that motor and vision weigh
equally at ``w_m = w_v = 1`` (a 48x64x3 frame has 1024 times as many values as a 9-joint
vector) and numbers do not depend on the batch size. ``fit`` and ``infer`` use the same
definition, so their curves compare.

Each code's gradient is that of its own sample's loss, whatever the batch: the batch
mean divides it by the batch size ``B``, so the table steps with ``B`` times the code
gradient of the batch loss. With θ frozen (``infer``) every code therefore receives
exactly the same updates for any batch size (up to floating-point summation order): a
large inference batch is only faster. (Before 0.2 the codes stepped on the batch-mean
gradient, so a code that fell in the short last batch of an epoch got a differently
scaled gradient; at 300 samples and batch 256 the final codes differed by 19-24%.)

The package, one concept per module:

- :mod:`~primspace.train.config`: :class:`TrainConfig`, the schedule, the device, and
  :func:`configure_process` (the process-wide settings that only entry points apply);
- :mod:`~primspace.train.run`: :class:`TrainedRun`, a run in memory;
- :mod:`~primspace.train.rundir`: the run directory, :func:`load_run`, :func:`write_run`;
- :mod:`~primspace.train.checkpoint`: the checkpoint format (packing, checking and
  unpacking a checkpoint's keys);
- :mod:`~primspace.train.loss`: the loss of a batch (``DataTensors``, ``batch_loss``,
  ``code_step``);
- :mod:`~primspace.train.loop`: the training loop (one ``Session`` per call);
- :mod:`~primspace.train.streaming`: frames read from the data file batch by batch;
- :mod:`~primspace.train.distributed`: one model trained by several processes (torchrun);
- :mod:`~primspace.train.api`: :func:`fit`, :func:`infer`, :func:`reconstruct`,
  :func:`decode_keypoints`, :func:`evaluate`, which accept each other's runs and work in memory unless given a
  directory;

A run directory holds the configs, ``metrics.jsonl`` (epoch 0 = the codes as initialised,
before any update), the checkpoint (written atomically after epoch 0, every
``checkpoint_seconds`` or ``checkpoint_every`` epochs, and at the end) and the codes.
``resume`` continues from the checkpoint bit-identically on the CPU.
"""

from importlib import import_module
from typing import TYPE_CHECKING

# Loaded on first use (PEP 562), so that ``primspace.train.config`` (and the command
# line's defaults) do not import torch; ``from primspace.train import fit`` works as usual.
_HOME = {
    "TrainConfig": "config",
    "TrainingDivergedError": "config",
    "configure_process": "config",
    "lr_factor": "config",
    "resolve_device": "config",
    "TrainedRun": "run",
    "fit": "api",
    "infer": "api",
    "reconstruct": "api",
    "decode_keypoints": "api",
    "evaluate": "api",
    "as_run": "sessions",
    "uses_images": "sessions",
    "load_run": "rundir",
    "write_run": "rundir",
    "check_run_data": "rundata",
    "load_fitted_data": "rundata",
    "read_indices": "primspace.data.indices",  # an index file, checked by data.check_indices
}
__all__ = list(_HOME)


def __getattr__(name: str):
    if name not in _HOME:
        raise AttributeError(f"module 'primspace.train' has no attribute {name!r}")
    home = _HOME[name]
    value = getattr(import_module(home if "." in home else f"primspace.train.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


if TYPE_CHECKING:  # for type checkers and IDEs
    from primspace.data.indices import read_indices  # noqa: F401
    from primspace.train.api import decode_keypoints, evaluate, fit, infer, reconstruct  # noqa: F401
    from primspace.train.config import (  # noqa: F401
        TrainConfig,
        TrainingDivergedError,
        configure_process,
        lr_factor,
        resolve_device,
    )
    from primspace.train.run import TrainedRun  # noqa: F401
    from primspace.train.rundata import check_run_data, load_fitted_data  # noqa: F401
    from primspace.train.rundir import load_run, write_run  # noqa: F401
    from primspace.train.sessions import as_run, uses_images  # noqa: F401
