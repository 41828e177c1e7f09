"""Markdown tables of one experiment summary: what the generated blocks of docs/results.md,
docs/predict.md and docs/sequences.md show, and the numbers as the docs print them.

The markdown counterpart of :mod:`primspace.report.sections` (the HTML report): both read
results and compute nothing. Each function takes a summary (``docs/results/*.json``,
:mod:`primspace.results.summary`) and returns markdown text;
:mod:`primspace.report.markdown` puts the text between the markers of the docs files.
Standard deviations are sample ones (ddof 1, over the seeds run; :func:`primspace.utils.stats.sample_std`).
"""

from __future__ import annotations

import re

import numpy as np

from primspace.report.commands import portable_command
from primspace.report.predict_tables import TASKS_TEXT, VERDICT_RULE, splits_tasks, task_tables
from primspace.results.claims import check_claims, codes_of_summary, verdict_text
from primspace.results.composite import PEER_RULES, bounds_table, composite_table, primitives_table, recall_table
from primspace.results.layout import LEARNED_CODES
from primspace.results.measures import eighth_loss
from primspace.results.tables import predict_error_table, scene_table, tuning_table
from primspace.utils.stats import sample_std, t_interval, wilson_interval

__all__ = [
    "g",
    "mean_spread",
    "table",
    "outcome_rows",
    "final_losses",
    "render_summary",
    "render_composite",
    "render_scene",
    "render_predict",
    "SMOKE_TEST_NOTE",
]


def g(x: float | None, digits: int = 2) -> str:
    """A number as the docs print it: ``digits`` significant digits, in scientific notation
    below 1e-3 (``2.7e-5``, not ``2.7e-05`` or ``0.000027``)."""
    if x is None or not np.isfinite(x):
        return "—"
    text = f"{x:.{digits - 1}e}" if x != 0 and (abs(x) < 1e-3 or abs(x) >= 1e5) else f"{x:.{digits}g}"
    return re.sub(r"e([+-])0*(\d)", lambda m: "e" + ("-" if m.group(1) == "-" else "") + m.group(2), text)


def mean_spread(values: list[float], digits: int = 2, rng: bool = True, ci: bool = False) -> str:
    """``mean ± std`` (sample std, ddof 1), with several values ``[min–max]`` (``rng``) and the
    95 % t-interval half-width (``ci``, :func:`primspace.utils.stats.t_interval`); one value alone."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    if v.size < 2:
        return g(v[0], digits) if v.size else "—"
    spread = 1 if digits <= 2 else digits - 1
    text = f"{g(v.mean(), digits)} ± {g(sample_std(v), spread)}"
    text += f" (95 % CI ± {g(t_interval(v)[1], spread)})" if ci else ""
    return text + (f" [{g(v.min(), digits)}–{g(v.max(), digits)}]" if rng else "")


def _last(curve: list[dict]) -> float | None:
    return curve[-1]["loss"] if curve else None


def _intra_rows(intra: dict) -> list[list[str]]:
    groups: dict = {}
    for r in intra["runs"]:
        groups.setdefault((r["latent_dim"], r["init"]), []).append(r)
    order = ["projection", "calibrated", "pca", "zero", "random"]
    rows = []
    for (q, init), runs in sorted(
        groups.items(), key=lambda kv: (kv[0][0], order.index(kv[0][1]) if kv[0][1] in order else 9)
    ):
        rows.append(
            [
                str(q),
                init,
                str(len(runs)),
                mean_spread([_last(r["fit"]) for r in runs]) if runs[0]["fit"] else "(projection's fit)",
                mean_spread([r["infer"][0]["loss"] for r in runs], rng=False),
                mean_spread([_last(r["infer"]) for r in runs]),
            ]
        )
    return rows


def table(columns: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _seed_points(success: dict) -> dict[str, list[dict]]:
    """``{init: [judged point per seed]}`` of a success summary."""
    out: dict = {}
    for gen in [success.get("generated", {})] + list(success.get("by_seed", {}).values()):
        for init, res in gen.items():
            out.setdefault(init, []).append(res)
    return out


def _rate(points: list[dict], prim: str | None) -> str:
    """Mean ± sample std (ddof 1) over seeds of a success rate, and the pooled rate with its Wilson 95 % interval."""
    rates, k, n = [], 0, 0
    for p in points:
        counts = p["counts"] if prim is None else {prim: p["counts"].get(prim)}
        if any(c is None for c in counts.values()):
            continue
        succ = p.get("successes") or {q: round(p["rates"][q] * c) for q, c in p["counts"].items()}
        k += sum(succ[q] for q in counts)
        n += sum(counts.values())
        rates.append(p["overall"] if prim is None else p["rates"][prim])
    if not n:
        return "—"
    lo, hi = wilson_interval(k, n)
    return f"{mean_spread(rates)}; pooled {k / n:.2f} [{lo:.2f}, {hi:.2f}]"


def outcome_rows(results: dict) -> list[list[str]]:
    success, clustering = results.get("success"), results.get("clustering")
    points = _seed_points(success) if success else {}
    acc: dict = {}
    if clustering:
        for rows in [clustering["latent"]] + list(clustering.get("by_seed", {}).values()):
            for r in rows:
                key = r["init"] if r["codes"] == LEARNED_CODES else "untrained P m"
                acc.setdefault(key, []).append(r["accuracy"])
    out = []
    for init in dict.fromkeys([*points, *acc]):
        p = points.get(init, [])
        out.append(
            [
                init,
                str(max(len(p), len(acc.get(init, [])))),
                _rate(p, None) if p else "—",
                _rate(p, "grasp") if p else "—",
                mean_spread(acc.get(init, [])),
            ]
        )
    return out


def _inter_rows(inter: dict) -> list[list[str]]:
    by: dict = {}
    for r in inter["runs"]:
        by.setdefault(r["init"], []).append(r)
    rows = []
    for init, runs in by.items():
        seeds = sorted({r.get("seed", 0) for r in runs})
        eighth = [eighth_loss(r["phase2"]) for r in runs]
        rows.append(
            [
                init,
                f"{len(runs)} ({len(seeds)} seeds)",
                mean_spread([r["phase2"][0]["loss"] for r in runs], rng=False),
                mean_spread(eighth, rng=False),
                mean_spread([_last(r["phase2"]) for r in runs]),
            ]
        )
    return rows


def _claim_rows(results: dict, codes=None) -> list[list[str]]:
    rows = []
    for r in check_claims(results, codes):
        if r["verdict"] == "not run":
            continue
        earlier = "; ".join(f"v{p['version']}: {p['verdict']}" for p in r["previous"]) or "—"
        rows.append(
            [
                f"“{r['quote']}”",
                f"v{r['version']}: {r['test']}",
                verdict_text(r, markdown=True),
                r["direction"],
                earlier,
            ]
        )
    return rows


def render_summary(summary: dict, tune_only: bool = False) -> str:
    """The markdown section of one summary; ``tune_only``: its tuning table alone (a tune
    run whose shared-setting runs are another summary's, :data:`primspace.report.markdown.TUNED_IN`, whose tables
    show them)."""
    res = summary["results"]
    out = _header(summary)
    if tune_only:
        return "\n".join(out + _tune_section(res))
    out += _intra_section(res)
    out += _outcome_section(res, summary.get("preset", {}))
    out += _inter_section(res)
    out += _tune_section(res)
    smoke = summary.get("preset", {}).get("name") == "demo"
    out += _claims_section(res, codes_of_summary(summary), SMOKE_TEST_NOTE if smoke else "")
    return "\n".join(out)


def _header(summary: dict) -> list[str]:
    """A summary's heading, its command and one line of its settings and machine."""
    preset, cpu = summary.get("preset", {}), summary.get("cpu", {})
    seeds = preset.get("seeds", [])
    return [
        f"#### {summary['name']}",
        "",
        "```",
        portable_command(summary["command"].strip()),
        "```",
        "",
        f"primspace {summary.get('primspace')}; preset {preset.get('name')}, "
        f"{'with images' if preset.get('images') else 'motor only'}, seeds {', '.join(map(str, seeds))}, "
        f"epochs {preset.get('fit_epochs')} + {preset.get('infer_epochs')}, loss "
        f"{preset.get('train', {}).get('loss_reduction', 'mean')}; measured on {cpu.get('model', '?')} ({cpu.get('isa', '?')})."
        + (f" {summary['note']}" if summary.get("note") else ""),
    ]


def _intra_section(res: dict) -> list[str]:
    """The lines of a summary's intra losses (none where it holds no intra)."""
    if "intra" not in res:
        return []
    return [
        "",
        "Losses (mean ± sample std (ddof 1) over seeds [per-seed range]): the fit's final loss, and the eval part's loss "
        "(θ frozen) before the first and after the last inference epoch.",
        "",
        table(["q", "init", "seeds", "fit, final", "eval, start", "eval, final"], _intra_rows(res["intra"])),
    ]


def _outcome_section(res: dict, preset: dict) -> list[str]:
    """The lines of a summary's success rates and clustering accuracies (none where it holds neither)."""
    outcome = outcome_rows(res)
    if not outcome:
        return []
    q = (res.get("clustering") or res.get("success") or {}).get("latent_dim")
    columns = ["init", "seeds", "success, all primitives", "success, grasp", "clustering accuracy"]
    keep = [0, 1] + ([2, 3] if res.get("success") else []) + ([4] if res.get("clustering") else [])
    said = (
        [
            "success rate of the generated eval motions judged by the simulator (mean ± sample std (ddof 1) over seeds; pooled "
            "over seeds with its Wilson 95 % interval)"
        ]
        if res.get("success")
        else []
    ) + (
        [
            f"clustering accuracy of the codes (R² = {preset.get('cluster_r2')}; mean ± sample std (ddof 1) over seeds [range])"
        ]
        if res.get("clustering")
        else []
    )
    return [
        "",
        f"At q = {q}: {', and '.join(said)}.",
        "",
        table([columns[i] for i in keep], [[row[i] for i in keep] for row in outcome]),
    ]


def _inter_section(res: dict) -> list[str]:
    """The lines of a summary's inter-primitive phase 2 (none where it holds no inter)."""
    if "inter" not in res:
        return []
    return [
        "",
        f"Inter-primitive, phase 2 at q = {res['inter'].get('latent_dim')} (mean ± sample std (ddof 1) over folds and seeds):",
        "",
        table(["init", "folds", "loss at start", "after 1/8 of the epochs", "final"], _inter_rows(res["inter"])),
    ]


#: Said above the demo preset's claims: its verdicts show that the checks run, not what the paper's claims do.
SMOKE_TEST_NOTE = (
    " **A smoke test, not evidence**: the demo preset (126 motions, a few hundred epochs) is too small to test the "
    "paper's claims (see its success rates above): these verdicts show that the checks run."
)


def _claims_section(res: dict, codes=None, note: str = "") -> list[str]:
    """The lines of a summary's claims table (none where no claim is checked); ``codes``: its
    codes file, where it has one; ``note``: said after the table's title."""
    claims = _claim_rows(res, codes)
    if not claims:
        return []
    return [
        "",
        "The paper's sentences, checked (`primspace.results.claims`):" + note,
        "",
        table(["the paper (verbatim)", "rule (version): what we test", "verdict", "direction", "earlier rule"], claims),
    ]


def _tune_section(res: dict) -> list[str]:
    """The lines of a summary's tuning table (none where it holds no tune)."""
    if not ("tune" in res and res.get("intra")):
        return []
    tune = res["tune"]
    columns, rows = tuning_table(tune, res["intra"])
    factors = ", ".join(f"{f:.3g}" for f in tune["grid"]["latent_lr_factor"])
    return [
        "",
        f"Fair baselines (`primspace experiment tune`): each init tuned on a validation split carved from "
        f"the fitted part, over the same grid (layer time constants {tune['grid']['taus']}, latent "
        f"learning rate x {factors}) at q = {tune['latent_dim']} and applied at every q, epochs the "
        "preset's for all; the final eval loss with the shared and the tuned setting (mean ± sample std (ddof 1) over "
        "seeds). README's table and the claims use the shared setting (the paper's protocol); this table "
        "says whether a gap survives tuning:",
        "",
        table(columns, [[str(c) for c in row] for row in rows]),
    ]


def final_losses(intra: dict, q: int | None = None) -> dict[str, list[float]]:
    """``{init: [final eval loss per run]}`` of an intra summary at ``q`` (default, or a q
    not run: the largest q)."""
    qs = sorted({r["latent_dim"] for r in intra["runs"]})
    q = q if q in qs else qs[-1]
    out: dict = {}
    for r in intra["runs"]:
        if r["latent_dim"] == q:
            out.setdefault(r["init"], []).append(_last(r["infer"]))
    return out


#: Pairs of summaries shown side by side: (a, b, what differs). Both must be stored.
def _md_table(columns_rows) -> str:
    columns, rows = columns_rows
    return table(columns, [[str(c) for c in row] for row in rows])


def render_composite(summary: dict) -> str:
    """The composite tables of one summary (``primspace experiment composite``): primspace per
    init beside its peers, the upper bounds, and each primitive's recall."""
    co = summary["results"]["composite"]
    preset, cpu = summary.get("preset", {}), summary.get("cpu", {})
    seeds = sorted({r["seed"] for r in co["runs"]})
    out = [
        f"#### {summary['name']}",
        "",
        "```",
        portable_command(summary["command"].strip()),
        "```",
        "",
        f"primspace {summary.get('primspace')}; preset {preset.get('name')}, seeds {', '.join(map(str, seeds))}, "
        f"W = {co.get('window')}, epochs {preset.get('fit_epochs')} + {preset.get('infer_epochs')}; measured on "
        f"{cpu.get('model', '?')}." + (f" {summary['note']}" if summary.get("note") else ""),
        "",
        "Mean ± sample std (ddof 1) over seeds; losses are mean squared errors of the scaled joints of the held-out "
        "demonstrations; boundaries match one-to-one within the tolerance; accuracies are per step (Hungarian). "
        "Peers: " + "; ".join(f"`{k}` {v}" for k, v in PEER_RULES.items()) + ".",
        "",
        _md_table(composite_table(co)),
    ]
    single = primitives_table(co)
    if single is not None:
        out += [
            "",
            "The model of single primitives (synthesis, surprise; same held-out demonstrations, same scores) "
            "and its labeller's bound: each found segment given its nearest template's true primitive:",
            "",
            _md_table(single),
        ]
    bounds, recall = bounds_table(co), recall_table(co)
    if bounds is not None:
        out += [
            "",
            "Upper bounds on the true segments of the same held-out demonstrations (per-step accuracy; "
            "classifiers given the labels, 5-fold stratified cross-validation):",
            "",
            _md_table(bounds),
        ]
    if recall is not None:
        out += ["", "Recall of each primitive by the logistic regression (mean over seeds):", "", _md_table(recall)]
    return "\n".join(out)


def render_scene(summary: dict) -> str:
    """The scene-only table of one summary (of the retired ``primspace experiment scene``)."""
    sc = summary["results"]["scene"]
    seeds = sc.get("seeds") or summary.get("preset", {}).get("seeds", [])
    columns, rows = scene_table(sc)
    return "\n".join(
        [
            f"#### {summary['name']}",
            "",
            "```",
            portable_command(summary["command"].strip()),
            "```",
            "",
            f"q = {sc['latent_dim']}, seeds {', '.join(map(str, seeds))}, {sc['epochs']} inference epochs in the "
            "subspace; n: samples per seed; MSE of the steps after the first (joints scaled to [-1, 1] over the data "
            "set), mean ± sample std (ddof 1) over seeds"
            + ("; success: the share the simulator judges a success." if sc.get("judged") else "."),
            "",
            table(columns, [[str(c) for c in row] for row in rows]),
        ]
    )


def render_predict(summary: dict) -> str:
    """The prediction table of one summary (``primspace experiment predict``); from grid version 4
    on, two (:func:`primspace.report.predict_tables.task_tables`): with the primitive given and without it."""
    pr = summary["results"]["predict"]
    seeds = pr.get("seeds") or summary.get("preset", {}).get("seeds", [])  # summaries before 0.6.1: all of them
    cpu = summary.get("cpu", {})
    head = [
        f"#### {summary['name']}",
        "",
        "```",
        portable_command(summary["command"].strip()),
        "```",
        "",
        f"The experiment directory ran primspace {summary.get('primspace')}; q = {pr['latent_dim']}, seeds {', '.join(map(str, seeds))}, "
        f"{pr['epochs']} inference epochs for the gradient starts; measured on {cpu.get('model', '?')}. MSE of the "
        "unobserved steps (joints scaled to [-1, 1] over the data set), mean ± sample std (ddof 1) over seeds"
        + ("; success: the share of predicted motions the simulator judges a success." if pr.get("judged") else "."),
    ]
    if not splits_tasks(pr):
        columns, rows = predict_error_table(pr)
        return "\n".join(head + ["", table(columns, [[str(c) for c in row] for row in rows])])
    head[-1] += " " + TASKS_TEXT + " " + VERDICT_RULE
    for task in task_tables(pr):
        head += ["", f"##### {task.title}", "", table(task.columns, task.rows), "", task.verdict]
    return "\n".join(head)
