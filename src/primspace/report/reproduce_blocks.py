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

import json
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from primspace.report.comparisons import merged, render_comparison, side_names
from primspace.report.summary_tables import g, mean_spread, table
from primspace.results.layout import LEARNED_CODES
from primspace.utils.stats import sample_std, wilson_interval

__all__ = [
    "PAPER_SETTING",
    "ABLATION",
    "clustering_gaps",
    "clustering_ablation",
    "ablation",
    "success_by_primitive",
    "paper_setting",
    "load_balances",
    "balance_tables",
    "setting_verdicts",
    "BALANCE_DIR",
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


def paper_setting(summaries: dict[str, dict], balances: dict[str, dict] | None = None) -> str:
    """docs/reproduce.md's block on the paper's own setting: each pair of :data:`PAPER_SETTING`
    that is stored, as a comparison (errors per element, success, clustering), then success
    per primitive of every stored summary of the pairs; the loss-balance measurements
    (``balances``, :func:`load_balances`) and the section's rules (:func:`setting_verdicts`)."""
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
    if balances:
        parts.append(balance_tables(balances))
    verdicts = setting_verdicts(summaries, balances or {})
    if verdicts:
        parts.append("**The rules** (written before the run, above):\n\n" + "\n".join(verdicts))
    if missing:
        parts.append(f"Not stored yet: {', '.join(dict.fromkeys(missing))}.")
    return "\n\n".join(parts)


#: Where the loss-balance measurements (``primspace diagnose loss-balance --json``) are kept,
#: one file per setting: ``{"command": ..., "runs": {name: the command's JSON}}``.
BALANCE_DIR = "balance"

#: The rules of docs/reproduce.md's paper-setting section (written before the run).
MOTOR_FIT_FACTOR = 10.0  # the summed loss's fit motor error at least this many times ours
VISION_GRADIENT_FACTOR = 10.0  # the vision term's θ-gradient at least this many times the motor term's
OPPOSED_COSINE = -0.5  # ... or the two θ-gradients opposed at least this much


def load_balances(results_dir) -> dict[str, dict]:
    """The stored loss-balance files of ``results_dir / BALANCE_DIR``, by file stem."""
    folder = Path(results_dir) / BALANCE_DIR
    return {p.stem: json.loads(p.read_text(encoding="utf-8")) for p in sorted(folder.glob("*.json"))}


def _joint_rms(b: dict) -> list[float]:
    """RMS per joint over every sample (the per-primitive RMS weighted by the primitives' sizes)."""
    values = np.asarray(b["joint_rms"]["values"], dtype=float)
    n = np.asarray([b["per_primitive"][p]["n"] for p in b["primitives"]], dtype=float)
    return list(np.sqrt((n[:, None] * values**2).sum(0) / n.sum()))


def balance_tables(balances: dict[str, dict]) -> str:
    """Per measured run: the motor error, the vision term's share of the loss and of the
    θ- and code-gradients, the cosine of the two terms' θ-gradients; then the motor RMS
    per primitive and per joint (radians)."""
    runs = {f"{setting}: {name}": b for setting, f in balances.items() for name, b in f["runs"].items()}
    if not runs:
        return ""
    rows, prims, joints = [], [], []
    for name, b in runs.items():
        th, co = b.get("gradients", {}).get("theta", {}), b.get("gradients", {}).get("codes", {})
        ratio, cos = th.get("vision_over_motor", {}).get("all"), th.get("cosine", {}).get("all")
        code_ratio, code_cos = co.get("vision_over_motor_median"), co.get("cosine")
        rows.append(
            [name, b["loss_reduction"], g(b["mse"]["motor"]), g(b["motor_rms"]), f"{100 * b['vision_share']:.1f} %"]
            + [f"{ratio:.0f}x" if ratio is not None else "—", g(cos), f"{code_ratio:.0f}x" if code_ratio else "—"]
            + [g(code_cos)]
        )
        prims.append([name] + [g(b["per_primitive"][p]["motor_rms"]) for p in b["primitives"]])
        joints.append([name] + [g(v) for v in _joint_rms(b)])
    first = next(iter(runs.values()))
    columns = ["run", "loss", "motor MSE (scaled)", "motor RMS (rad)", "vision share of the loss"]
    columns += ["θ-gradient vision / motor", "cosine of the θ-gradients", "code gradient vision / motor"]
    columns += ["cosine of the code gradients"]
    short = [j.rsplit(":", 1)[-1].split("_", 1)[-1] if "panda" in j else j for j in first["joints"]]
    return "\n\n".join(
        [
            "**The loss's two terms at the end of each run** (`primspace diagnose loss-balance`; gradients over "
            "the run's own samples; '—': no vision term)",
            table(columns, rows),
            "**Motor RMS per primitive** (rad)",
            table(["run", *first["primitives"]], prims),
            "**Motor RMS per joint** (rad, over every sample)",
            table(["run", *short], joints),
        ]
    )


def _pooled(summary: dict) -> tuple[int, int]:
    """Projection's successes and trials in the simulator, pooled over seeds: ``(k, n)``."""
    success = summary["results"].get("success") or {}
    k = n = 0
    for gen in [success.get("generated", {})] + list(success.get("by_seed", {}).values()):
        p = gen.get("projection")
        if p:
            k += sum((p.get("successes") or {q: round(p["rates"][q] * c) for q, c in p["counts"].items()}).values())
            n += sum(p["counts"].values())
    return k, n


def setting_verdicts(summaries: dict[str, dict], balances: dict[str, dict]) -> list[str]:
    """The three rules of docs/reproduce.md's paper-setting section, on projection's runs
    (:data:`PAPER_SETTING`'s first pair; the balances ``paper-adam40`` (ours) and
    ``paper-sum40``): does success collapse, does the motor fit explain it, does the vision
    term hold the motor fit back? A rule whose numbers are not stored says so."""
    ours, theirs, _ = PAPER_SETTING[0]
    out = []
    if ours in summaries and theirs in summaries and _pooled(summaries[theirs])[1]:
        (k0, n0), (k1, n1) = _pooled(summaries[ours]), _pooled(summaries[theirs])
        (lo0, hi0), (lo1, hi1) = wilson_interval(k0, n0), wilson_interval(k1, n1)
        verdict = "collapses" if hi1 < lo0 else "does not collapse"
        out.append(
            f"- Success under the summed loss {verdict}: projection {k1 / n1:.2f} [{lo1:.2f}, {hi1:.2f}] against "
            f"ours {k0 / n0:.2f} [{lo0:.2f}, {hi0:.2f}] (pooled over seeds, Wilson 95 %)."
        )
    sum_fit = balances.get(theirs, {}).get("runs", {}).get("projection fit")
    our_fit = balances.get("paper-adam40", {}).get("runs", {}).get("projection fit")
    if sum_fit and our_fit:
        factor = sum_fit["mse"]["motor"] / our_fit["mse"]["motor"]
        text = f"- The fit's motor error under the summed loss is {factor:.0f}x ours (projection, the fitted samples)"
        success = summaries.get(theirs, {}).get("results", {}).get("success")
        judged = balances[theirs]["runs"].get("projection infer", sum_fit)  # the samples success judged, where stored
        if success:
            names = judged["primitives"]
            rates = {p: np.mean([g_["projection"]["rates"][p] for g_ in _generated(success)]) for p in names}
            rho = spearmanr(
                [rates[p] for p in names], [judged["per_primitive"][p]["motor_rms"] for p in names]
            ).statistic
            explains = factor >= MOTOR_FIT_FACTOR and rho <= -0.5
            samples = {"fit": "the fitted samples", "infer": "the inferred samples, those judged"}[judged["kind"]]
            text += (
                f"; rank correlation of the primitives' success with their motor RMS ({samples}) {rho:.2f}: by the "
                f"rule the motor fit {'explains' if explains else 'does not explain'} the collapse"
                + (
                    ""
                    if explains or factor < MOTOR_FIT_FACTOR
                    else " (the error is there, but the primitives that fail most are not those with the largest error)"
                )
            )
        out.append(text + ".")
        th = sum_fit.get("gradients", {}).get("theta", {})
        ratio, cos = th.get("vision_over_motor", {}).get("all"), th.get("cosine", {}).get("all")
        if ratio is not None and cos is not None:
            held = ratio >= VISION_GRADIENT_FACTOR or cos <= OPPOSED_COSINE
            out.append(
                f"- At the end of fitting the vision term's θ-gradient is {ratio:.0f}x the motor term's, cosine "
                f"{cos:.2f}: the vision term {'holds' if held else 'does not hold'} the motor fit back."
            )
    return out


def _generated(success: dict) -> list[dict]:
    return [
        gen for gen in [success.get("generated", {})] + list(success.get("by_seed", {}).values()) if "projection" in gen
    ]
