"""Runs packed: several independent runs of one architecture trained together on one device.

An experiment grid is many small runs (inits x seeds at one latent size). One run keeps
a GPU nearly idle: the recurrent loop is a few hundred small operations per batch, each
a kernel launch whatever its size (docs/performance.md). Packed, R runs cost the
launches of one: per batch, the runs' parameters are stacked (``torch.stack``, so
autograd hands each run its own gradient) and the one loss function
(:func:`~primspace.train.loss.batch_loss`) is mapped over the runs with
``torch.func.vmap`` and ``functional_call``; the backward pass of the summed losses
gives each run the gradient it would get alone, and each run's optimiser and code table
step as alone.

Each run stays a :class:`~primspace.train.loop.Session` of its own (:func:`fit_session`,
:func:`infer_session`): its own seed, data rows, codes and their row-wise Adam state, θ
optimiser, shuffling and frame generators, metrics, run directory and checkpoints. A
packed run resumes packed or alone, and a run trained alone resumes packed.

**Same numbers?** The forward pass is bit-identical to the run alone on the CPU; the
gradients differ by rounding (the batched matrix products sum in another order, about
1e-7 of a gradient's size), so a packed run is the run alone within float tolerance,
not bit for bit (``tests/test_packed.py`` measures it). Runs pack when what shapes their
work agrees (:func:`pack_key`): architecture, number of samples, batch size, epochs,
frames, the loss and the device; each run trains alone in one process, frames in memory.
"""

from __future__ import annotations

import copy
import time
from dataclasses import astuple

import torch
from torch.func import functional_call, vmap

from primspace.train.captured import StepGraph, check_graphable, float_rates, padded_rows, tensor_rates
from primspace.train.config import TrainingDivergedError, thread_limit
from primspace.train.loop import Session
from primspace.train.loss import DataTensors, batch_loss
from primspace.train.run import TrainedRun
from primspace.train.rundir import run_from_state
from primspace.train.sessions import fit_session, infer_session
from primspace.utils.errors import UserError
from primspace.utils.interrupt import Interrupted, deferred_interrupt
from primspace.utils.progress import progress_bar

__all__ = ["PackedStep", "pack_key", "train_packed", "fit_packed", "infer_packed"]

#: The TrainConfig fields every run of a pack shares: the loss function is mapped over the
#: runs with one config, and the epochs and batches must line up.
SHARED_FIELDS = (
    "epochs",
    "optimizer",
    "batch_size",
    "vision_frames",
    "loss_reduction",
    "motor_weight",
    "vision_weight",
    "code_smoothness",
    "amp",
)

#: The data tensors of a :class:`~primspace.train.loss.DataTensors`, stacked over the runs.
_DATA_FIELDS = ("motor", "images", "mask", "motor_mask", "frame_mask")


def pack_key(session: Session) -> tuple:
    """What must agree for sessions to train packed: the model's architecture, the
    number of samples and steps, the :data:`SHARED_FIELDS` of the train config, whether
    θ trains and the device. Sessions with equal keys pack."""
    tc = session.tc
    shapes = tuple(
        None if getattr(session.tensors, f) is None else tuple(getattr(session.tensors, f).shape) for f in _DATA_FIELDS
    )
    return (
        astuple(session.model.config),
        shapes,
        tuple(getattr(tc, f) for f in SHARED_FIELDS),
        session.theta_opt is not None,
        str(session.device),
    )


def _check_packable(sessions: list[Session]) -> None:
    for s in sessions:
        if s.world.size > 1 or s.world.micro_batches > 1 or s.stream is not None:
            raise UserError(f"{s.name}: a packed run trains in one process with its frames in memory")
    keys = [pack_key(s) for s in sessions]
    for s, key in zip(sessions[1:], keys[1:]):
        if key != keys[0]:
            what = ("architecture", "data shapes", "train config (" + ", ".join(SHARED_FIELDS) + ")", "kind", "device")
            differs = next(w for w, a, b in zip(what, key, keys[0]) if a != b)
            raise UserError(f"{s.name}: cannot train packed with {sessions[0].name}: the {differs} differ")


class PackedStep:
    """The batch step of several sessions at once (module docstring).

    Parameters
    ----------
    sessions : list of Session
        Runs whose :func:`pack_key` agree, each in one process with frames in memory.
    """

    def __init__(self, sessions: list[Session]) -> None:
        _check_packable(sessions)
        self.sessions = sessions
        # the module whose forward is called with each run's parameters (a copy: its layout set for vmap)
        self.base = copy.deepcopy(sessions[0].model)
        if self.base.image_head is not None:
            self.base.image_head.channels_last = False
        self.names = [name for name, _ in self.base.named_parameters()]
        # each data tensor once when every run trains on the same (an experiment's inits), else stacked
        self.data, self.data_dims = {}, {}
        for f in _DATA_FIELDS:
            tensors = [getattr(s.tensors, f) for s in sessions]
            if tensors[0] is None:
                continue
            shared = all(t is tensors[0] or torch.equal(t, tensors[0]) for t in tensors[1:])
            self.data[f] = tensors[0] if shared else torch.stack(tensors)
            self.data_dims[f] = None if shared else 0
        first, runs, device = sessions[0], len(sessions), sessions[0].device
        self.tc, self.n = first.tc, first.n
        # static buffers, one row per run (primspace.train.captured): padded batches of one size
        self.size = min(self.tc.batch_size, self.n)
        self.idx = torch.arange(self.size, device=device).repeat(runs, 1)
        self.weights = torch.zeros(runs, self.size, device=device)
        self.active = torch.zeros(runs, self.size, dtype=torch.bool, device=device)
        self.count = torch.zeros(runs, device=device)
        k = None if first.frames is None else first.frames[0]
        self.steps = None if k is None else torch.zeros(runs, self.size, k, dtype=torch.long, device=device)
        self.values = torch.zeros(runs, 3, device=device)
        self.code_lr = torch.zeros(runs, device=device)
        self.theta_lr = torch.zeros(runs, device=device)
        self.autocast = None
        self.graph = None
        self.optimizers = [s.theta_opt for s in sessions if s.theta_opt is not None]
        if device.type == "cuda" and self.tc.step == "captured":
            check_graphable(self.tc)
            state = [t for s in sessions for t in (s.table.codes, s.table.exp_avg, s.table.exp_avg_sq, s.table.steps)]
            state += [p for s in sessions for p in s.model.parameters() if p.requires_grad]
            self.graph = StepGraph(self._compute, state, self.optimizers)

    def _loss(self, params: dict, z, idx, steps, data: dict, weights):
        tensors = DataTensors(**{f: data.get(f) for f in _DATA_FIELDS})
        model = _Functional(self.base, params)
        return batch_loss(model, z, idx, tensors, self.tc, self.autocast, steps, None, weights)

    def begin_epoch(self, autocast) -> None:
        """The epoch's learning rates (set by each session's ``begin_epoch``) into the step's tensors."""
        self.autocast = autocast
        for r, s in enumerate(self.sessions):
            self.code_lr[r] = s.table.lr
            if s.theta_opt is not None and self.graph is not None:
                tensor_rates(s.theta_opt, self.theta_lr[r], s.device)

    def end_epoch(self) -> None:
        if self.graph is not None:
            for r, s in enumerate(self.sessions):
                if s.theta_opt is not None:
                    float_rates(s.theta_opt, self.theta_lr[r])

    def step(self, batches: list, sums: list[torch.Tensor]) -> None:
        """One batch of every run: ``batches[r]`` is run r's ``(idx, parts)`` of
        :meth:`Session.begin_epoch` (one part), ``sums[r]`` its epoch's loss sums."""
        parts = [parts[0] for _, parts in batches]
        for r, (_, rows, steps) in enumerate(parts):
            b = rows.numel()
            self.idx[r] = padded_rows(rows, self.n, self.size)
            self.weights[r].zero_()[:b] = 1.0
            self.active[r].zero_()[:b] = True
            self.count[r] = b
            if steps is not None:
                self.steps[r].zero_()[:b] = steps
        if self.graph is not None:
            self.graph.replay()
        else:
            for opt in self.optimizers:
                opt.zero_grad(set_to_none=True)
            self._compute()
        for r, (part, _, _) in enumerate(parts):
            sums[r][part.micro] += self.values[r].double() * part.size

    def _compute(self) -> None:
        zs = [s.table.codes.index_select(0, self.idx[r]).requires_grad_(True) for r, s in enumerate(self.sessions)]
        own = [dict(s.model.named_parameters()) for s in self.sessions]
        params = {name: torch.stack([p[name] for p in own]) for name in self.names}
        in_dims = (0, 0, 0, None if self.steps is None else 0, self.data_dims, 0)
        loss, values = vmap(self._loss, in_dims=in_dims)(
            params, torch.stack(zs), self.idx, self.steps, self.data, self.weights
        )
        loss.sum().backward()  # each run's loss has weight 1 in the sum: its gradients are its own
        for r, s in enumerate(self.sessions):
            if s.theta_opt is not None:
                s.theta_opt.step()
            # the weighted mean scaled each code's gradient by 1/b: undone (Session._step)
            s.table.step(self.idx[r], zs[r].grad.mul_(self.count[r]), self.active[r], self.code_lr[r])
        self.values.copy_(values.detach())


class _Functional:
    """A decoder called with given parameters (``functional_call``), as :func:`batch_loss` calls a model."""

    def __init__(self, base, params: dict) -> None:
        self.base, self.params, self.config = base, params, base.config

    def __call__(self, *args, **kwargs):
        return functional_call(self.base, self.params, args, kwargs)


def train_packed(
    prepared: list[tuple[Session, dict | None]], progress: bool | None = None, label: str = "fit"
) -> list[TrainedRun]:
    """Run sessions of :func:`fit_session` / :func:`infer_session` packed (module docstring)
    to their last epoch; returns their runs in order.

    Sessions that resume from different epochs train in groups, one group per epoch they
    start from. A run whose loss becomes NaN/inf leaves the pack (its last good checkpoint
    kept) and the others go on; its :class:`~primspace.train.config.TrainingDivergedError`
    is raised when they are done.
    """
    sessions = [s for s, _ in prepared]
    errors = []
    with thread_limit(sessions[0].tc.threads):
        try:
            _check_packable(sessions)  # inside: a refused pack still closes its sessions (their run directories' locks)
            for s, ckpt in prepared:
                s.start(ckpt)
            for start in sorted({s.epoch for s in sessions}):
                group = [s for s in sessions if s.epoch == start and s.epoch < s.tc.epochs]
                if group:
                    errors += _train_group(group, progress, f"{label} {len(group)} runs packed")
            for s in sessions:
                if not any(s is e[0] for e in errors):
                    s.finish()
        finally:
            for s in sessions:
                s.close()
    if errors:
        raise errors[0][1]
    return [run_from_state(s.state(), s.history, None if s.run_dir is None else s.run_dir.path) for s in sessions]


def _train_group(group: list[Session], progress: bool | None, label: str) -> list:
    """Train ``group`` (all at the same epoch) to their last epoch; the (session, error) of those that diverged."""
    errors = []
    epochs = group[0].tc.epochs
    fields_fmt = "loss {task.fields[loss]:.4g}  {task.fields[sps]:.0f} samples/s"
    then = "stopping after this epoch, the runs' checkpoints written"
    deferred = all(s.store is not None for s in group)  # a pack trains in one process (_check_packable)
    with (
        deferred_interrupt(then, enabled=deferred) as stop,
        progress_bar(epochs, label, enabled=progress, fields=fields_fmt) as advance,
    ):
        advance(group[0].epoch)
        step = PackedStep(group)
        while group and group[0].epoch < epochs and not stop.requested:
            t0 = time.perf_counter()
            plans = [s.begin_epoch() for s in group]
            step.begin_epoch(plans[0].autocast)
            try:
                for batches in zip(*(p.batches for p in plans)):
                    step.step(list(batches), [p.sums for p in plans])
            finally:
                step.end_epoch()
            seconds = time.perf_counter() - t0
            going, lines = [], []
            for s, plan in zip(group, plans):
                try:
                    lines.append(s.end_epoch(s.world.sum(plan.sums.sum(0)), seconds))
                    going.append(s)
                except TrainingDivergedError as exc:  # a diverged run leaves the pack; the others go on
                    errors.append((s, exc))
            if len(going) != len(group):
                group = going
                step = PackedStep(group) if group else None
            if lines:
                advance(
                    loss=sum(line["loss"] for line in lines) / len(lines),
                    sps=sum(line["samples_per_s"] for line in lines),
                )
    if group and group[0].epoch < epochs:  # stopped by Ctrl-C
        for s in group:
            s.checkpoint_now()
        raise Interrupted(
            f"{label}: stopped after epoch {group[0].epoch} of {epochs}, checkpoints written; continue them with "
            f"resume=True, epochs={epochs}"
        )
    return errors


def fit_packed(jobs: list[dict], progress: bool | None = None) -> list[TrainedRun]:
    """:func:`~primspace.train.fit` of each job (a dict of its keyword arguments,
    ``dataset`` included), trained packed (:func:`train_packed`); the runs in order."""
    return train_packed(_sessions(fit_session, jobs), progress, "fit")


def infer_packed(jobs: list[dict], progress: bool | None = None) -> list[TrainedRun]:
    """:func:`~primspace.train.infer` of each job (``run``, ``dataset``, ``epochs``, ...), trained packed."""
    return train_packed(_sessions(infer_session, jobs), progress, "infer")


def _sessions(build, jobs: list[dict]) -> list:
    prepared = []
    try:
        for job in jobs:
            prepared.append(build(**job))
    except BaseException:
        for s, _ in prepared:
            s.close()
        raise
    return prepared
