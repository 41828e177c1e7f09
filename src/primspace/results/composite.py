"""The composite experiment's tables: primspace's segmentation beside its peers, and the upper bounds.

Read by the report, the command line and :mod:`primspace.docs` from a ``composite`` result
(an experiment directory's ``results/composite.json`` or a stored summary's): one place
that turns its numbers into rows, so the three show the same table. Numbers are mean ± std
(population) over the seeds.
"""

from __future__ import annotations

import numpy as np

from primspace.results.tables import final, mean_std

__all__ = [
    "METHODS",
    "composite_table",
    "primitives_table",
    "bounds_table",
    "recall_table",
    "PEER_RULES",
    "BOUND_FEATURES",
]

#: The segmentations by a model of single primitives
#: (:mod:`primspace.experiments.composite.primitives`), in table order.
METHODS = ("synthesis", "surprise")

#: What each peer is, for the tables' readers (primspace.segmentation.peers has the rules).
PEER_RULES = {
    "pelt-l2-noise": "ruptures PELT, l2 cost, primspace's noise penalty",
    "pelt-normal-bic": "ruptures PELT, Gaussian cost, BIC penalty",
    "binseg-l2-elbow": "ruptures binary segmentation, l2 cost, elbow of the cost",
    "binseg-rbf-elbow": "ruptures binary segmentation, rbf cost, elbow of the cost",
    "binseg-normal-elbow": "ruptures binary segmentation, Gaussian cost, elbow of the cost",
    "dynp-l2-count": "ruptures Dynp, l2 cost, true number of boundaries",
    "dynp-rbf-count": "ruptures Dynp, rbf cost, true number of boundaries",
    "dynp-normal-count": "ruptures Dynp, Gaussian cost, true number of boundaries",
    "hmm-full": "hmmlearn GaussianHMM, a state per primitive, full covariance",
}

#: How the bounds' feature rows read (a code row: ``codes <init>-q<q>``, its trajectory, untrained).
BOUND_FEATURES = {"raw": "raw joints (resampled)", "relative": "raw joints minus the start pose"}


def _seed_blocks(results: dict) -> list[dict]:
    return [results.get("peers", {})[s] for s in sorted(results.get("peers", {}), key=int)]


def composite_table(results: dict) -> tuple[list[str], list[list]]:
    """Per (q, init) of primspace, mean ± std over seeds of the held-out loss before and
    after inference, the boundary precision, recall and F1 (within the tolerance), the
    per-step labelling accuracy (also given the true boundaries), the same two for the
    untrained codes, and segments found against true (means over seeds); then a row per peer (same seeds,
    same held-out demonstrations, same scores; "given the true boundaries" for the
    change-point peers is their labeller on the true segments)."""
    groups: dict = {}
    for r in results["runs"]:
        groups.setdefault((r["latent_dim"], r["init"]), []).append(r)
    rows = []
    for (q, init), runs in sorted(groups.items()):
        seg = [r["segmentation"] for r in runs]
        raw = [r["segmentation_untrained"] for r in runs]
        rows.append(
            [
                init,
                q,
                len(runs),
                mean_std([r["infer"][0]["loss"] for r in runs]),
                mean_std([final([h["loss"] for h in r["infer"]]) for r in runs]),
                *[mean_std([s["boundary"][k] for s in seg]) for k in ("precision", "recall", "f1")],
                _within_transition(seg),
                mean_std([s["accuracy"] for s in seg]),
                mean_std([s.get("accuracy_true_boundaries") for s in seg]),
                mean_std([s["boundary"]["f1"] for s in raw]),
                mean_std([s["accuracy"] for s in raw]),
                f"{np.mean([s['segments_found'] for s in seg]):.0f} / {np.mean([s['segments_true'] for s in seg]):.0f}",
            ]
        )
    rows += _primitive_rows(results)
    rows += _peer_rows(results)
    tol = next(iter(groups.values()))[0]["segmentation"]["tolerance"] if groups else None
    return [
        "method",
        "q",
        "seeds",
        "held-out loss before inference",
        "after inference",
        f"boundary precision (±{tol} steps)",
        "recall",
        "F1",
        f"F1 within ±{tol} of the transition",
        "step labelling accuracy",
        "accuracy given the true boundaries",
        "F1, untrained codes",
        "accuracy, untrained codes",
        "segments found / true",
    ], rows


def _within_transition(scores: list[dict]) -> str:
    """Mean ± std of the F1 that counts a boundary anywhere within the tolerance of the
    transition (data with transitions; "—" for others and for results scored before 0.8)."""
    return mean_std([(s.get("boundary_transition") or {}).get("f1") for s in scores])


def _primitive_rows(results: dict) -> list[list]:
    """A row per method of the model of single primitives (synthesis, surprise): mean ± std
    over the seeds that ran it; q is the single-primitive model's."""
    seeds = results.get("primitives") or []
    rows = []
    for name in METHODS:
        got = [r[name] for r in seeds if name in r]
        if not got:
            continue
        rows.append(
            [
                f"{name} ({seeds[0]['preset']} single primitives)",
                seeds[0]["latent_dim"],
                len(got),
                "—",
                "—",
                *[mean_std([m["boundary"][k] for m in got]) for k in ("precision", "recall", "f1")],
                _within_transition(got),
                mean_std([m["accuracy"] for m in got]),
                "—",
                "—",
                "—",
                f"{np.mean([m['segments_found'] for m in got]):.0f} / {np.mean([m['segments_true'] for m in got]):.0f}",
            ]
        )
    return rows


def primitives_table(results: dict) -> tuple[list[str], list[list]] | None:
    """The model of single primitives per method (synthesis, surprise): the offset model
    chosen without labels (seeds per model), boundary F1, per-step
    labelling accuracy, the same with each segment given its nearest template's true
    primitive (the labeller's bound), the surprise threshold, and the seeds' values; mean ±
    std over seeds. None when the experiment had no such model."""
    seeds = results.get("primitives") or []
    if not seeds:
        return None
    rows = []
    for name in METHODS:
        got = [(r["seed"], r[name]) for r in seeds if name in r]
        per = ", ".join(f"{s}: {m['boundary']['f1']:.2f} / {m['accuracy']:.2f}" for s, m in got)
        offsets = [m.get("offset") for _, m in got if m.get("offset")]
        chosen = ", ".join(f"{o} ({offsets.count(o)} of {len(got)})" for o in dict.fromkeys(offsets)) or "—"
        rows.append(
            [
                name,
                len(got),
                chosen,
                mean_std([m["boundary"]["f1"] for _, m in got]),
                mean_std([m["accuracy"] for _, m in got]),
                mean_std([m.get("accuracy_template_labels") for _, m in got]),
                mean_std([m.get("threshold") for _, m in got]) if name == "surprise" else "—",
                per,
            ]
        )
    first = seeds[0]
    return [
        f"method ({first['preset']} preset, q = {first['latent_dim']}, {first['n_templates']} single primitives "
        "fitted)",
        "seeds",
        "offset model chosen",
        "boundary F1",
        "step labelling accuracy",
        "accuracy, nearest template's true primitive",
        "surprise threshold",
        "per seed (F1 / accuracy)",
    ], rows


def _peer_rows(results: dict) -> list[list]:
    blocks = _seed_blocks(results)
    names = list(dict.fromkeys(n for b in blocks for n in b.get("methods", {})))
    rows = []
    for name in names:
        got = [b["methods"][name] for b in blocks if name in b.get("methods", {})]
        oracle = (
            [b["bounds"]["raw"]["clustered"] for b in blocks if name in b.get("methods", {})]
            if not name.startswith("hmm")
            else []
        )
        true = [b["segments_true"] for b in blocks if name in b.get("methods", {})]
        rows.append(
            [
                f"peer: {name}",
                "—",
                len(got),
                "—",
                "—",
                *[mean_std([m["boundary"][k] for m in got]) for k in ("precision", "recall", "f1")],
                _within_transition(got),
                mean_std([m["accuracy"] for m in got]),
                mean_std(oracle),
                "—",
                "—",
                f"{np.mean([m['segments_found'] for m in got]):.0f} / {np.mean(true):.0f}",
            ]
        )
    return rows


def _feature_name(key: str) -> str:
    return BOUND_FEATURES.get(key, key)


def _bound_keys(blocks: list[dict]) -> list[str]:
    return list(dict.fromkeys(k for b in blocks for k in b.get("bounds", {})))


def bounds_table(results: dict) -> tuple[list[str], list[list]] | None:
    """The upper bounds on the true segments of the held-out demonstrations, per feature:
    per-step accuracy of the cross-validated classifiers given the labels (logistic
    regression, also on first and later segments; nearest neighbour) and of the
    clustering without labels; mean ± std over seeds. None without peers blocks."""
    blocks = _seed_blocks(results)
    if not blocks:
        return None
    rows = []
    for key in _bound_keys(blocks):
        got = [b["bounds"][key] for b in blocks if key in b["bounds"]]
        sup = [g["supervised"] for g in got if g["supervised"]]
        rows.append(
            [
                _feature_name(key),
                len(got),
                mean_std([s["logistic"]["accuracy"] for s in sup]),
                mean_std([s["logistic"]["first"] for s in sup]),
                mean_std([s["logistic"]["later"] for s in sup]),
                mean_std([s["nearest"]["accuracy"] for s in sup]),
                mean_std([g["clustered"] for g in got]),
            ]
        )
    return [
        "features of a true segment",
        "seeds",
        "logistic regression, given labels (CV)",
        "first segments",
        "later segments",
        "nearest neighbour, given labels (CV)",
        "clustered without labels",
    ], rows


def recall_table(results: dict) -> tuple[list[str], list[list]] | None:
    """Per feature, the logistic regression's recall of each primitive (share of its true
    segments named right, mean over seeds) and the confusion most often made (true →
    predicted, segments over all seeds). None without peers blocks."""
    blocks = _seed_blocks(results)
    names = results.get("label_names") or []
    if not blocks or not names:
        return None
    rows = []
    for key in _bound_keys(blocks):
        sup = [b["bounds"][key]["supervised"] for b in blocks if key in b["bounds"] and b["bounds"][key]["supervised"]]
        if not sup:
            continue
        recall = [
            np.mean([s["logistic"]["recall"][j] for s in sup if s["logistic"]["recall"][j] is not None] or [np.nan])
            for j in range(len(names))
        ]
        confusion = np.sum([s["logistic"]["confusion"] for s in sup], axis=0)
        np.fill_diagonal(confusion, 0)
        t, p = np.unravel_index(int(np.argmax(confusion)), confusion.shape)
        worst = f"{names[t]} → {names[p]} ({int(confusion[t, p])})" if confusion[t, p] else "none"
        rows.append([_feature_name(key), *[f"{r:.2f}" if np.isfinite(r) else "—" for r in recall], worst])
    return ["features (logistic regression)", *names, "most frequent confusion"], rows
