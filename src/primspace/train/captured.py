"""How a batch's step runs when it is not op by op (``TrainConfig.step``): compiled or captured.

The model is small (two MTRNN layers of 32 and 12 units) and its recurrent loop is
hundreds of small operations per batch (61 steps x 2 layers, forward and backward), so a
step is bound by launching them, not by arithmetic (docs/performance.md):

* ``"compiled"`` (:class:`CompiledDecoder`): the recurrent loop
  (:meth:`~primspace.model.decoder.MTRNNDecoder.dynamics`) through ``torch.compile``; the
  elementwise work of the cell is fused. The heads stay eager.
* ``"captured"`` (:class:`CapturedStep`): every batch has the same shape, so the whole
  step (forward, loss, backward, θ's Adam and the codes' row-wise Adam) is recorded once as
  a CUDA graph and replayed for every batch: one launch per batch. Static shapes: a
  batch has ``min(batch_size, N)`` rows, a shorter last batch padded with rows that are
  not in it and weigh 0 in the loss (:func:`~primspace.train.loss.batch_loss`
  ``weights``) and do not step (:meth:`~primspace.model.latent.LatentTable.step` ``active``);
  the K drawn frames are indices into the static buffer of each batch's steps; the
  learning rates are tensors the graph reads. On the CPU the same padded step runs
  without a graph: what the tests check on machines without a GPU.

Both are the eager step within float tolerance (the padded means sum in another order;
the compiled cell fuses its arithmetic), not bit for bit: ``"eager"`` stays the default
and the CPU's reference.
"""

from __future__ import annotations

import torch

from primspace.train.loss import batch_loss
from primspace.utils.errors import UserError

__all__ = [
    "CompiledDecoder",
    "CapturedStep",
    "StepGraph",
    "padded_rows",
    "check_single_process",
    "check_graphable",
    "tensor_rates",
    "float_rates",
    "COMPILE_BACKEND",
]

#: The ``torch.compile`` backend of ``step="compiled"`` (the tests on machines without a
#: GPU trace with ``"eager"``: inductor's first compile takes minutes on two cores).
COMPILE_BACKEND = "inductor"


def check_single_process(session, what: str) -> None:
    """One line when ``session`` trains on several processes, in micro-batches or from streamed frames."""
    if session.world.size > 1 or session.world.micro_batches > 1 or session.stream is not None:
        raise UserError(f"{session.name}: {what} trains in one process, in whole batches, with its frames in memory")


def check_graphable(tc) -> None:
    """One line for a step that cannot be a CUDA graph yet: θ's plain gradient descent (its
    rate is a number inside ``torch.optim.SGD``, not a tensor the graph reads)."""
    if tc.optimizer != "adam":
        raise UserError(
            f"step='captured' on CUDA needs optimizer='adam' (not built for {tc.optimizer!r}); use step='eager'"
        )


class CompiledDecoder:
    """A decoder called as the loss calls it, its recurrent loop compiled (``torch.compile``).

    The decoder itself is not changed (its checkpoints, copies and other callers stay
    eager); the compiled function is this object's.
    """

    def __init__(self, model) -> None:
        self.model, self.config = model, model.config
        self.dynamics = torch.compile(model.dynamics, backend=COMPILE_BACKEND)

    def __call__(self, z: torch.Tensor, *, images: bool = True, frame_steps: torch.Tensor | None = None, seen=None):
        return self.model.decode(self.dynamics(z), images=images, frame_steps=frame_steps, seen=seen)


def padded_rows(rows: torch.Tensor, n: int, size: int) -> torch.Tensor:
    """``rows`` (b,) followed by ``size - b`` other rows of ``range(n)`` (the first not in
    ``rows``): a batch of the static size whose rows are distinct."""
    b = rows.numel()
    if b == size:
        return rows
    free = torch.ones(n, dtype=torch.bool, device=rows.device).index_fill_(0, rows, False)
    return torch.cat([rows, free.nonzero().squeeze(1)[: size - b]])


class StepGraph:
    """A step function recorded once as a CUDA graph and replayed (``torch.cuda.graphs``).

    ``compute`` reads and writes only tensors that live as long as this object (static
    inputs, parameters, optimiser state, outputs). Recording follows PyTorch's recipe:
    a few warm-up calls on a side stream (which allocate the optimisers' state), then the
    capture. The warm-up calls change the state, so ``state`` (the tensors a step writes)
    and the optimisers' state are put back before the capture: the first replay is the
    first step.
    """

    WARMUP = 3

    def __init__(self, compute, state: list[torch.Tensor], optimizers: list) -> None:
        self.compute, self.state, self.optimizers = compute, state, optimizers
        self.graph = None

    def replay(self) -> None:
        if self.graph is None:
            self._record()
        self.graph.replay()

    def warm_up(self) -> None:
        """Run ``compute`` :attr:`WARMUP` times (they allocate the optimisers' state), then put
        ``state`` and the optimisers' state back as they were (a state the warm-up created:
        zeros, as a fresh one). Device-agnostic: the tests run it on the CPU."""
        saved = [t.detach().clone() for t in self.state]
        opt_saved = [
            {p: {k: v.clone() for k, v in st.items()} for p, st in opt.state.items()} for opt in self.optimizers
        ]
        for _ in range(self.WARMUP):
            for opt in self.optimizers:
                opt.zero_grad(set_to_none=True)
            self.compute()
        with torch.no_grad():
            for t, v in zip(self.state, saved):
                t.copy_(v)
            for opt, before in zip(self.optimizers, opt_saved):
                for p, st in opt.state.items():
                    for k, v in st.items():
                        v.copy_(before[p][k]) if p in before else v.zero_()

    def _record(self) -> None:
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side):
            self.warm_up()
        torch.cuda.current_stream().wait_stream(side)
        for opt in self.optimizers:
            opt.zero_grad(set_to_none=True)  # the captured backward writes the gradients afresh
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            self.compute()


class CapturedStep:
    """The ``"captured"`` step of a :class:`~primspace.train.loop.Session` (module docstring).

    :meth:`run` trains one epoch of the session's draws (:meth:`Session.begin_epoch`).
    """

    def __init__(self, session) -> None:
        check_single_process(session, "step='captured'")
        self.session = session
        device = session.device
        self.size = min(session.tc.batch_size, session.n)
        self.idx = torch.arange(self.size, device=device)
        self.weights = torch.zeros(self.size, device=device)
        self.active = torch.zeros(self.size, dtype=torch.bool, device=device)
        self.count = torch.zeros((), device=device)
        self.steps = (
            None
            if session.frames is None
            else torch.zeros(self.size, session.frames[0], dtype=torch.long, device=device)
        )
        self.values = torch.zeros(3, device=device)
        self.code_lr = torch.zeros((), device=device)
        self.theta_lr = torch.zeros((), device=device)
        self.autocast = None
        self.graph = None
        if device.type == "cuda":
            check_graphable(session.tc)
            opts = [] if session.theta_opt is None else [session.theta_opt]
            state = [session.table.codes, session.table.exp_avg, session.table.exp_avg_sq, session.table.steps]
            state += [p for p in session.model.parameters() if p.requires_grad]
            self.graph = StepGraph(self._compute, state, opts)

    def run(self, epoch) -> None:
        """Every batch of ``epoch`` (one part each), its loss sums added to ``epoch.sums``."""
        self.autocast = epoch.autocast
        self._rates_in()
        try:
            for _, parts in epoch.batches:
                ((part, rows, steps),) = parts
                self._load(rows, steps)
                if self.graph is not None:
                    self.graph.replay()
                else:
                    if self.session.theta_opt is not None:
                        self.session.theta_opt.zero_grad(set_to_none=True)
                    self._compute()
                epoch.sums[part.micro] += self.values.double() * part.size
        finally:
            self._rates_out()

    def _load(self, rows: torch.Tensor, steps: torch.Tensor | None) -> None:
        b = rows.numel()
        self.idx.copy_(padded_rows(rows, self.session.n, self.size))
        self.weights.zero_()[:b] = 1.0
        self.active.zero_()[:b] = True
        self.count.fill_(b)
        if steps is not None:
            self.steps.zero_()[:b] = steps

    def _compute(self) -> None:
        s = self.session
        z = s.table.codes.index_select(0, self.idx).requires_grad_(True)
        loss, values = batch_loss(s.net, z, self.idx, s.tensors, s.tc, self.autocast, self.steps, None, self.weights)
        loss.backward()
        if s.theta_opt is not None:
            s.theta_opt.step()
        # the weighted mean scaled each code's gradient by 1/b: undone (Session._step)
        s.table.step(self.idx, z.grad.mul_(self.count), self.active, self.code_lr)
        self.values.copy_(values)

    def _rates_in(self) -> None:
        """The epoch's learning rates (set by ``begin_epoch``) into the tensors the step reads."""
        s = self.session
        self.code_lr.fill_(s.table.lr)
        if s.theta_opt is not None and self.graph is not None:  # no graph: θ's float rate, as the eager step reads it
            tensor_rates(s.theta_opt, self.theta_lr, s.device)

    def _rates_out(self) -> None:
        if self.session.theta_opt is not None and self.graph is not None:
            float_rates(self.session.theta_opt, self.theta_lr)


def tensor_rates(opt, lr: torch.Tensor, device) -> None:
    """Make ``opt`` (Adam) capturable, its rate read from ``lr`` (filled with its current rate)."""
    lr.fill_(opt.param_groups[0]["lr"])
    for group in opt.param_groups:
        group["lr"], group["capturable"] = lr, True
    for state in opt.state.values():  # a resumed optimiser's step counts on the device
        if "step" in state and state["step"].device != device:
            state["step"] = state["step"].to(device, torch.float32)


def float_rates(opt, lr: torch.Tensor) -> None:
    """Undo :func:`tensor_rates`: plain rates again, so a checkpoint's optimiser state loads anywhere."""
    for group in opt.param_groups:
        group["lr"], group["capturable"] = float(lr), False
