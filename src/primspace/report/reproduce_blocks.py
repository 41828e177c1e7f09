"""The generated blocks of docs/reproduce.md: the paper's own setting, and the clustering ablation.

Issue 42 asks two questions of the stored summaries, each answered by a block that
:mod:`primspace.report.markdown` writes into docs/reproduce.md:

- **the paper's own setting** (:func:`paper_setting`): the paper trains motor and vision
  together, "L(θ, z_1, z_2, ..., z_n) = Σ_i ‖d(θ, z_i) − o_i‖²", the squared error summed over
  every joint angle and every pixel. Ours (every preset) averages each modality per element.
  The block sets the runs in the paper's setting (:data:`PAPER_SETTING`) beside ours at the
  same preset: the final motor and vision error per element (the same scale whatever the
  loss), success in the simulator per primitive, and clustering.
- **the clustering ablation** (:func:`clustering_ablation`, :func:`ablation`): does the
  optimiser, or the codes' scale, explain why zero-initialised codes cluster worse than
  projection's at q = 40, where the paper finds them alike? Its rule was written in
  docs/reproduce.md before the runs.

Every spread is the sample std over seeds (ddof 1). Reads summaries only.
"""

from __future__ import annotations

import numpy as np

from primspace.experiments.results import LEARNED_CODES
from primspace.report.comparisons import merged, render_comparison, side_names
from primspace.report.summary_tables import g, mean_spread, table
from primspace.stats import sample_std

__all__ = [
    "PAPER_SETTING",
    "ABLATION",
    "clustering_gaps",
    "clustering_ablation",
    "ablation",
    "success_by_primitive",
    "paper_setting",
]

#: The summaries of the paper-setting block, in order: (ours, the paper's setting, what differs).
PAPER_SETTING = (
    (
        "paper",
        "paper-sum40",
        "ours (motor only, per-element mean, Adam) against the paper's setting (motor and frames, the summed "
        "squared error, Adam: the optimiser the ablation supports), paper preset, full schedule, q = 40",
    ),
    (
        "paper-images-short-mean",
        "paper-images-short-sum",
        "with frames, the per-element mean against the summed loss, 35 % of the schedule, one seed, one H200",
    ),
)

#: The clustering ablation's two sides: Adam's summary, and plain gradient descent's
#: (one summary, or one per init when the rates were tuned per init).
ABLATION = ("paper-adam40", "paper-sgd40")


def clustering_gaps(summary: dict) -> dict[str, list[float]]:
    """Per seed, projection's clustering accuracy minus zero's (learned codes), as they are and
    after each rescaling of the clustering's ``rescaled`` rows: ``{how: [gap per seed]}``."""
    c = summary["results"].get("clustering") or {}
    rows = [(int(c.get("seed", 0)), r) for r in c.get("latent", [])]
    rows += [(int(seed), r) for seed, rs in c.get("by_seed", {}).items() for r in rs]
    ways = {"as they are": {(seed, r["init"]): r["accuracy"] for seed, r in rows if r.get("codes") == LEARNED_CODES}}
    for r in c.get("rescaled", []):
        ways.setdefault(r["rescaling"], {})[(int(r["seed"]), r["init"])] = r["accuracy"]
    return {
        how: [acc[(s, "projection")] - acc[(s, "zero")] for s in sorted({s for s, _ in acc}) if (s, "zero") in acc]
        for how, acc in ways.items()
    }


def _gone(base: list[float], other: list[float]) -> tuple[bool, str]:
    """docs/reproduce.md's rule: the gap is gone in ``other`` (|g| <= s) and shrank by more than both spreads."""
    (g0, s0), (g1, s1) = ((float(np.mean(v)), sample_std(v)) for v in (base, other))
    ok = abs(g1) <= s1 and g0 - g1 > s0 + s1
    return ok, f"{g1:.2f} ± {s1:.2f} against {g0:.2f} ± {s0:.2f}"


def clustering_ablation(adam: dict, sgd: dict) -> str:
    """The verdict of the clustering ablation (docs/reproduce.md, its rule written before the
    runs): does the optimiser, or the codes' scale, explain the gap between zero and projection?"""
    a, b = clustering_gaps(adam), clustering_gaps(sgd)
    if len(a.get("as they are", [])) < 2 or len(b.get("as they are", [])) < 2:
        return "The clustering ablation needs two seeds or more on each side."
    lines = ["Gap = projection's clustering accuracy minus zero's, per seed; mean ± sample std over seeds:", ""]
    ok, text = _gone(a["as they are"], b["as they are"])
    lines.append(
        f"- plain gradient descent: {text} (Adam) — the optimiser {'explains' if ok else 'does not explain'} the gap"
    )
    for how in (h for h in a if h != "as they are"):
        ok, text = _gone(a["as they are"], a[how])
        lines.append(
            f"- Adam's codes, {how}: {text} (as they are) — the scale {'explains' if ok else 'does not explain'} it"
        )
    return "\n".join(lines)


def ablation(summaries: dict[str, dict]) -> str:
    """docs/reproduce.md's ablation block: the two sides' table and the rule's verdict."""
    adam, sgd = ABLATION
    if not all(n in summaries for n in side_names(adam) + side_names(sgd)):
        return f"The clustering ablation's summaries ({', '.join(side_names(adam) + side_names(sgd))}) are not all stored yet."
    a, b = merged(summaries, adam), merged(summaries, sgd)
    what = "Adam (ours) against plain gradient descent (`--optimizer sgd`), paper preset, motor only, q = 40"
    return render_comparison(a, b, what) + "\n\n" + clustering_ablation(a, b)


def success_by_primitive(summary: dict) -> tuple[list[str], list[list[str]]]:
    """Success in the simulator per init and primitive: mean over seeds (the number of seeds
    in the init's cell)."""
    success = summary["results"].get("success")
    if not success:
        return [], []
    names = success.get("label_names") or []
    points: dict[str, list[dict]] = {}
    for gen in [success.get("generated", {})] + list(success.get("by_seed", {}).values()):
        for init, res in gen.items():
            points.setdefault(init, []).append(res)
    rows = []
    for init, ps in points.items():
        cells = [mean_spread([p["rates"][n] for p in ps if n in p.get("rates", {})], rng=False) for n in names]
        rows.append(
            [f"{summary['name']}: {init} ({len(ps)} seeds)", *cells, g(float(np.mean([p["overall"] for p in ps])))]
        )
    return ["run", *names, "all"], rows


def paper_setting(summaries: dict[str, dict]) -> str:
    """docs/reproduce.md's block on the paper's own setting: each pair of :data:`PAPER_SETTING`
    that is stored, as a comparison (errors per element, success, clustering), then success
    per primitive of every stored summary of the pairs."""
    parts, stored = [], []
    for ours, theirs, what in PAPER_SETTING:
        if ours in summaries and theirs in summaries:
            parts.append(render_comparison(summaries[ours], summaries[theirs], what))
        stored += [n for n in (ours, theirs) if n in summaries and n not in stored]
    missing = [n for pair in PAPER_SETTING for n in pair[:2] if n not in summaries]
    rows, columns = [], []
    for name in stored:
        columns_i, rows_i = success_by_primitive(summaries[name])
        columns = columns or columns_i
        rows += rows_i if columns_i == columns else []
    if rows:
        parts.append("**Success per primitive** (mean ± sample std over seeds)\n\n" + table(columns, rows))
    if missing:
        parts.append(f"Not stored yet: {', '.join(dict.fromkeys(missing))}.")
    return "\n\n".join(parts)
