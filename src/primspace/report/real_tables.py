"""docs/real.md's generated block: the intra protocol on real recordings, one row per data set.

Every stored summary of the experiment preset ``real`` (``primspace experiment intra --preset
real --data FILE.h5``, :func:`is_real`) is one data set: its commands, then two tables. The
first gives each init's final held-out inference loss (the eval part's, θ frozen; mean ±
sample std over seeds) and the verdict of :mod:`primspace.results.claim_rules_real` (projection
below zero by more than the spread). The second gives what explains the verdict
(:func:`~primspace.results.claim_rules_real.diagnostics`, from the codes stored beside the
summary): the data's dimension against q, the codes' scale, the projected codes'
conditioning, and the losses before inference and at the end of the fit. These summaries are
shown here only, not among docs/results.md's tables of the paper's presets.
"""

from __future__ import annotations

import numpy as np

from primspace.report.commands import portable_command
from primspace.report.summary_tables import g, mean_spread, table
from primspace.results.claim_rules_real import RULE, diagnostics, eval_losses, projection_below_zero
from primspace.results.claims import codes_of_summary
from primspace.results.codes import read_codes

__all__ = ["REAL", "INITS", "is_real", "render_real", "NO_REAL"]

#: The experiment preset whose summaries this block shows (``primspace.experiments.presets.REAL_PRESET``).
REAL = "real"
#: The inits, in the tables' order.
INITS = ("zero", "random", "projection", "pca", "calibrated")
#: The block while no such summary is stored.
NO_REAL = "No summaries of the real preset are stored yet (docs/results/real-*.json)."


def is_real(summary: dict) -> bool:
    """Whether ``summary`` is of the experiment preset ``real``."""
    return (summary.get("preset") or {}).get("name") == REAL


def _curve_point(intra: dict, phase: str, index: int) -> dict[str, list[float]]:
    """``{init: [loss at ``index`` of ``phase`` per run]}``."""
    out: dict = {}
    for run in intra["runs"]:
        curve = [h["loss"] for h in run.get(phase, []) if h.get("loss") is not None]
        if curve:
            out.setdefault(run["init"], []).append(curve[index])
    return out


def _verdict_cell(outcome: dict) -> str:
    return f"**{outcome['verdict']}**: {outcome['text']}"


def _loss_row(summary: dict) -> list[str]:
    intra, data = summary["results"]["intra"], summary.get("data", {})
    losses = eval_losses(intra)
    q = max(losses) if losses else None
    by_init = {i: list(d.values()) for i, d in losses.get(q, {}).items()}
    runs = intra["runs"]
    n = f"{runs[0].get('n_train')} / {runs[0].get('n_eval')}" if runs else "—"
    seeds = len({r["seed"] for r in runs})
    classes = len(data.get("label_names") or intra.get("label_names") or [])
    return [
        f"*{summary['name']}*",
        n,
        str(classes),
        f"{data.get('length')} x {data.get('n_joints')}",
        str(q),
        str(seeds),
        *(mean_spread(by_init[i], digits=2, rng=False) if i in by_init else "—" for i in INITS),
        _verdict_cell(projection_below_zero(intra)),
    ]


def _why_row(summary: dict) -> list[str]:
    intra = summary["results"]["intra"]
    q = max(r["latent_dim"] for r in intra["runs"])
    path = codes_of_summary(summary)
    d = diagnostics(read_codes(path), summary.get("data", {}), q) if path is not None else {}
    start, fit = _curve_point(intra, "infer", 0), _curve_point(intra, "fit", -1)

    def mean(values) -> str:
        return g(float(np.mean(values))) if values else "—"

    return [
        f"*{summary['name']}*",
        f"{d.get('values')} / {q}" if d else "—",
        g(d.get("pm_norm")),
        g(d.get("zero_norm")),
        g(d.get("scale_ratio")),
        g(d.get("drift")),
        g(d.get("condition")),
        g(d.get("top_share")),
        *(mean(start.get(i)) for i in ("projection", "calibrated", "zero")),
        *(mean(fit.get(i)) for i in ("projection", "zero")),
    ]


_LOSS_COLUMNS = [
    "data set",
    "fitted / inferred",
    "classes",
    "T x J",
    "q",
    "seeds",
    *INITS,
    "verdict",
]
_WHY_COLUMNS = [
    "data set",
    "T·J / q",
    "‖P m‖",
    "‖z‖, zero's fit",
    "‖P m‖ / ‖z‖",
    "drift of projection's fit",
    "σ1/σq of P m",
    "σ1² share",
    "eval loss at start: projection",
    "calibrated",
    "zero",
    "fit loss, final: projection",
    "zero",
]


def render_real(summaries: dict[str, dict]) -> str:
    """The block (module docstring), or :data:`NO_REAL`."""
    real = [s for s in summaries.values() if is_real(s) and "intra" in s["results"]]
    if not real:
        return NO_REAL
    lines = ["The commands, per data set (`OUT` the experiment folder, `DATA.h5` the imported file):", ""]
    for s in real:
        lines += [f"*{s['name']}*" + (f": {s['note']}" if s.get("note") else ""), "", "```"]
        lines += [portable_command(c.strip()) for c in s["command"].strip().splitlines()] + ["```", ""]
    lines += [
        "**Final held-out inference loss** (the inferred 80 %'s loss after the last inference epoch, θ frozen; "
        f"mean ± sample std over seeds, ddof 1) and the verdict, rule {RULE}:",
        "",
        table(_LOSS_COLUMNS, [_loss_row(s) for s in real]),
        "",
        "**What explains it** (means over seeds; codes from the summary's codes file): the values P maps to q; "
        "the mean norm of the projected codes P m before training and of the codes zero's fit learned, and their "
        "ratio; the mean relative drift ‖z − P m‖ / ‖P m‖ of projection's fitted codes; the centred P m's largest "
        "over smallest singular value and the first one's share of the variance; the eval loss before the first "
        "inference step, and the fit's final loss:",
        "",
        table(_WHY_COLUMNS, [_why_row(s) for s in real]),
    ]
    return "\n".join(lines)
