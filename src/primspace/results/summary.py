"""The small summary of a finished experiment, kept in the repository.

Result folders are not kept from one machine to the next, so the numbers the docs quote
must live somewhere that is: :func:`summarize` reduces an experiment directory to a small
JSON object (tens of kilobytes) that holds every number the docs' tables and the claims
are made from, and nothing else: loss curves cut to a few epochs, success counts, the
accuracy of each clustering, the inter folds. ``docs/results/NAME.json`` holds one per
run we report; ``python -m primspace.report.markdown`` writes the tables of README and
docs/results.md from them, and a test keeps the committed text equal to what it writes.
Beside each, ``docs/results/NAME.codes.npz`` keeps the codes of the directory's runs
(:mod:`primspace.results.codes`, written by ``primspace summarize``), so that
clustering can be re-checked without training again.

The claims (:func:`primspace.results.claims.check_claims`) read a summary's
``results`` exactly as they read a directory, so a rule that changes is re-judged from
the stored summaries without re-running anything.
"""

from __future__ import annotations

import json
import platform
from pathlib import Path

from primspace.results.act import ALL
from primspace.results.readers import read_meta, read_results
from primspace.utils.errors import UserError

__all__ = [
    "SUMMARY_VERSION",
    "CURVE_EPOCHS",
    "DIGITS",
    "summarize",
    "read_summary",
    "write_summary",
    "cpu_class",
    "kept_epochs",
    "recorded_commands",
    "recorded_versions",
]

#: Bumped when the summary's form changes.
SUMMARY_VERSION = 1

#: The epochs of a loss curve a summary keeps (besides the last, and an eighth of the way,
#: which the inter claim reads as "convergence speed").
CURVE_EPOCHS = (0, 1, 2, 5, 10, 20, 50, 100, 200, 400, 800)


def cpu_class() -> dict:
    """The CPU a run was measured on: vendor and model, and the widest vector extension
    (the same seed trains to other last digits on another class)."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name":
                model = value.strip()
            elif key.strip() == "flags":
                flags = set(value.split())
    except OSError:
        pass
    isa = "avx512" if "avx512f" in flags else "avx2" if "avx2" in flags else platform.machine()
    return {"model": model, "isa": isa}


def kept_epochs(last: int) -> set[int]:
    """The epochs a summary keeps of a curve that ends at epoch ``last``."""
    return {e for e in CURVE_EPOCHS if e <= last} | {last, max(1, round(last / 8))}


#: Significant digits a summary keeps of a measured number (losses, rates, accuracies).
DIGITS = 5


def _round(value):
    """``value`` with every float cut to :data:`DIGITS` significant digits (nested)."""
    if isinstance(value, float):
        return float(f"{value:.{DIGITS}g}")
    if isinstance(value, dict):
        return {k: _round(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_round(v) for v in value]
    return value


def _curve(curve: list[dict], epochs: set[int] | None = None) -> list[dict]:
    """The curve at :func:`kept_epochs` only (or at ``epochs``): the loss, and the motor
    and vision parts when vision was trained (without it the motor part is the loss)."""
    points = [h for h in curve if h.get("loss") is not None]
    if not points:
        return []
    keep = kept_epochs(points[-1]["epoch"]) if epochs is None else epochs | {points[0]["epoch"], points[-1]["epoch"]}
    parts = (
        ("epoch", "loss", "motor", "vision") if any(h.get("vision") is not None for h in points) else ("epoch", "loss")
    )
    return [{k: h[k] for k in parts if h.get(k) is not None} for h in points if h["epoch"] in keep]


def _intra(r: dict) -> dict:
    out = {k: r.get(k) for k in ("init", "latent_dim", "seed", "n_train", "n_eval", "fit_seconds", "seconds")}
    out |= {"fit": _curve(r["fit"]), "infer": _curve(r["infer"])}
    for key in ("final", "calibration"):
        if r.get(key) is not None:
            out[key] = r[key]
    return out


def _judged(res: dict | None) -> dict | None:
    if res is None:
        return None
    return {k: v for k, v in res.items() if k != "failed_criteria"}


def _success(s: dict) -> dict:
    out = {k: v for k, v in s.items() if k not in ("recorded", "generated", "by_seed")}
    out["recorded"] = _judged(s.get("recorded"))
    out["generated"] = {i: _judged(r) for i, r in s.get("generated", {}).items()}
    out["by_seed"] = {seed: {i: _judged(r) for i, r in g.items()} for seed, g in s.get("by_seed", {}).items()}
    return out


_CLUSTER_ROW = ("init", "codes", "tau", "r2", "rank", "accuracy", "nmi", "ari")


def _clustering(c: dict) -> dict:
    def rows(rs):
        return [{k: r.get(k) for k in _CLUSTER_ROW} for r in rs]

    return {
        "latent_dim": c.get("latent_dim"),
        "seed": c.get("seed"),
        "r2_target": c.get("r2_target"),
        "latent": rows(c.get("latent", [])),
        "by_seed": {s: rows(rs) for s, rs in c.get("by_seed", {}).items()},
        # every seed's codes clustered after a rescaling (issue 42), with their size before it
        "rescaled": [
            {k: r.get(k) for k in ("init", "seed", "rescaling", "rms", *_CLUSTER_ROW)} for r in c.get("rescaled", [])
        ],
        "trajectory": {
            name: {k: t.get(k) for k in ("n", "dim", "k", "r2_target", "chosen")}
            for name, t in c.get("trajectory", {}).items()
        },
    }


def _inter(i: dict) -> dict:
    keep = ("fold", "primitive", "init", "latent_dim", "seed", "n_phase1", "n_new", "n_replay", "seconds")
    return {
        "latent_dim": i.get("latent_dim"),
        "replay": i.get("replay"),
        "failures": i.get("failures", {}),
        "runs": [
            {k: r.get(k) for k in keep} | {"phase1": _curve(r["phase1"], set()), "phase2": _curve(r["phase2"])}
            for r in i.get("runs", [])
        ],
    }


def _probe(p: dict) -> dict:
    return {
        "runs": [
            {k: r.get(k) for k in ("init", "latent_dim", "seed")}
            | {codes: {"mean_r2": r.get(codes, {}).get("mean_r2")} for codes in ("fitted", "inferred", "initial")}
            for r in p.get("runs", [])
        ]
    }


def _tune(t: dict) -> dict:
    return {k: t.get(k) for k in ("latent_dim", "grid", "settings", "validation", "chosen", "failures")} | {
        "tuned": {"runs": [_intra(x) for x in t.get("tuned", {}).get("runs", [])]}
    }


def _seeds_run(p: dict) -> list[int]:
    """The seeds a grid over seeds holds (its ``by_seed``), in order."""
    return sorted(int(s) for s in p.get("by_seed", {}))


def _predict(p: dict) -> dict:
    """The predict results kept (the grid's version and its rows given the primitive where the results say them)."""
    return (
        {k: p.get(k) for k in ("latent_dim", "fractions", "starts", "peers", "epochs", "judged", "table", "failures")}
        | {k: p[k] for k in ("version", "given_rows") if k in p}
        | {"seeds": _seeds_run(p)}
    )


def _scene(p: dict) -> dict:
    return {k: p.get(k) for k in ("latent_dim", "epochs", "judged", "methods", "table", "failures")} | {
        "seeds": _seeds_run(p)
    }


def _act(a: dict) -> dict:
    """The act results kept: the settings, the table over seeds, the rows' order, and per seed
    its sizes, its plan latency and each row's entry over all primitives (not per primitive)."""
    keep = ("latent_dim", "every", "move_at", "perturbation", "scene_rows", "loop_rows", "table", "failures")
    small = ("latency_ms", "n_fitted", "n_test", "has_image_head", "loop_settings", "loop_tuning")
    return {k: a.get(k) for k in keep} | {
        "by_seed": {
            seed: {k: r.get(k) for k in small}
            | {part: {row: e.get(ALL) for row, e in r.get(part, {}).items()} for part in ("scene", "loop")}
            for seed, r in a.get("by_seed", {}).items()
        },
        "seeds": _seeds_run(a),
    }


def _composite(c: dict) -> dict:
    keep = (
        "init",
        "latent_dim",
        "seed",
        "window",
        "n_train",
        "n_eval",
        "seconds",
        "segmentation",
        "segmentation_untrained",
    )
    return {k: c.get(k) for k in ("failures", "splits", "window", "label_names")} | {
        "runs": [
            {k: r.get(k) for k in keep} | {"fit": _curve(r["fit"]), "infer": _curve(r["infer"])}
            for r in c.get("runs", [])
        ],
        "peers": c.get("peers", {}),
        "primitives": c.get("primitives", []),
    }


def _regime(r: dict) -> dict:
    """The regime results kept: the settings, the tables over seeds, and per seed each row's MSE and success
    (not per primitive)."""
    keep = (
        "version",
        "latent_dim",
        "fractions",
        "fitted_per_primitive",
        "eval_per_primitive",
        "train_fraction",
        "mixed_few",
        "rows",
        "given_rows",
        "judged",
        "settings",
        "label_names",
        "table",
        "mixed",
        "failures",
    )

    def small(point: dict) -> dict:
        return {
            row: {f: {k: e[k] for k in ("mse", "success", "error") if k in e} for f, e in cells.items()}
            for row, cells in point["methods"].items()
        }

    return {k: r.get(k) for k in keep} | {
        "by_seed": {
            seed: {"n_eval": s.get("n_eval"), "n": {n: {"methods": small(p)} for n, p in s.get("n", {}).items()}}
            | ({"mixed": {"few": s["mixed"]["few"], "methods": small(s["mixed"])}} if "mixed" in s else {})
            for seed, s in r.get("by_seed", {}).items()
        }
    }


_REDUCERS = {
    "intra": lambda r: {
        "runs": [_intra(x) for x in r.get("runs", [])],
        "failures": r.get("failures", {}),
        "splits": r.get("splits", {}),
        "label_names": r.get("label_names"),
    },
    "success": _success,
    "clustering": _clustering,
    "inter": _inter,
    "probe": _probe,
    "tune": _tune,
    "predict": _predict,
    "scene": _scene,
    "composite": _composite,
    "act": _act,
    "regime": _regime,
}


def recorded_commands(meta: dict) -> str:
    """The ``primspace experiment`` commands experiment.json recorded, each once, in order, one per line."""
    seen: list[str] = []
    for entry in meta.get("invocations", []):
        if isinstance(entry, dict) and isinstance(entry.get("command"), str) and entry["command"] not in seen:
            seen.append(entry["command"])
    return "\n".join(seen)


def recorded_versions(meta: dict) -> str | None:
    """The primspace versions that ran into an experiment directory, in order, each once:
    the one that made it, then those of its recorded invocations (a later stage added by
    a newer version shows, e.g. ``"0.6.1, 0.8.0"``)."""
    seen: list[str] = [meta["primspace"]] if isinstance(meta.get("primspace"), str) else []
    for entry in meta.get("invocations", []):
        version = entry.get("primspace") if isinstance(entry, dict) else None
        if isinstance(version, str) and version not in seen:
            seen.append(version)
    return ", ".join(seen) or None


def summarize(out_dir: str | Path, name: str, command: str | None = None, note: str = "") -> dict:
    """The summary of experiment directory ``out_dir``.

    Parameters
    ----------
    out_dir : path
        A directory ``primspace experiment`` wrote.
    name : str
        The summary's name (its file in docs/results/ and its heading in the docs).
    command : str, optional
        The command(s) that made the directory, exactly as run (the docs print them);
        default: those experiment.json recorded (:func:`recorded_commands`; directories
        made before 0.6.1 recorded none: then give them).
    note : str
        Anything a reader must know (e.g. "other jobs shared the cores").

    Returns
    -------
    dict
        ``summary_version``, ``name``, ``command``, ``note``, ``primspace`` (the versions
        that ran into the directory, :func:`recorded_versions`), ``cpu`` (:func:`cpu_class` of this machine: run it where the
        runs ran), ``preset`` (the settings), ``timings``, ``data`` (the data summary) and
        ``results`` by experiment name (intra, success, clustering, inter, probe, tune, predict, scene,
        composite, act, regime: those run).
    """
    if not isinstance(name, str) or not name.strip() or any(c in name for c in "\n\r\x00"):
        raise UserError(f"the summary's name is a heading on one line, not empty: got {name!r}")
    meta = read_meta(out_dir)
    if command is None:
        command = recorded_commands(meta)
        if not command:
            raise UserError(
                f"{out_dir}: its experiment.json recorded no commands (made before 0.6.1): "
                "give --command, the command(s) that made it"
            )
    results = {}
    for key, reduce in _REDUCERS.items():
        found = read_results(out_dir, key)
        if found is not None:
            results[key] = reduce(found)
    if not results:
        raise UserError(f"{out_dir}: no results to summarise (run an experiment into it first)")
    data = read_results(out_dir, "data") or {}
    return {
        "summary_version": SUMMARY_VERSION,
        "name": name,
        "command": command,
        "note": note,
        "primspace": recorded_versions(meta),
        "cpu": cpu_class(),
        "preset": meta.get("preset_config", {}),
        "timings": meta.get("timings", {}),
        "data": {
            k: data.get(k) for k in ("n_samples", "length", "n_joints", "label_names", "image_shape") if k in data
        },
        "results": _round(results),
    }


def read_summary(path: str | Path) -> dict:
    """A stored summary, checked to be one (one clear line if not)."""
    try:
        summary = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise UserError(f"{path}: cannot read the summary ({exc})") from None
    if not isinstance(summary, dict) or summary.get("summary_version") != SUMMARY_VERSION:
        raise UserError(f"{path}: not a primspace summary of version {SUMMARY_VERSION}")
    return summary


def write_summary(path: str | Path, summary: dict, overwrite: bool = False) -> dict:
    """Write a summary compactly (one line per top-level key), atomically; an existing
    file only with ``overwrite``. Returns the summary written. (``primspace summarize`` also
    writes the codes of the runs beside it first, :mod:`primspace.experiments.summary_codes`,
    and names them in the summary's ``codes`` field.)
    """
    from primspace.utils.files import atomic_write_text

    lines = ",\n".join(f"{json.dumps(k)}: {json.dumps(v, separators=(',', ':'))}" for k, v in summary.items())
    atomic_write_text(path, "{\n" + lines + "\n}\n", overwrite)
    return summary
