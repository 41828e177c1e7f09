"""The act experiment's tables (:mod:`primspace.experiments.act`; docs/act.md).

Read by the command line, the HTML report (:mod:`primspace.report.act_section`) and the
generated block of docs/act.md (:mod:`primspace.report.markdown`) from an ``act`` result: an
experiment directory's ``results/act.json`` or a stored summary's (which keeps ``table``,
``scene_rows``, ``loop_rows`` and ``by_seed``'s small entries). One place turns its numbers
into rows, so the three show the same tables. Numbers are mean ± std over seeds (ddof 1). Where
the results record each row's ``model_share`` (the share of its motion through the run's decoder),
every table ends with a "model share" column, and a row at 0 is marked :data:`NO_MODEL`, as the
prediction tables do (:mod:`primspace.report.predict_tables`).

This module imports no experiment (the report may import it).
"""

from __future__ import annotations

from primspace.results.tables import cell_text

__all__ = ["ALL", "NO_MODEL", "act_tables", "act_table", "act_latency_text", "share_text", "move_text", "every_text"]

#: The column (and ``by_seed`` entry) of every primitive together.
ALL = "all"
#: The mark of a row whose motion does not come through the run's decoder (model share 0); the
#: prediction tables' mark (:data:`primspace.report.predict_tables.NO_MODEL`).
NO_MODEL = "does not use the model"


def share_text(cells: dict) -> str:
    """A row's model share (its ``"all"`` cell's mean over seeds), with :data:`NO_MODEL` at 0; "" when
    not recorded (results before act version 4)."""
    cell = cells.get(ALL, {}).get("model_share")
    if not cell:
        return ""
    return f"{cell[0]:.2g} ({NO_MODEL})" if cell[0] == 0 else f"{cell[0]:.2g}"


def _wide(part: dict, rows: list, metric: str) -> tuple[list[str], list[list]]:
    """Rows ``rows`` of ``part`` by primitive (columns, then "all"): ``metric`` mean ± std over seeds;
    then the model share where recorded (:func:`share_text`)."""
    names = [p for p in dict.fromkeys(p for r in rows if r in part for p in part[r]) if p != ALL] + [ALL]
    kept = [r for r in rows if r in part]
    out = [[row] + [cell_text(part[row].get(p, {}).get(metric), digits=2) for p in names] for row in kept]
    shares = [share_text(part[row]) for row in kept]
    if not any(shares):
        return ["method"] + names, out
    return ["method"] + names + ["model share"], [row + [share] for row, share in zip(out, shares)]


def move_text(results: dict) -> str:
    """When the block is moved: ``"20 % and 30 %"`` (the recorded fractions), ``"30 %"`` before act version 5."""
    at = (results.get("perturbation") or {}).get("at", 0.3)
    return " and ".join(f"{100 * float(a):g} %" for a in (at if isinstance(at, list) else [at]))


def every_text(results: dict) -> str:
    """How often the closed loop looks: ``"every 3 steps"``, or, tuned, the interval each seed's fitted
    demonstrations chose."""
    every = results.get("every", "?")
    if every != "tuned":
        return f"every {every} steps"
    chosen = [(r.get("loop_settings") or {}).get("every") for r in results.get("by_seed", {}).values()]
    return (
        "at the interval chosen on each seed's fitted demonstrations (every " + ", ".join(map(str, chosen)) + " steps)"
    )


def _moved_title(results: dict) -> str:
    """The closed-loop tables' title: the fractions of the move where the results record them (act version 5)."""
    return f"Block moved at {move_text(results)}"


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
        (f"{_moved_title(results)}: success ({seeds} seeds)", *_wide(table["loop"], loop_rows, "success")),
    ] + (
        [
            (
                f"{_moved_title(results)}, the episodes whose open-loop replay fails: success ({seeds} seeds)",
                *_wide(table["where_open_fails"], loop_rows, "success"),
            )
        ]
        if table.get("where_open_fails")
        else []
    )


def act_table(results: dict) -> tuple[list[str], list[list]]:
    """The scene-only and closed-loop success over all primitives, one row per method, and each row's
    model share where recorded."""
    table = results["table"]
    rows = [
        [f"{label}: {r}", cell_text(table[part][r][ALL].get("success"), digits=2), share_text(table[part][r])]
        for part, label in (
            ("scene", "scene only"),
            ("loop", "closed loop" if "move_at" in results else "moved at 30 %"),
        )
        for r in table[part]
    ]
    if not any(row[2] for row in rows):
        return ["method", "success (all primitives)"], [row[:2] for row in rows]
    return ["method", "success (all primitives)", "model share"], rows


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
