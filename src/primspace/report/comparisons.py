"""Two stored summaries side by side: one grid under one changed setting.

:data:`COMPARISONS` names the pairs docs/results.md shows (the loss reductions, the
optimisers); :func:`render_comparison` renders a pair per init: the inferred motor error and
vision PSNR per element (the same scale whatever the loss), success and clustering, and the
clustering after rescaling where the summaries hold it. A side may be several summaries of
one setting that differ only in their inits (:func:`merged`). Reads summaries only; spreads
are the sample std over seeds (ddof 1).
"""

from __future__ import annotations

from primspace.report.summary_tables import mean_spread, outcome_rows, table

__all__ = ["COMPARISONS", "RESCALED_COLUMNS", "render_comparison", "merged", "side_names"]

COMPARISONS = (
    (
        "demo-images-mean",
        "demo-images-sum",
        "the per-element loss (ours) against the paper's summed loss (`--loss-reduction sum`)",
    ),
    (
        "demo-images-precision",
        "demo-images-mean",
        "each modality weighed by its learned precision (`--loss-reduction precision`) against the per-element "
        "mean loss, the demo preset with frames, three seeds",
    ),
    ("demo-images-precision-zero", "demo-images-mean", "the same from the zero start"),
    (
        "paper-images-short-mean",
        "paper-images-short-sum",
        "the same at the paper preset with images, 35 % of the schedule, one seed, one H200",
    ),
    (
        "paper-adam40",
        "paper-sgd40",
        "Adam (ours) against the paper's plain gradient descent (`--optimizer sgd`, its two rates tuned on a "
        "validation split), paper preset, motor only, q = 40, three seeds: the clustering ablation of issue 42",
    ),
)


def _final_metric(run: dict, phase: str, key: str, motor_loss: bool = False) -> float | None:
    """An intra run's final all-frame ``key`` (motor, vision, psnr) of ``phase``, else its last logged
    value; ``motor_loss``: the run's loss is its motor MSE (motor only, per-element mean, weight 1)."""
    if run.get("final"):
        return run["final"][phase].get(key)
    curve = run["fit" if phase == "fit" else "infer"]
    last = curve[-1] if curve else {}
    return last.get(key, last.get("loss") if key == "motor" and motor_loss else None)


def _motor_loss(summary: dict) -> bool:
    """Whether a summary's losses are its motor MSE: motor only, the per-element mean, motor weight 1."""
    preset = summary.get("preset", {})
    train = preset.get("train", {})
    return preset.get("images") is False and train.get("loss_reduction") == "mean" and train.get("motor_weight") == 1.0


#: The columns of :func:`render_comparison` read from the clustering's rescaled rows
#: (:func:`primspace.experiments.clustering.rescaled_rows`): the codes' size, then the
#: accuracy after each rescaling.
RESCALED_COLUMNS = {
    "rms": "code RMS size",
    "common scale": "clustering, common scale",
    "standardised per dimension": "clustering, standardised",
}


def _rescaled(summary: dict, init: str, key: str) -> str:
    rows = [r for r in summary["results"]["clustering"]["rescaled"] if r["init"] == init]
    if key == "rms":
        return mean_spread([r["rms"] for r in rows if r["rescaling"] == "common scale"], rng=False)
    return mean_spread([r["accuracy"] for r in rows if r["rescaling"] == key], rng=False)


def render_comparison(a: dict, b: dict, what: str) -> str:
    """Two summaries of the same grid under one changed setting, per init: the inferred
    motor loss and vision PSNR (all frames, per element: comparable across losses),
    success and clustering accuracy, mean ± sample std (ddof 1) over seeds (unmeasured columns left out)."""
    rows = []
    rescaled = all(s["results"].get("clustering", {}).get("rescaled") for s in (a, b))
    inits = dict.fromkeys(r["init"] for r in a["results"]["intra"]["runs"])
    outcomes = {name: {row[0]: row for row in outcome_rows(s["results"])} for name, s in (("a", a), ("b", b))}
    for init in inits:
        row = [init]
        for key in ("motor", "psnr"):
            for s in (a, b):
                runs = [r for r in s["results"]["intra"]["runs"] if r["init"] == init]
                row.append(
                    mean_spread(
                        [_final_metric(r, "infer", key, _motor_loss(s)) for r in runs],
                        3 if key == "psnr" else 2,
                        rng=False,
                    )
                )
        for col in (2, 4):
            row += [outcomes[k].get(init, [""] * 5)[col] for k in ("a", "b")]
        row += [_rescaled(s, init, key) for key in RESCALED_COLUMNS for s in (a, b) if rescaled]
        rows.append(row)
    metrics = ["eval motor MSE", "eval vision PSNR dB", "success, all", "clustering"]
    metrics += list(RESCALED_COLUMNS.values()) if rescaled else []  # the clustering experiment's rows
    columns = ["init"] + [f"{m}: {n}" for m in metrics for n in (a["name"], b["name"])]
    shown = [0] + [i for i in range(1, len(columns)) if any(row[i] not in ("—", "") for row in rows)]
    columns, rows = [columns[i] for i in shown], [[row[i] for i in shown] for row in rows]
    return "\n".join(
        [
            f"#### {a['name']} against {b['name']}: {what}",
            "",
            "Per-element errors recomputed on every frame, so the two losses are compared on the same scale; "
            "mean ± sample std (ddof 1) over seeds (pooled success with its Wilson 95 % interval).",
            "",
            table(columns, rows),
        ]
    )


def side_names(side) -> tuple[str, ...]:
    """The summary names of one side of a comparison (a name, or several)."""
    return (side,) if isinstance(side, str) else tuple(side)


def merged(summaries: dict[str, dict], side) -> dict:
    """One side of a comparison: a summary, or several summaries of one setting that differ
    only in their inits (e.g. rates tuned per init, one experiment each) as one: their intra
    runs and clustering rows together."""
    names = side_names(side)
    if len(names) == 1:
        return summaries[names[0]]
    parts = [summaries[n]["results"] for n in names]
    intra = {"runs": [r for p in parts for r in p["intra"]["runs"]]}
    clustering = {"latent": [], "by_seed": {}, "rescaled": [], "seed": (parts[0].get("clustering") or {}).get("seed")}
    for p in parts:
        c = p.get("clustering") or {}
        clustering["latent"] += c.get("latent", [])
        clustering["rescaled"] += c.get("rescaled", [])
        for seed, rows in c.get("by_seed", {}).items():
            clustering["by_seed"].setdefault(seed, []).extend(rows)
    return {"name": " + ".join(names), "results": {"intra": intra, "clustering": clustering}}
