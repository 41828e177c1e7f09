"""The numbers of README, docs/results.md, docs/predict.md, docs/sequences.md, docs/act.md and
docs/reproduce.md, written from the stored summaries.

``python -m primspace.report.markdown`` (``make docs``) reads every ``docs/results/*.json``
(experiment summaries, :mod:`primspace.results.summary`) and rewrites the generated
blocks of README.md (the results at a glance), docs/results.md (the tables per summary,
and the numbers its prose discusses), docs/predict.md (prediction, scene),
docs/real.md (the intra protocol on real recordings, :mod:`primspace.report.real_tables`),
docs/sequences.md (composite segmentation, and its synthesis at a glance; the blocks
behind the prose: :mod:`primspace.report.prose_numbers`) and
docs/act.md (acting from the scene and in closed loop, :func:`render_act`) and docs/reproduce.md
(the paper's own setting and the clustering ablation, :mod:`primspace.report.reproduce_blocks`): the text between ``<!-- generated: NAME -->`` and ``<!-- end generated: NAME -->``.
``--check`` writes nothing and exits 1 when a block differs from what it would write
(tests/test_docs_generated.py runs it). Everything else in those files is prose, written
by hand around the blocks.

This is the markdown counterpart of the HTML report (:mod:`primspace.report.build`): the
report shows one experiment directory, these blocks every stored summary.
:mod:`primspace.report.summary_tables` renders one summary; this module says which
summary goes where, renders README's table, and writes the files.

What is generated: per summary, the losses (mean ± sample std over seeds, ddof 1, and
the per-seed range), success rates (mean ± sample std over seeds, and the pooled rate
with its Wilson 95 % interval), clustering accuracies, the inter folds, the tuned
baselines, and the paper's claims with each rule's version, threshold, per-seed
verdicts, the judge-tolerance sweep and the earlier rule's verdict; and README's table
of results at a glance. Each page states the convention of its spreads once, atop its
first block with numbers (:func:`primspace.utils.stats.spread_convention`).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from primspace.report.commands import portable_command
from primspace.report.comparisons import COMPARISONS, merged, render_comparison, side_names
from primspace.report.prose_numbers import render_composite_glance, render_differ
from primspace.report.real_tables import is_real, render_real
from primspace.report.regime_tables import figure_path, regime_figure, render_regime
from primspace.report.reproduce_blocks import (
    ABLATION,
    ablation,
    clustering_ablation,
    clustering_gaps,
    load_balances,
    paper_setting,
)
from primspace.report.summary_tables import (
    final_losses,
    g,
    mean_spread,
    outcome_rows,
    render_composite,
    render_predict,
    render_scene,
    render_summary,
    table,
)
from primspace.results.act import act_latency_text, act_tables, every_text, move_text
from primspace.results.claims import check_claims
from primspace.results.summary import read_summary
from primspace.results.tables import projection_lead
from primspace.utils.stats import spread_convention

__all__ = [
    "merged",
    "clustering_gaps",
    "clustering_ablation",
    "g",
    "mean_spread",
    "render_summary",
    "render_comparison",
    "render_composite",
    "render_scene",
    "render_predict",
    "render_act",
    "NO_ACT",
    "glance",
    "blocks",
    "replace_blocks",
    "load_summaries",
    "main",
    "SUMMARY_DIR",
    "TARGETS",
    "ORDER",
    "TUNED_IN",
]

#: Where the summaries are kept, relative to the repository.
SUMMARY_DIR = Path("docs") / "results"

#: Each generated block: the file it lives in.
TARGETS = {
    "glance": Path("README.md"),
    "results": Path("docs") / "results.md",
    "differ": Path("docs") / "results.md",
    "predict": Path("docs") / "predict.md",
    "scene": Path("docs") / "predict.md",
    "regime": Path("docs") / "predict.md",
    "composite": Path("docs") / "sequences.md",
    "composite-glance": Path("docs") / "sequences.md",
    "act": Path("docs") / "act.md",
    "real": Path("docs") / "real.md",
    "ablation": Path("docs") / "reproduce.md",
    "paper-setting": Path("docs") / "reproduce.md",
}

#: The act block while no stored summary holds act results.
NO_ACT = "No act summary is committed yet."

#: The order summaries are shown in (others follow, by name); README's table shows these only.
ORDER = ("paper", "paper-q10-20", "paper-q10", "paper-images", "demo", "lasa")

#: Summaries whose baselines were tuned in another experiment directory (the tune's
#: shared-setting runs are copies of this summary's): README's table reads the tune from
#: there, and docs/results.md shows only that summary's tuning table (not the copies again).
TUNED_IN = {"paper-q10-20": "paper-tune20"}

#: What the demo preset's verdicts are (126 motions, a few hundred epochs, every init at
#: 0.12-0.14 success): they show that the checks run, not what the paper's claims do.
SMOKE_TEST = " (a smoke test, not evidence)"

#: The experiments docs/results.md shows (a summary holding none of them is shown elsewhere only).
_REPRODUCED = {"intra", "success", "clustering", "inter", "tune"}

_GLANCE_COLUMNS = [
    "summary",
    "seeds",
    "q",
    "eval loss: projection",
    "zero",
    "success: projection",
    "zero",
    "clustering: projection",
    "zero",
    "tuned: projection below zero / pca",
    "paper's sentences holding",
]


def glance(summaries: dict[str, dict]) -> str:
    """README's results at a glance: one row per summary of :data:`ORDER` with intra runs.

    Columns: projection's and zero's final eval loss at the largest q (mean ± sample std
    over seeds, and the 95 % t-interval half-width); their success in the simulator and
    the clustering accuracy of their codes,
    where run; where the baselines were tuned (here or in the summary :data:`TUNED_IN`
    names), in how many seeds projection ends below zero and below pca with every init
    tuned; and how many of the paper's sentences checked hold in every seed."""
    rows = []
    for name, s in summaries.items():
        intra = s["results"].get("intra")
        if name not in ORDER or not intra:
            continue  # ablations (other losses, tuning alone) stay in docs/results.md
        by = final_losses(intra)
        outcomes = {row[0]: row for row in outcome_rows(s["results"])}

        def outcome(init: str, column: int) -> str:
            return outcomes[init][column].split(";")[0].split(" [")[0] if init in outcomes else "—"

        success, clustering = bool(s["results"].get("success")), bool(s["results"].get("clustering"))
        verdicts = [r for r in check_claims(s["results"]) if r["verdict"] not in ("not run", "cannot be checked")]
        held = sum(r["verdict"].startswith("holds in every") or r["verdict"] == "holds" for r in verdicts)
        rows.append(
            [
                f"*{name}*",
                str(len(by.get("projection", []))),
                str(max(r["latent_dim"] for r in intra["runs"])),
                *(mean_spread(by.get(i, []), rng=False, ci=True) for i in ("projection", "zero")),
                *(outcome(i, 2) if success else "—" for i in ("projection", "zero")),
                *(outcome(i, 4) if clustering else "—" for i in ("projection", "zero")),
                _tuned_cell(summaries.get(TUNED_IN.get(name, name), {})),
                f"{held} of {len(verdicts)}" + (SMOKE_TEST if s.get("preset", {}).get("name") == "demo" else ""),
            ]
        )
    if not rows:
        return "No stored summaries yet (docs/results/)."
    return spread_convention() + "\n\n" + table(_GLANCE_COLUMNS, rows)


def _tuned_cell(summary: dict) -> str:
    """In how many seeds projection ends below zero and below pca at the tuned q with every
    init tuned on a validation split (``—`` where ``summary`` holds no tune)."""
    tune = summary.get("results", {}).get("tune")
    if not tune:
        return "—"
    leads = [
        projection_lead(tune, summary["results"].get("intra"), init)["tuned"]
        for init in ("zero", "pca")
        if init in tune["chosen"]
    ]
    return " / ".join(leads) + f" (q = {tune['latent_dim']})"


def render_act(summary: dict) -> str:
    """The act tables of one summary (``primspace experiment act``): scene-only success and error,
    success with the block moved, and the closed loop's latency."""
    act = summary["results"]["act"]
    seeds = act.get("seeds") or sorted(int(s) for s in act.get("by_seed", {}))
    move = act.get("perturbation") or {}
    lo, hi = move.get("distance_m", [0.02, 0.04])
    n_test = sorted({r.get("n_test") for r in act.get("by_seed", {}).values() if r.get("n_test") is not None})
    lines = [f"#### {summary['name']}", "", "```", portable_command(summary["command"].strip()), "```", ""]
    lines.append(
        f"q = {act['latent_dim']}, seeds {', '.join(map(str, seeds))}"
        + (f" ({' or '.join(map(str, n_test))} scenes each)" if n_test else "")
        + f"; the block moved {100 * lo:g}-{100 * hi:g} cm at {move_text(act)} of the motion, the closed loop "
        f"re-asked {every_text(act)}; mean ± sample std (ddof 1) over seeds."
    )
    for title, columns, rows in act_tables(act):
        lines += ["", f"**{title}**", "", table(columns, [[str(c) for c in row] for row in rows])]
    lines += ["", act_latency_text(act)]
    if act.get("failures"):
        lines += ["", f"{len(act['failures'])} point(s) failed: {', '.join(act['failures'])}."]
    return "\n".join(lines)


def load_summaries(root: Path) -> dict[str, dict]:
    """The stored summaries by name, in :data:`ORDER`."""
    found = {s["name"]: s for s in (read_summary(p) for p in sorted((root / SUMMARY_DIR).glob("*.json")))}
    return {n: found[n] for n in sorted(found, key=lambda n: (ORDER.index(n) if n in ORDER else len(ORDER), n))}


def blocks(summaries: dict[str, dict], balances: dict[str, dict] | None = None) -> dict[str, str]:
    """The text of every generated block, by block name (:data:`TARGETS`); ``balances``: the
    stored loss-balance measurements (:func:`primspace.report.reproduce_blocks.load_balances`)."""
    tune_only = {tuned for source, tuned in TUNED_IN.items() if source in summaries}
    parts = [
        render_summary(s, s["name"] in tune_only)
        for s in summaries.values()
        if set(s["results"]) & _REPRODUCED and not is_real(s)  # the real preset's: docs/real.md
    ]
    parts += [
        render_comparison(merged(summaries, a), merged(summaries, b), what)
        + ("\n\n" + clustering_ablation(merged(summaries, a), merged(summaries, b)) if a == ABLATION[0] else "")
        for a, b, what in COMPARISONS
        if all(n in summaries for n in side_names(a) + side_names(b))
    ]
    note = spread_convention() + "\n\n"  # once per page: atop its first block with numbers
    predicted = "\n\n".join(render_predict(s) for s in summaries.values() if "predict" in s["results"])
    scene = "\n\n".join(render_scene(s) for s in summaries.values() if "scene" in s["results"])
    composite = "\n\n".join(render_composite(s) for s in summaries.values() if "composite" in s["results"])
    act = "\n\n".join(render_act(s) for s in summaries.values() if "act" in s["results"])
    regime = "\n\n".join(render_regime(s) for s in summaries.values() if "regime" in s["results"])
    if scene and not predicted:
        scene = note + scene  # docs/predict.md's first block with numbers
    return {
        "glance": glance(summaries),
        "results": note + "\n\n".join(parts) if parts else "No stored summaries yet (docs/results/).",
        "predict": note + predicted if predicted else "No stored prediction summaries yet (docs/results/).",
        "scene": scene or "No stored scene-only summaries yet (docs/results/).",
        "regime": regime or "No stored regime summaries yet (docs/results/).",
        "composite": note + composite if composite else "No stored composite summaries yet (docs/results/).",
        "composite-glance": render_composite_glance(summaries),
        "differ": render_differ(summaries),
        "act": note + act if act else NO_ACT,
        "ablation": ablation(summaries),
        "paper-setting": paper_setting(summaries, balances),
        "real": render_real(summaries),
    }


def replace_blocks(text: str, new: dict[str, str], path: Path | str = "") -> str:
    """``text`` with the block of each name in ``new`` replaced (markers kept)."""
    for name, body in new.items():
        pattern = re.compile(
            rf"(<!-- generated: {re.escape(name)} -->\n)(.*?)(<!-- end generated: {re.escape(name)} -->)", re.S
        )
        if not pattern.search(text):
            raise ValueError(
                f"{path}: no generated block {name!r} (markers <!-- generated: {name} --> ... "
                f"<!-- end generated: {name} -->)"
            )
        text = pattern.sub(lambda m: m.group(1) + body.rstrip("\n") + "\n" + m.group(3), text, count=1)
    return text


def main(argv: list[str] | None = None) -> int:
    """Rewrite (or with ``--check``, compare) every generated block; the exit status."""
    parser = argparse.ArgumentParser(prog="python -m primspace.report.markdown", description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path("."), help="the repository (default: here)")
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a block differs")
    args = parser.parse_args(argv)
    summaries = load_summaries(args.root)
    new = blocks(summaries, load_balances(args.root / SUMMARY_DIR))
    stale = _regime_figures(summaries, args.root, args.check)
    for target in dict.fromkeys(TARGETS.values()):
        path = args.root / target
        text = path.read_text(encoding="utf-8")
        wanted = replace_blocks(text, {k: v for k, v in new.items() if TARGETS[k] == target}, path)
        if wanted != text:
            stale.append(str(target))
            if not args.check:
                tmp = path.with_name(path.name + ".tmp")
                tmp.write_text(wanted, encoding="utf-8")
                tmp.replace(path)
    if args.check and stale:
        print(f"stale generated text in {', '.join(stale)}: run python -m primspace.report.markdown", file=sys.stderr)
        return 1
    print(("rewrote " + ", ".join(stale)) if stale else "generated text is up to date")
    return 0


def _regime_figures(summaries: dict[str, dict], root: Path, check: bool) -> list[str]:
    """Draw each regime summary's figure (:func:`~primspace.report.regime_tables.figure_path`); with ``check``
    draw nothing and return those missing."""
    missing = []
    for name, summary in summaries.items():
        if "regime" in summary["results"]:
            path = root / figure_path(name)
            if check and not path.is_file():
                missing.append(str(figure_path(name)))
            elif not check:
                regime_figure(summary, path)
    return missing


if __name__ == "__main__":
    sys.exit(main())
