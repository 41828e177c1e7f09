"""The tables and the qualitative verdict an experiment folder's results give (read by
:mod:`primspace.results.readers`); the report prints them and computes nothing else."""

from __future__ import annotations

import numpy as np

from primspace.results.layout import LEARNED_CODES
from primspace.utils.stats import sample_std

__all__ = [
    "final",
    "mean_std",
    "final_loss_table",
    "qualitative_check",
    "latent_table",
    "probe_table",
    "spread_table",
    "outcome_spread_table",
    "success_table",
    "failed_criteria_table",
    "inter_table",
    "tuning_table",
    "projection_lead",
    "scene_table",
    "cell_text",
]

# ---------------------------------------------------------------------- tables


def final(curve: list) -> float:
    """The last value of a loss curve that is not None (NaN for none)."""
    vals = [v for v in curve if v is not None]
    return float(vals[-1]) if vals else float("nan")


def final_loss_table(results: dict) -> tuple[list[str], list[list]]:
    """Intra: rows ``init, q, seed, fit loss, eval loss at epoch 0, eval loss at the end``;
    for runs with images also the final motor and vision losses recomputed on every frame
    (the run's ``final``) and the vision loss as PSNR."""
    with_images = any(r.get("final") for r in results["runs"])
    rows = []
    for r in sorted(results["runs"], key=lambda r: (r["latent_dim"], r["seed"], r["init"])):
        fit_loss = [h["loss"] for h in r["fit"]]
        eval_loss = [h["loss"] for h in r["infer"]]
        row = [r["init"], r["latent_dim"], r["seed"], final(fit_loss), eval_loss[0], final(eval_loss)]
        if with_images:
            f = r.get("final") or {}
            row += [(f.get(phase) or {}).get(k) for phase in ("fit", "infer") for k in ("motor", "vision", "psnr")]
        rows.append(row)
    columns = ["init", "q", "seed", "final fit loss", "eval loss before inference", "final eval loss"]
    if with_images:
        columns += [f"{phase} {k} (all frames)" for phase in ("fit", "eval") for k in ("motor", "vision", "PSNR dB")]
    return columns, rows


def qualitative_check(results: dict) -> tuple[bool | None, str]:
    """Intra: does projection's final eval loss lie below zero's and random's at every q? (the paper's claim)"""
    by: dict = {}
    for r in results["runs"]:
        by.setdefault((r["latent_dim"], r["seed"]), {})[r["init"]] = final([h["loss"] for h in r["infer"]])
    verdicts, lines = [], []
    for (q, seed), losses in sorted(by.items()):
        if not {"projection", "zero", "random"} <= losses.keys():
            continue
        ok = losses["projection"] < losses["zero"] and losses["projection"] < losses["random"]
        verdicts.append(ok)
        lines.append(
            f"q={q}, seed {seed}: projection {losses['projection']:.4g}, zero {losses['zero']:.4g}, "
            f"random {losses['random']:.4g} — {'holds' if ok else 'does NOT hold'}"
        )
    if not verdicts:
        return None, "not enough runs to compare projection with zero and random"
    return all(verdicts), "; ".join(lines)


def probe_table(results: dict) -> tuple[list[str], list[list]]:
    """Probe: one row per run and set of codes (fitted, inferred, initial): the
    within-primitive cross-validated R² per factor and their mean."""
    names = results["factor_names"]
    rows = []
    for r in results["runs"]:
        for codes in ("fitted", "inferred", "initial"):
            p = r[codes]
            rows.append([r["init"], r["latent_dim"], r["seed"], codes, *[p["r2"].get(n) for n in names], p["mean_r2"]])
    return ["init", "q", "seed", "codes", *[f"R² {n}" for n in names], "mean R²"], rows


def mean_std(values: list, digits: int = 3) -> str:
    """``mean ± std`` (sample std over seeds, ddof 1) of the values that are not None; one
    value alone (no spread), "—" for none."""
    v = [float(x) for x in values if x is not None]
    if len(v) < 2:
        return f"{v[0]:.{digits}g}" if v else "—"
    return f"{np.mean(v):.{digits}g} ± {sample_std(v):.2g}"


def spread_table(results: dict, probe: dict | None = None) -> tuple[list[str], list[list]] | None:
    """Intra over seeds: per (q, init), mean ± sample std (ddof 1) over the seeds of the
    final fit loss, the eval loss before inference and after it, and (with the probe's
    results) the mean probe R² of the inferred codes. None with fewer than two seeds of any (q, init)."""
    groups: dict = {}
    for r in results["runs"]:
        groups.setdefault((r["latent_dim"], r["init"]), []).append(r)
    if not groups or max(len(g) for g in groups.values()) < 2:
        return None
    probes = {(p["latent_dim"], p["init"], p["seed"]): p["inferred"]["mean_r2"] for p in (probe or {}).get("runs", [])}
    rows = []
    for (q, init), runs in sorted(groups.items()):
        row = [
            init,
            q,
            len(runs),
            mean_std([final([h["loss"] for h in r["fit"]]) for r in runs]),
            mean_std([r["infer"][0]["loss"] for r in runs]),
            mean_std([final([h["loss"] for h in r["infer"]]) for r in runs]),
        ]
        if probe is not None:
            row.append(mean_std([probes.get((q, init, r["seed"])) for r in runs]))
        rows.append(row)
    columns = ["init", "q", "seeds", "final fit loss", "eval loss before inference", "final eval loss"]
    return columns + (["probe R² (inferred codes)"] if probe is not None else []), rows


def outcome_spread_table(clustering: dict | None, success: dict | None) -> tuple[list[str], list[list]] | None:
    """Success rates (all primitives, grasp) and latent clustering accuracy per init:
    mean ± sample std (ddof 1) over the focus seed and the others (``by_seed``). None with
    one seed."""
    acc: dict = {}
    if clustering is not None:
        per_seed = [clustering["latent"]] + list(clustering.get("by_seed", {}).values())
        for rows in per_seed:
            for r in rows:
                key = r["init"] if r["codes"] == LEARNED_CODES else "untrained P m"
                acc.setdefault(key, []).append(r["accuracy"])
    rates: dict = {}
    if success is not None:
        for gen in [success.get("generated", {})] + list(success.get("by_seed", {}).values()):
            for init, res in gen.items():
                rates.setdefault(init, []).append((res["overall"], res["rates"].get("grasp")))
    n_seeds = max([len(v) for v in acc.values()] + [len(v) for v in rates.values()] + [0])
    if n_seeds < 2:
        return None
    rows = []
    for init in list(dict.fromkeys([*rates, *acc])):
        r = rates.get(init, [])
        rows.append(
            [
                init,
                max(len(r), len(acc.get(init, []))),
                mean_std([x for x, _ in r]),
                mean_std([g for _, g in r]),
                mean_std(acc.get(init, [])),
            ]
        )
    return ["init", "seeds", "success, all primitives", "success, grasp", "latent clustering accuracy"], rows


def latent_table(results: dict) -> tuple[list[str], list[list]]:
    """Clustering: one row per set of codes, then one per raw-trajectory data set."""
    rows = [
        [r["init"], r["codes"], r["tau"], r["r2"], r["rank"], r["accuracy"], r["nmi"], r["ari"]]
        for r in results["latent"]
    ]
    for name, t in results["trajectory"].items():
        c = t["chosen"]
        rows.append(
            [
                f"raw trajectories ({name})",
                f"{t['n']} x {t['dim']}",
                c["tau"],
                c["r2"],
                c["rank"],
                c["accuracy"],
                c["nmi"],
                c["ari"],
            ]
        )
    return ["init / data", "codes", "τ", "R²", "rank", "accuracy", "NMI", "ARI"], rows


def _with_interval(res: dict, prim: str) -> str | float:
    """A success rate with its Wilson 95 % interval where the results hold one."""
    rate = res["overall"] if prim == "all" else res["rates"].get(prim, float("nan"))
    interval = res.get("intervals", {}).get(prim)
    return rate if interval is None else f"{rate:.2f} [{interval[0]:.2f}, {interval[1]:.2f}]"


def success_table(results: dict) -> tuple[list[str], list[list]]:
    """Success: rows primitive (then "all", then "all" at each judge tolerance of the
    sweep); columns recorded, then each init's success rate with its Wilson 95 % interval."""
    inits = list(results["generated"])
    prims = [p for p in results["label_names"] if results["recorded"] and p in results["recorded"]["rates"]]
    judged = [results["recorded"]] + [results["generated"][i] for i in inits]
    rows = [[p] + [_with_interval(res, p) for res in judged] for p in prims + ["all"]]
    for tol in sorted(results["recorded"].get("by_tolerance", {}), key=float):
        rows.append(
            [f"all, held within {float(tol) * 1000:g} mm"]
            + [res.get("by_tolerance", {}).get(tol, {}).get("overall", float("nan")) for res in judged]
        )
    return ["primitive", "recorded"] + [f"{i} init" for i in inits], rows


def failed_criteria_table(results: dict) -> tuple[list[str], list[list]]:
    """Success: for each init and primitive with failures, how often each criterion failed."""
    rows = []
    for init, res in results["generated"].items():
        for prim, counts in res.get("failed_criteria", {}).items():
            if counts:
                rows.append([init, prim, f"{res['counts'][prim]}", "; ".join(f"{k} ({v})" for k, v in counts.items())])
    return ["init", "primitive", "judged", "failed criteria (samples)"], rows


def inter_table(results: dict) -> tuple[list[str], list[list]]:
    """Inter: phase-2 loss at the start and at the end, mean ± sample std (ddof 1) over folds, per init."""
    by: dict[str, list] = {}
    for r in results["runs"]:
        by.setdefault(r["init"], []).append(r)
    rows = []
    for init, runs in by.items():
        first = [r["phase2"][0]["loss"] for r in runs]
        last = [r["phase2"][-1]["loss"] for r in runs]
        rows.append([init, len(runs), mean_std(first, 4), mean_std(last, 4)])
    return ["init", "folds", "phase-2 loss at start", "phase-2 final loss"], rows


def tuning_table(results: dict, intra: dict | None = None) -> tuple[list[str], list[list]]:
    """Tune: per q and init, the chosen setting (layer time constants, latent learning
    rate, its validation loss), the final eval loss under the shared setting and under
    the tuned one (mean ± sample std over seeds, ddof 1), and in how many seeds
    projection's final eval loss is below the init's, seed by seed, under each (does a
    gap survive tuning?). The setting is chosen at one q (``latent_dim``) and applied at
    every q: rows of another q name that choice instead of repeating it. The shared runs
    are ``intra``'s (default: the copy the tune results keep)."""
    finals = _tuning_finals(results, intra)
    tuned_at = results.get("latent_dim")
    rows = []
    for q in sorted({r["latent_dim"] for r in results["tuned"]["runs"]}):
        for init, setting in results["chosen"].items():
            s, t = (
                [v for (k, i, d, _), v in finals.items() if (k, i, d) == (kind, init, q)]
                for kind in ("shared", "tuned")
            )
            choice = f"τ {setting['taus'][0]:g}, {setting['taus'][1]:g}; latent lr {setting['latent_lr']:.3g}"
            validation = f"{setting['validation_loss']:.3g}"
            if q != tuned_at:  # tuned at one q, applied at every q: the choice is q = tuned_at's
                choice, validation = f"q = {tuned_at}'s choice", "—"
            wins = " → ".join(_projection_below(finals, kind, init, q) for kind in ("shared", "tuned"))
            rows.append([q, init, choice, validation, mean_std(s), mean_std(t), "—" if init == "projection" else wins])
    return [
        "q",
        "init",
        "chosen on validation",
        "validation loss",
        "final eval loss, shared setting",
        "final eval loss, tuned",
        "projection lower, seeds (shared → tuned)",
    ], rows


def projection_lead(results: dict, intra: dict | None = None, init: str = "zero") -> dict[str, str]:
    """Tune: at the tuned q, the seeds where projection's final eval loss is below
    ``init``'s, ``{"shared": "k of n", "tuned": "k of n"}`` (README's headline)."""
    finals = _tuning_finals(results, intra)
    return {kind: _projection_below(finals, kind, init, results["latent_dim"]) for kind in ("shared", "tuned")}


def _tuning_finals(results: dict, intra: dict | None) -> dict[tuple, float]:
    """``(shared|tuned, init, q, seed) -> final eval loss`` of the tune results' runs."""
    finals = {}
    for kind, runs in (
        ("shared", (intra or results.get("shared") or {"runs": []})["runs"]),
        ("tuned", results["tuned"]["runs"]),
    ):
        for r in runs:
            finals[(kind, r["init"], r["latent_dim"], r["seed"])] = final([h["loss"] for h in r["infer"]])
    return finals


def _projection_below(finals: dict, kind: str, init: str, q: int) -> str:
    """ "k of n": the seeds where projection's final eval loss is below ``init``'s (paired by seed)."""
    seeds = [sd for (k, i, d, sd) in finals if (k, i, d) == (kind, init, q) and (kind, "projection", q, sd) in finals]
    return f"{sum(finals[(kind, 'projection', q, sd)] < finals[(kind, init, q, sd)] for sd in seeds)} of {len(seeds)}"


def predict_error_table(results: dict) -> tuple[list[str], list[list]]:
    """Predict: rows method (primspace's starts, then the peers); columns the observed
    fractions: MSE of the unobserved steps, mean ± std over seeds (and success where judged)."""
    fractions = [f"{f:g}" for f in results["fractions"]]
    table = results["table"]
    judged = results.get("judged") and any("1" in cells for cells in table.values())
    columns = ["method"] + [f"MSE, {float(f):.0%} observed" for f in fractions]
    if results.get("judged"):
        columns += [f"success, {float(f):.0%}" for f in fractions + (["1"] if judged else [])]
    rows = []
    for method, cells in table.items():
        row = [method] + [cell_text(cells.get(f, {}).get("mse")) for f in fractions]
        if results.get("judged"):
            row += [cell_text(cells.get(f, {}).get("success"), digits=2) for f in fractions + (["1"] if judged else [])]
        rows.append(row)
    return columns, rows


def scene_table(results: dict) -> tuple[list[str], list[list]]:
    """Scene: per primitive (then all), a row per method (the scene only, the mean motion given
    the label, the reproduction from the whole motion): its samples per seed, the success
    where judged and the MSE of the steps after the first, mean ± std over seeds."""
    table = results["table"]
    methods = [m for m in results.get("methods", list(table)) if m in table]
    judged = bool(results.get("judged"))
    names = [p for p in dict.fromkeys(p for m in methods for p in table[m]) if p != "all"] + ["all"]
    columns = ["primitive", "method", "n"] + (["success"] if judged else []) + ["MSE after step 1"]
    rows = []
    for name in names:
        for method in methods:
            cell = table[method].get(name)
            if cell:
                rows.append(
                    [name, method, f"{cell['n'][0]:g}"]
                    + ([cell_text(cell.get("success"), digits=2)] if judged else [])
                    + [cell_text(cell.get("mse"))]
                )
    return columns, rows


def cell_text(cell, digits: int = 4) -> str:
    """``[mean, std (ddof 1), n]`` as "mean ± std" (n > 1) or "mean"; "–" for none."""
    if not cell:
        return "–"
    mean, std, n = cell
    return f"{mean:.{digits}g} ± {std:.{digits - 2 if digits > 2 else 1}g}" if n > 1 else f"{mean:.{digits}g}"
