"""The prediction grid's two tasks as tables (grid version 4 on, issue 39): with the primitive
given and without it, each with its verdict against the peers.

One function for the markdown docs (:func:`primspace.report.summary_tables.render_predict`)
and the HTML report (:func:`primspace.report.sections.prediction`). Both read the predict
results' ``table`` (``{row: {fraction: {"mse" | "success" | "accuracy": [mean, std (ddof 1), n]}}}``,
:func:`primspace.experiments.prediction_table.predict_table`) and its ``given_rows``; every
other row is the label-free task. Results before version 4 have one table
(:func:`primspace.results.tables.predict_error_table`).
"""

from __future__ import annotations

from dataclasses import dataclass

from primspace.results.tables import cell_text

__all__ = [
    "PEER_PREFIXES",
    "NO_MODEL",
    "MODEL_SHARE_TEXT",
    "TASKS_TEXT",
    "VERDICT_RULE",
    "TaskTable",
    "splits_tasks",
    "task_tables",
    "verdict",
    "share_text",
]

#: A row is a peer's when its name starts with one of these; every other row is primspace's.
PEER_PREFIXES = ("promp", "nearest neighbour", "mean motion", "raw gaussian")
#: The mark of a row whose prediction does not come through the run's decoder (model share 0).
NO_MODEL = "does not use the model"
#: What the model-share column is, as the text says it.
MODEL_SHARE_TEXT = (
    "Model share: the share of a row's prediction that comes through the run's decoder (1 for the rows "
    "that decode codes; for the prior, the weight its K-fold choice gave the decoded draws against the "
    "fitted demonstrations' own Gaussian; 0 for the peers), per fraction where it differs; a row at 0 "
    f'is marked "{NO_MODEL}".'
)
#: What the two tables are, as the text says it.
TASKS_TEXT = (
    "Two tasks: with the primitive given (the rows told the test motion's primitive) and without it (the "
    "rows given no label at test time); standard deviations over seeds with ddof 1; top-1 accuracy: the share "
    "of test motions whose most probable primitive under the row's posterior is their own."
)
#: The rule of the verdict lines, as the text says it (issue 17's: a difference holds only beyond both spreads).
VERDICT_RULE = (
    "Verdict per fraction: primspace's best row (lowest mean MSE, highest mean success) against the best "
    "peer row (names starting with " + ", ".join(f'"{p}"' for p in PEER_PREFIXES) + ") of the same table: "
    "it holds when primspace's is better by more than both standard deviations, loses when it is worse by "
    "more than both, and ties otherwise."
)
#: The metrics a verdict is stated for: (key, label, lower is better).
_METRICS = (("mse", "MSE", True), ("success", "success", False))


@dataclass(frozen=True)
class TaskTable:
    """One task's table: its title, columns, rows (text cells) and the verdict line under it."""

    title: str
    columns: list[str]
    rows: list[list[str]]
    verdict: str


def splits_tasks(results: dict) -> bool:
    """Whether predict ``results`` are shown as two tasks (grid version 4 on)."""
    return (results.get("version") or 0) >= 4


def task_tables(results: dict) -> list[TaskTable]:
    """The two tasks of version-4 predict ``results``: "With the primitive given" (its
    ``given_rows``) and "Without the primitive" (all other rows; a top-1 accuracy column group
    where a row has one); empty tasks are left out."""
    table, given = results["table"], set(results.get("given_rows") or ())
    tasks = (
        ("With the primitive given", [m for m in table if m in given], False),
        ("Without the primitive", [m for m in table if m not in given], True),
    )
    return [_task(results, title, methods, accuracy) for title, methods, accuracy in tasks if methods]


def _keys(results: dict, methods: list[str], accuracy: bool) -> dict[str, list[str]]:
    """The fraction keys of each metric's columns: MSE at the observed fractions; success at those and
    at "1" where judged; with ``accuracy``, the top-1 accuracy at those (and "1") where a row has one."""
    table = results["table"]
    fractions = [f"{f:g}" for f in results["fractions"]]
    with_one = fractions + (["1"] if any("1" in table[m] for m in methods) else [])
    found = [k for k in with_one if any("accuracy" in table[m].get(k, {}) for m in methods)]
    return {
        "mse": fractions,
        "success": with_one if results.get("judged") else [],
        "accuracy": found if accuracy else [],
    }


def _task(results: dict, title: str, methods: list[str], accuracy: bool) -> TaskTable:
    table = results["table"]
    keys = _keys(results, methods, accuracy)
    heads = {"mse": "MSE, {:.0%} observed", "success": "success, {:.0%}", "accuracy": "top-1 accuracy, {:.0%}"}
    digits = {"mse": 4, "success": 2, "accuracy": 2}
    columns = ["method"] + [heads[name].format(float(k)) for name, ks in keys.items() for k in ks]
    rows = [
        [m] + [cell_text(table[m].get(k, {}).get(name), digits=digits[name]) for name, ks in keys.items() for k in ks]
        for m in methods
    ]
    shares = [share_text(table[m], keys["mse"]) for m in methods]
    if any(shares):  # recorded from grid version 5 on
        columns.append("model share")
        rows = [row + [share] for row, share in zip(rows, shares)]
    return TaskTable(title, columns, rows, _verdict_line(table, methods, keys))


def _shares(cells: dict, keys: list[str]) -> list[float]:
    return [cells[k]["model_share"][0] for k in keys if cells.get(k, {}).get("model_share")]


def share_text(cells: dict, keys: list[str]) -> str:
    """A row's model share at the fractions ``keys`` (one number when the same at all, else one per
    fraction), with :data:`NO_MODEL` where it is 0 at all; "" when none was recorded."""
    shares = _shares(cells, keys)
    if not shares:
        return ""
    text = f"{shares[0]:.2g}" if len(set(shares)) == 1 else " / ".join(f"{v:.2g}" for v in shares)
    return f"{text} ({NO_MODEL})" if max(shares) == 0 else text


def verdict(ours: list, peer: list, lower_better: bool) -> str:
    """ "holds", "ties" or "loses": ``ours`` ``[mean, std, n]`` against ``peer``'s by :data:`VERDICT_RULE`."""
    gain = (peer[0] - ours[0]) if lower_better else (ours[0] - peer[0])
    spread = max(ours[1], peer[1])
    return "holds" if gain > spread else "loses" if -gain > spread else "ties"


def _best(table: dict, methods: list[str], key: str, name: str, lower_better: bool) -> tuple[str, list] | None:
    """The row of ``methods`` with the best mean ``name`` at ``key``, and its cell (None where none has one)."""
    cells = [(m, table[m][key][name]) for m in methods if table[m].get(key, {}).get(name)]
    if not cells:
        return None
    return (min if lower_better else max)(cells, key=lambda mc: mc[1][0])


def _verdict_line(table: dict, methods: list[str], keys: dict[str, list[str]]) -> str:
    """Per metric and fraction: primspace's best row against the best peer's, and the verdict."""
    peers = [m for m in methods if m.startswith(PEER_PREFIXES)]
    ours = [m for m in methods if m not in peers]
    parts = []
    for name, label, lower_better in _METRICS:
        for k in keys[name]:
            a, b = _best(table, ours, k, name, lower_better), _best(table, peers, k, name, lower_better)
            if a is None or b is None:
                continue
            digits = 4 if name == "mse" else 2
            mark = f", {NO_MODEL}" if _shares(table[a[0]], [k]) == [0.0] else ""
            parts.append(
                f"{label} at {float(k):.0%}: {verdict(a[1], b[1], lower_better)} ({a[0]}{mark} "
                f"{cell_text(a[1], digits)} against {b[0]} {cell_text(b[1], digits)})"
            )
    if not parts:
        return "No verdict: the table holds no primspace row or no peer row with a number."
    return "Verdicts, primspace's best row against the best peer row. " + "; ".join(parts) + "."
