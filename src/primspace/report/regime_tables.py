"""The regime of few demonstrations in docs/predict.md: its tables, the hypothesis's verdict, the
crossing point and the figure, from a stored summary's ``regime`` results.

:func:`render_regime` writes one summary's block (the command, the settings, per task the MSE and
success at 25 % observed against ``n``, the mixed variant beside the run with every primitive at
its few, the crossing point at each fraction, and the verdict of
:mod:`primspace.results.claim_rules_regime`); :func:`regime_figure` draws its error against ``n``
(log-log) and :func:`figure_path` names the figure docs/predict.md shows.
"""

from __future__ import annotations

from pathlib import Path

from primspace.report.commands import portable_command
from primspace.results.claim_rules_regime import check_regime
from primspace.results.layout import file_stem
from primspace.results.regime import METRICS, MODEL_ROWS, TASKS, comparisons, crossing, regime_panels, seed_crossings
from primspace.results.regime import task_rows as rows_of
from primspace.results.tables import cell_text

__all__ = ["render_regime", "regime_figure", "figure_path", "FIGURE_DIR", "crossing_text"]

#: Where the docs' figures are, relative to the repository.
FIGURE_DIR = Path("docs") / "figures"


def figure_path(name: str) -> Path:
    """The figure of summary ``name``, relative to the repository: ``docs/figures/<name>_error_vs_n.png``."""
    return FIGURE_DIR / f"{file_stem(name)}_error_vs_n.png"


def regime_figure(summary: dict, path: str | Path) -> None:
    """Draw ``summary``'s MSE (and success, where judged) at 25 % observed against ``n``, log-log, into ``path``."""
    from primspace.plots import save_figure
    from primspace.plots.regime import plot_error_against_n

    regime = summary["results"]["regime"]
    save_figure(
        plot_error_against_n(regime_panels(regime, "mse"), title=f"{summary['name']}: mean ± std over seeds"),
        Path(path),
    )


def _row(regime: dict, row: str, key: str, metric: str, ns: list[str]) -> list[str]:
    cells = regime["table"].get(row, {})
    digits = 3 if metric == "mse" else 2
    return [row] + [cell_text(cells.get(n, {}).get(key, {}).get(metric), digits) for n in ns]


def _share(regime: dict, row: str, key: str, ns: list[str]) -> str:
    cells = regime["table"].get(row, {})
    shares = [cells.get(n, {}).get(key, {}).get("model_share") for n in ns]
    values = [f"{s[0]:.2g}" for s in shares if s]
    return " / ".join(values) if len(set(values)) > 1 else (values[0] if values else "–")


def _task_table(regime: dict, task: str, metric: str, fraction: float) -> list[str]:
    key, ns = f"{fraction:g}", [str(n) for n in regime["fitted_per_primitive"]]
    rows = [_row(regime, row, key, metric, ns) + [_share(regime, row, key, ns)] for row in rows_of(regime, task)]
    columns = ["method"] + [f"n = {n}" for n in ns] + ["model share (by n)"]
    title = f"**{TASKS[task].capitalize()}: {'MSE' if metric == 'mse' else 'success'} at {fraction:.0%} observed**"
    return ["", title, "", _table(columns, rows)]


def _table(columns: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows])


def crossing_text(regime: dict, task: str, metric: str, fraction: float) -> str:
    """The crossing point of ``task`` and ``metric`` at ``fraction``: the ``n`` up to which the model's row
    beats the best peer by more than both spreads, with the first ``n`` where it does not, and each seed's."""
    compared = comparisons(regime, task, metric, fraction)
    if not compared:
        return "not measured"
    last = crossing(compared)
    after = next((n for n, c in compared.items() if c["verdict"] != "holds"), None)
    text = "none (the model does not win at the smallest n)" if last is None else f"wins up to n = {last}"
    if after is not None:
        c = compared[after]
        text += f"; at n = {after} it {c['verdict'].replace('holds', 'wins')} against {c['peer']}"
    text += "; by n: " + ", ".join(f"{n} {c['verdict'].replace('holds', 'wins')}" for n, c in compared.items())
    seeds = seed_crossings(regime, task, metric, fraction)
    if len(seeds) > 1:
        text += "; seed by seed: " + ", ".join(f"{s}: {'none' if v is None else v}" for s, v in seeds.items())
    return text


def _mixed(regime: dict, fraction: float) -> list[str]:
    mixed, key = regime.get("mixed") or {}, f"{fraction:g}"
    if not mixed:
        return []
    few, many = regime.get("mixed_few", 2), max(regime["fitted_per_primitive"])
    rows = []
    for row in regime["table"]:
        cell = mixed.get(row, {}).get(key, {})
        rows.append(
            [row]
            + [
                cell_text(cell.get(part, {}).get(m), 3 if m == "mse" else 2)
                for m, _ in METRICS
                for part in ("alone", "mixed")
            ]
        )
    columns = [
        "method",
        f"MSE, all at n = {few}",
        f"MSE, others at n = {many}",
        f"success, all at {few}",
        f"success, others at {many}",
    ]
    title = (
        f"**One primitive with n = {few} among primitives with n = {many}** (its evaluation motions only, "
        f"{fraction:.0%} observed; the primitive: each seed's in turn)"
    )
    return ["", title, "", _table(columns, rows)]


def _settings_text(settings: dict) -> str:
    return "; ".join(f"{kind} {', '.join(f'{k} = {v}' for k, v in kw.items())}" for kind, kw in settings.items())


def render_regime(summary: dict) -> str:
    """One summary's regime block (module docstring)."""
    regime = summary["results"]["regime"]
    seeds = sorted(int(s) for s in regime.get("by_seed", {}))
    n_eval = sorted({s.get("n_eval") for s in regime.get("by_seed", {}).values()})
    cap = regime.get("eval_per_primitive")
    lines = [f"#### {summary['name']}", "", "```", portable_command(summary["command"].strip()), "```", ""]
    lines.append(
        f"q = {regime['latent_dim']}, seeds {', '.join(map(str, seeds))}; n = "
        f"{', '.join(map(str, regime['fitted_per_primitive']))} fitted demonstrations per primitive (nested subsets "
        f"of the fitted split, {regime['train_fraction']:g} of each primitive); the same "
        f"{' or '.join(map(str, n_eval))} evaluation motions for every n"
        + (f" (at most {cap} per primitive)" if cap else " (the whole evaluation split)")
        + f"; measured on {summary.get('cpu', {}).get('model', 'an unrecorded CPU')}"
        + " (times: docs/reproduce.md). Mean ± sample std (ddof 1) over seeds; with one seed there is no spread, and "
        "a comparison holds when the model's number is better at all."
        + (f" Note: {summary['note']}." if summary.get("note") else "")
        + (f" The rows' settings: {_settings_text(regime['settings'])}." if regime.get("settings") else "")
    )
    metrics = [m for m, _ in METRICS if m != "success" or regime.get("judged")]
    for task in TASKS:
        for metric in metrics:
            lines += _task_table(regime, task, metric, 0.25)
    lines += _mixed(regime, 0.25)
    lines += ["", f"**Crossing points** ({', '.join(MODEL_ROWS.values())} against the best peer row of its task):", ""]
    for task in TASKS:
        for metric in metrics:
            for fraction in regime["fractions"]:
                lines.append(
                    f"- {TASKS[task]}, {'MSE' if metric == 'mse' else metric} at {fraction:.0%}: {crossing_text(regime, task, metric, fraction)}"
                )
    row = check_regime(regime)
    lines += ["", f"**Hypothesis** (written before the runs): {row['hypothesis']}", "", f"Rule {row['rule']}.", ""]
    lines.append(f"Verdict: **{row['verdict']}** ({row['ours']}).")
    if regime.get("failures"):
        lines += ["", f"{len(regime['failures'])} point(s) failed: {', '.join(regime['failures'])}."]
    lines += ["", f"![error against n, {summary['name']}](figures/{figure_path(summary['name']).name})"]
    return "\n".join(lines)
