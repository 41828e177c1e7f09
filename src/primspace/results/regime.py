"""The regime of few demonstrations read from its results (``results/regime.json`` or a summary's):
the figure's lines, each ``n``'s comparison of the prior through the decoder with the best peer, and
the crossing point (the ``n`` up to which the model wins). Reads results only.

A comparison follows the prediction tables' rule: a row beats another when it is better by more than
both standard deviations over seeds (ddof 1), loses when worse by more than both, and ties otherwise.
"""

from __future__ import annotations

__all__ = [
    "PEER_PREFIXES",
    "MODEL_ROWS",
    "TASKS",
    "METRICS",
    "regime_panels",
    "beats",
    "task_rows",
    "best_peer",
    "comparisons",
    "crossing",
    "seed_crossings",
]

#: A row is a peer's when its name starts with one of these.
PEER_PREFIXES = ("promp", "nearest neighbour", "raw gaussian")
#: The tasks (given the primitive or not) and the model's row in each: the prior through the decoder (blend 0).
MODEL_ROWS = {"given": "prior decoded (labels)", "without": "prior decoded (posterior)"}
#: The tasks' titles.
TASKS = {"given": "with the primitive given", "without": "without the primitive"}
#: The metrics: (key, lower is better).
METRICS = (("mse", True), ("success", False))


def task_rows(results: dict, task: str) -> list[str]:
    """The rows of ``task`` ("given" or "without"), in the table's order."""
    given = set(results.get("given_rows") or ())
    return [row for row in results["table"] if (row in given) == (task == "given")]


def regime_panels(results: dict, metric: str, fraction: float = 0.25) -> dict:
    """``{title: {row: (ns, means, stds)}}`` of ``metric`` at ``fraction`` observed, one panel per task."""
    key, panels = f"{fraction:g}", {}
    for task, title in TASKS.items():
        lines = {}
        for row in task_rows(results, task):
            points = [(int(n), c[key][metric]) for n, c in results["table"][row].items() if c.get(key, {}).get(metric)]
            if points:
                lines[row] = ([p[0] for p in points], [p[1][0] for p in points], [p[1][1] for p in points])
        panels[f"{title}, {fraction:.0%} observed"] = lines
    return panels


def beats(ours: list, peer: list, lower_better: bool) -> str:
    """ "holds", "ties" or "loses": ``ours`` ``[mean, std, n]`` against ``peer``'s (module docstring)."""
    gain = (peer[0] - ours[0]) if lower_better else (ours[0] - peer[0])
    spread = max(ours[1], peer[1])
    return "holds" if gain > spread else "loses" if -gain > spread else "ties"


def best_peer(results: dict, task: str, n: str, key: str, metric: str) -> tuple[str, list] | None:
    """The peer row of ``task`` with the best mean ``metric`` at ``n`` and fraction ``key``, and its cell."""
    lower = dict(METRICS)[metric]
    cells = [
        (row, results["table"][row][n][key][metric])
        for row in task_rows(results, task)
        if row.startswith(PEER_PREFIXES) and results["table"][row].get(n, {}).get(key, {}).get(metric)
    ]
    return (min if lower else max)(cells, key=lambda rc: rc[1][0]) if cells else None


def comparisons(results: dict, task: str, metric: str, fraction: float = 0.25) -> dict:
    """``{n: {"verdict", "ours": cell, "peer": name, "peer_cell": cell}}`` of the model's row of ``task``
    against the best peer at every ``n`` where both have a number."""
    key, model, out = f"{fraction:g}", MODEL_ROWS[task], {}
    for n, cells in results["table"].get(model, {}).items():
        ours, peer = cells.get(key, {}).get(metric), best_peer(results, task, n, key, metric)
        if ours and peer:
            verdict = beats(ours, peer[1], dict(METRICS)[metric])
            out[n] = {"verdict": verdict, "ours": ours, "peer": peer[0], "peer_cell": peer[1]}
    return dict(sorted(out.items(), key=lambda kv: int(kv[0])))


def crossing(compared: dict) -> int | None:
    """The largest ``n`` up to which the model holds at every ``n`` compared (None: it does not hold at the
    smallest)."""
    last = None
    for n, c in compared.items():
        if c["verdict"] != "holds":
            break
        last = int(n)
    return last


def seed_crossings(results: dict, task: str, metric: str, fraction: float = 0.25) -> dict:
    """``{seed: crossing}`` seed by seed (the model's number better than every peer's of that seed; no
    spread), from the results' ``by_seed``."""
    key, model, lower = f"{fraction:g}", MODEL_ROWS[task], dict(METRICS)[metric]
    rows = [r for r in task_rows(results, task) if r.startswith(PEER_PREFIXES)]
    out = {}
    for seed, entry in results.get("by_seed", {}).items():
        last = None
        for n in sorted(entry.get("n", {}), key=int):
            methods = entry["n"][n]["methods"]
            ours = methods.get(model, {}).get(key, {}).get(metric)
            peers = [methods[r][key][metric] for r in rows if methods.get(r, {}).get(key, {}).get(metric) is not None]
            if ours is None or not peers:
                break
            best = min(peers) if lower else max(peers)
            if not (ours < best if lower else ours > best):
                break
            last = int(n)
        out[seed] = last
    return out
