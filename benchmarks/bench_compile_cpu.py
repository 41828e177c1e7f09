"""torch.compile of the recurrent loop on the CPU (not a test; issue 41, item 3: "torch.compile on CPU if it pays").

One fit step (forward, masked-free MSE, backward) of the paper-sized decoder (q = 40, layers
32/12, T = 61, 9 joints, motor only) at batch ``--batch``, eager against the same model whose
:meth:`~primspace.model.decoder.MTRNNDecoder.dynamics` (the two layers' 61-step loops) is wrapped by
``torch.compile`` (Inductor, default mode), on ``--threads`` CPU threads. Prints the first
call (the compile) and the median of ``--steps`` timed calls after it, their ratio, and the
largest difference of the loss and of the code gradient between the two (the compiled
arithmetic is reordered: not bit-identical).

The training path does not use this yet; a compiled fit would need its own (opt-in) setting,
since primspace's CPU results are bit-identical by default.

Usage::

    python benchmarks/bench_compile_cpu.py [--batch 32] [--steps 20] [--threads 1] [--json PATH]
"""

from __future__ import annotations

import argparse
import copy
import time

import torch

from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.utils.files import atomic_write_json


def _step(model, z, target):
    z.grad = None
    loss = ((model(z, images=False).motor - target) ** 2).mean()
    loss.backward()
    return float(loss.detach()), z.grad.clone()


def _timed(model, z, target, steps: int) -> dict:
    start = time.perf_counter()
    loss, grad = _step(model, z, target)
    first = time.perf_counter() - start
    times = []
    for _ in range(steps):
        start = time.perf_counter()
        _step(model, z, target)
        times.append(time.perf_counter() - start)
    times.sort()
    return {"first_s": first, "median_ms": 1e3 * times[len(times) // 2], "loss": loss, "grad": grad}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    config = ModelConfig(latent_dim=40, layer_sizes=(32, 12), taus=(2.0, 8.0), n_joints=9, length=61)
    eager = MTRNNDecoder(config)
    compiled = copy.deepcopy(eager)
    compiled.dynamics = torch.compile(compiled.dynamics)
    z = torch.randn(args.batch, config.latent_dim, requires_grad=True)
    target = torch.randn(args.batch, config.length, config.n_joints)
    a, b = _timed(eager, z, target, args.steps), _timed(compiled, z, target, args.steps)
    out = {
        "batch": args.batch,
        "threads": args.threads,
        "eager_ms": a["median_ms"],
        "compiled_ms": b["median_ms"],
        "speedup": a["median_ms"] / b["median_ms"],
        "compile_s": b["first_s"],
        "loss_diff": abs(a["loss"] - b["loss"]),
        "grad_max_diff": float((a["grad"] - b["grad"]).abs().max()),
        "torch": torch.__version__,
    }
    print(
        f"fit step, batch {args.batch}, {args.threads} thread(s): eager {out['eager_ms']:.2f} ms, "
        f"compiled {out['compiled_ms']:.2f} ms ({out['speedup']:.2f}x), compile {out['compile_s']:.0f} s; "
        f"|loss diff| {out['loss_diff']:.2e}, max |grad diff| {out['grad_max_diff']:.2e}"
    )
    if args.json:
        atomic_write_json(args.json, out)


if __name__ == "__main__":
    main()
