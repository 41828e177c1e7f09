"""The numbers the hand-written prose of docs/results.md and docs/sequences.md discusses,
generated from the stored summaries so that the prose need not restate them.

:func:`render_differ` is docs/results.md's block ``differ`` (beside "Where we differ from
the paper"): the paper preset's clustering accuracies and per-primitive success rates,
zero against projection, over seeds and per seed, and the raw trajectories' clustering.
:func:`render_composite_glance` is docs/sequences.md's block ``composite-glance``: per
composite summary, the model of single primitives against the peers and the window codes,
and whether issue 27's target is met (a rule, not a hand-typed verdict).
Spreads are the sample std over seeds (ddof 1, :func:`primspace.utils.stats.sample_std`).
"""

from __future__ import annotations

import numpy as np

from primspace.report.summary_tables import mean_spread, table
from primspace.results.layout import LEARNED_CODES

__all__ = ["render_differ", "render_composite_glance", "TARGET_27", "DIFFER_SUMMARY"]

#: The summary "Where we differ from the paper" discusses: the paper preset, motor only, q = 40.
DIFFER_SUMMARY = "paper"

#: Issue 27's target for segmentation by synthesis: boundary F1 and per-step labelling
#: accuracy of at least this, as the mean over seeds.
TARGET_27 = 0.8

#: The primitives the paper names as needing precision ("pushing and pulling the block as
#: well as grasping").
PRECISE = ("push", "pull", "grasp")


def _per_seed(values: list[float]) -> str:
    """``mean ± sample std (seeds a, b, c)``; one value alone as itself."""
    if len(values) < 2:
        return f"{values[0]:.2f} (one seed)" if values else "—"
    return f"{mean_spread(values, rng=False)} (per seed {', '.join(f'{v:.2f}' for v in values)})"


def _clustering_by_seed(clustering: dict) -> dict[str, list[float]]:
    """``{init or "untrained P m": [accuracy per seed, in seed order]}`` of a clustering summary."""
    rows = [(int(clustering.get("seed", 0)), r) for r in clustering.get("latent", [])]
    rows += [(int(seed), r) for seed, rs in clustering.get("by_seed", {}).items() for r in rs]
    out: dict[str, list[float]] = {}
    for _, r in sorted(rows, key=lambda sr: sr[0]):
        key = r["init"] if r.get("codes") == LEARNED_CODES else "untrained P m"
        out.setdefault(key, []).append(float(r["accuracy"]))
    return out


def _success_by_seed(success: dict, init: str, primitive: str) -> list[float]:
    """The success rate of ``init``'s generated motions on ``primitive``, per seed in seed order."""
    points = [(int(success.get("seed", 0)), success.get("generated", {}))]
    points += [(int(seed), p) for seed, p in success.get("by_seed", {}).items()]
    return [float(p[init]["rates"][primitive]) for _, p in sorted(points, key=lambda sp: sp[0]) if init in p]


def render_differ(summaries: dict[str, dict]) -> str:
    """The numbers behind "Where we differ from the paper" (docs/results.md), from
    :data:`DIFFER_SUMMARY`: clustering accuracy of the learned codes (zero, projection, pca)
    and of the untrained P m; success of zero and projection on push, pull and grasp; the
    raw trajectories clustered at the paper's motion-capture setting."""
    s = summaries.get(DIFFER_SUMMARY)
    res = (s or {}).get("results", {})
    if not res.get("clustering") and not res.get("success"):
        return f"No stored summary {DIFFER_SUMMARY!r} with clustering or success yet (docs/results/)."
    lines = [f"From *{DIFFER_SUMMARY}* (its table above); mean ± sample std (ddof 1) over seeds, then per seed:", ""]
    clustering = res.get("clustering") or {}
    if clustering:
        acc = _clustering_by_seed(clustering)
        q, r2 = clustering.get("latent_dim"), clustering.get("r2_target")
        lines.append(f"- clustering accuracy of the codes (q = {q}, R² = {r2:g}):")
        lines += [f"  {init} {_per_seed(acc[init])};" for init in ("projection", "zero", "pca") if init in acc]
        if "untrained P m" in acc:
            lines.append(f"  the untrained projections P m {_per_seed(acc['untrained P m'])}")
        for name, t in (clustering.get("trajectory") or {}).items():
            chosen = t.get("chosen") or {}
            what = "the preset's simulated data" if name == "data" else "LASA"
            lines.append(
                f"- raw trajectories ({what}, {t['n']} motions, k = {t['k']}) clustered at R² = "
                f"{t['r2_target']:g}: accuracy {chosen.get('accuracy', float('nan')):.2f} (one clustering of the data)"
            )
    success = res.get("success") or {}
    if success:
        lines.append(
            f"- success of the generated eval motions (q = {success.get('latent_dim')}), zero against projection:"
        )
        for prim in PRECISE:
            zero, proj = (_success_by_seed(success, i, prim) for i in ("zero", "projection"))
            if zero and proj:
                lines.append(f"  {prim}: zero {_per_seed(zero)}, projection {_per_seed(proj)};")
    lines[-1] = lines[-1].rstrip(";")
    return "\n".join(lines)


def _mean(values: list) -> float | None:
    v = [float(x) for x in values if x is not None]
    return float(np.mean(v)) if v else None


def _f(x: float | None) -> str:
    return "—" if x is None else f"{x:.2f}"


def _span(values: list[float | None]) -> str:
    """``lo-hi`` of the means that exist (one value as itself, none as "—")."""
    v = [x for x in values if x is not None]
    if not v:
        return "—"
    return _f(min(v)) if np.isclose(min(v), max(v)) else f"{min(v):.2f}-{max(v):.2f}"


def _method_means(scores: list[dict]) -> tuple[float | None, float | None, float | None]:
    """Mean over seeds of boundary F1, F1 within the transition, and labelling accuracy."""
    return (
        _mean([m["boundary"]["f1"] for m in scores]),
        _mean([(m.get("boundary_transition") or {}).get("f1") for m in scores]),
        _mean([m["accuracy"] for m in scores]),
    )


def _glance_row(name: str, comp: dict) -> list[str] | None:
    """One composite summary's row of :func:`render_composite_glance` (None without a model
    of single primitives)."""
    seeds = comp.get("primitives") or []
    syn = [r["synthesis"] for r in seeds if "synthesis" in r]
    if not syn:
        return None
    sur = [r["surprise"] for r in seeds if "surprise" in r]
    blocks = [comp.get("peers", {})[k] for k in sorted(comp.get("peers", {}), key=int)]
    peers = {n for b in blocks for n in b.get("methods", {})}
    peer = [_method_means([b["methods"][n] for b in blocks if n in b.get("methods", {})]) for n in peers]
    groups: dict = {}
    for r in comp.get("runs", []):
        groups.setdefault((r["latent_dim"], r["init"]), []).append(r["segmentation"])
    window = [_method_means(g) for g in groups.values()]
    f1s, accs = [m["boundary"]["f1"] for m in syn], [m["accuracy"] for m in syn]
    within = [(m.get("boundary_transition") or {}).get("f1") for m in syn]
    bound = [m.get("accuracy_template_labels") for m in syn if m.get("accuracy_template_labels") is not None]

    def best(rows: list, k: int) -> str:
        return _f(max((r[k] for r in rows if r[k] is not None), default=None))

    def spread3(rows: list) -> str:
        return f"{_span([r[0] for r in rows])} ({_span([r[1] for r in rows])}) / {_span([r[2] for r in rows])}"

    met = ["met" if np.mean(v) >= TARGET_27 else "missed" for v in (f1s, accs)]
    s_f1, s_within, s_acc = _method_means(sur) if sur else (None, None, None)
    return [
        f"{name} ({len(syn)} seeds)",
        mean_spread(f1s, rng=False),
        mean_spread([w for w in within if w is not None], rng=False) if any(w is not None for w in within) else "—",
        f"{mean_spread(accs, rng=False)} (per seed {', '.join(f'{a:.2f}' for a in accs)})",
        mean_spread(bound, rng=False) if bound else "—",
        f"{_f(s_f1)} ({_f(s_within)}) / {_f(s_acc)}",
        f"{best(peer, 0)} ({best(peer, 1)}) / {best(peer, 2)}" if peer else "—",
        spread3(window) if window else "—",
        f"{met[0]} / {met[1]}",
    ]


def render_composite_glance(summaries: dict[str, dict]) -> str:
    """docs/sequences.md's summary of segmentation by synthesis: per composite summary,
    synthesis's boundary F1 (also within the transition), its labelling and the labeller's
    bound (mean ± sample std over seeds), surprise's, the best peer's and the window codes'
    means (F1 (within the transition) / labelling; the best peer per column, the window codes
    as the range over inits), and issue 27's target (:data:`TARGET_27`, the mean over seeds)."""
    rows = [
        row
        for s in summaries.values()
        if "composite" in s["results"]
        for row in [_glance_row(s["name"], s["results"]["composite"])]
        if row
    ]
    if not rows:
        return "No stored composite summary with a model of single primitives yet (docs/results/)."
    columns = [
        "summary",
        "synthesis: boundary F1",
        "within the transition",
        "labelling",
        "labeller's bound (nearest template's true primitive)",
        "surprise: F1 (within the transition) / labelling",
        "best peer, per column: F1 (within) / labelling",
        "window codes, range over inits: F1 (within) / labelling",
        f"issue 27's target (mean ≥ {TARGET_27:g}): boundaries / labels",
    ]
    return (
        "Segmentation by synthesis at a glance, from the tables above; mean ± sample std (ddof 1) "
        "over seeds, means elsewhere:\n\n" + table(columns, rows)
    )
