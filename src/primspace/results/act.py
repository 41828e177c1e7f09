"""The act experiment's tables (:mod:`primspace.experiments.act`; docs/act.md).

Read by the command line, the HTML report (:mod:`primspace.report.act_section`) and the
generated block of docs/act.md (:mod:`primspace.report.markdown`) from an ``act`` result: an
experiment directory's ``results/act.json`` or a stored summary's (which keeps ``table``,
``scene_rows``, ``loop_rows`` and ``by_seed``'s small entries). One place turns its numbers
into rows, so the three show the same tables. Numbers are mean ± std over seeds (ddof 1).

This module imports no experiment (the report may import it).
"""

from __future__ import annotations

from primspace.results.tables import cell_text

__all__ = ["ALL", "act_tables", "act_table", "act_latency_text"]

#: The column (and ``by_seed`` entry) of every primitive together.
ALL = "all"


def _wide(part: dict, rows: list, metric: str) -> tuple[list[str], list[list]]:
    """Rows ``rows`` of ``part`` by primitive (columns, then "all"): ``metric`` mean ± std over seeds."""
    names = [p for p in dict.fromkeys(p for r in rows if r in part for p in part[r]) if p != ALL] + [ALL]
    out = []
    for row in [r for r in rows if r in part]:
        out.append([row] + [cell_text(part[row].get(p, {}).get(metric), digits=2) for p in names])
    return ["method"] + names, out


def act_tables(results: dict) -> list[tuple[str, list[str], list[list]]]:
    """The act experiment's tables as ``(title, columns, rows)``: scene-only success, scene-only
    MSE after the first step, closed-loop success, and (where recorded) closed-loop success on the
    episodes whose open loop fails (mean ± std over seeds, ddof 1)."""
    table = results["table"]
    scene_rows = results.get("scene_rows") or list(table["scene"])
    loop_rows = results.get("loop_rows") or list(table["loop"])
    seeds = len(results["by_seed"])
    return [
        (f"Scene only: success ({seeds} seeds)", *_wide(table["scene"], scene_rows, "success")),
        (
            f"Scene only: MSE of the steps after the first, scaled ({seeds} seeds)",
            *_wide(table["scene"], scene_rows, "mse"),
        ),
        (f"Block moved at 30 %: success ({seeds} seeds)", *_wide(table["loop"], loop_rows, "success")),
    ] + (
        [
            (
                f"Block moved at 30 %, the episodes whose open-loop replay fails: success ({seeds} seeds)",
                *_wide(table["where_open_fails"], loop_rows, "success"),
            )
        ]
        if table.get("where_open_fails")
        else []
    )


def act_table(results: dict) -> tuple[list[str], list[list]]:
    """The scene-only and closed-loop success over all primitives, one row per method."""
    table = results["table"]
    rows = [[f"scene only: {r}", cell_text(table["scene"][r][ALL].get("success"), digits=2)] for r in table["scene"]]
    rows += [[f"moved at 30 %: {r}", cell_text(table["loop"][r][ALL].get("success"), digits=2)] for r in table["loop"]]
    return ["method", "success (all primitives)"], rows


def act_latency_text(results: dict) -> str:
    """One sentence on the closed loop's plan latency: the per-seed median, mean ± std over
    seeds, and the largest p95 and max of the seeds."""
    cell = results["table"].get("latency_ms")
    if not cell:
        return "Latency of a plan: not measured."
    seeds = [s.get("latency_ms") or {} for s in results["by_seed"].values()]
    worst = [
        f"{key} up to {max(v[key] for v in seeds if v.get(key) is not None):.3g} ms"
        for key in ("p95", "max")
        if any(v.get(key) is not None for v in seeds)
    ]
    return (
        f"Latency of a plan in closed loop (features, map, continuity; wall time in the experiment's process): "
        f"median {cell_text(cell, digits=3)} ms over seeds" + (f" ({', '.join(worst)})" if worst else "") + "."
    )
