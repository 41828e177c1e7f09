"""The predictor ``auto`` chooses (not a test): its K-fold errors on the fitted demonstrations against each
candidate's error on the held-out motions, on an experiment's intra runs.

For each seed: the projection fit of ``runs/intra/projection-q*-s{seed}`` is copied into a temporary
folder (nothing is written into the experiment) and its evaluation samples (the intra split's ``infer``
run) are predicted at each ``--fractions`` by every candidate of both tasks (without the primitive, and
given each motion's label): ``kfold`` is what :class:`primspace.predict.SelectedPredictor` scored on the
fitted demonstrations, ``chosen`` what it chose, ``test`` each candidate's mean unobserved MSE on the
evaluation samples (scaled units, the error of the tables). The choice is right when ``chosen`` has the
lowest ``test``.

Usage::

    python benchmarks/eval_auto_predictor.py EXPERIMENT_DIR [--seeds 0] [--fractions 0.25] [--folds 3]
        [--tasks both|free|given] [--max-test N] [--json PATH]
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from primspace.data import MotionDataset  # noqa: E402
from primspace.predict import SelectedPredictor, fit_predictor  # noqa: E402
from primspace.predict.metrics import finite_mean, unobserved_mse  # noqa: E402
from primspace.predict.selection import SELECTION_FOLDS  # noqa: E402
from primspace.train import load_run  # noqa: E402
from primspace.train.observe import Observation  # noqa: E402
from primspace.utils.files import atomic_write_json  # noqa: E402


def one_task(run, test: MotionDataset, fraction: float, given: bool, folds: int = SELECTION_FOLDS) -> dict:
    """The selection of one task and every candidate's error on ``test``."""
    rule = Observation.build(fraction)
    truth = run.scaler.transform(test.motor)
    observed = rule.masks(test.valid_lengths, test.length)[0]
    start = time.perf_counter()
    auto = fit_predictor(SelectedPredictor(run, given=given, folds=folds, reuse=False), run)
    selection = auto.select(rule)
    seconds = time.perf_counter() - start
    errors = {}
    for name in auto.candidates_:
        chosen = name == selection["chosen"]
        predictor = auto.chosen(rule) if chosen else fit_predictor(auto.build(name, run), run)
        predicted = predictor.predict(truth, rule, test.labels if given else None, test.valid_lengths)
        errors[name] = finite_mean(unobserved_mse(predicted, truth, observed, test.valid_lengths))
    best = min(errors, key=errors.get)
    return {**selection, "test": errors, "right": best == selection["chosen"], "seconds": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("experiment", type=Path)
    parser.add_argument("--seeds", default="0")
    parser.add_argument("--fractions", default="0.25")
    parser.add_argument(
        "--max-test", type=int, default=None, help="at most this many evaluation samples, evenly spaced"
    )
    parser.add_argument("--folds", type=int, default=SELECTION_FOLDS)
    parser.add_argument("--tasks", choices=("both", "free", "given"), default="both")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    out = {}
    for seed in (int(s) for s in args.seeds.split(",")):
        (split,) = sorted((args.experiment / "runs" / "intra").glob(f"projection-q*-s{seed}"))
        with tempfile.TemporaryDirectory() as tmp:
            shutil.copytree(split / "fit", Path(tmp) / "fit")
            run = load_run(Path(tmp) / "fit")
            test_indices = json.loads((split / "infer" / "config.json").read_text())["data"]["indices"]
            if args.max_test is not None and len(test_indices) > args.max_test:
                test_indices = np.asarray(test_indices)[
                    np.linspace(0, len(test_indices) - 1, args.max_test).astype(int)
                ]
            test = MotionDataset.load(run.data_path).without_images().subset(np.asarray(test_indices))
            for fraction in (float(f) for f in args.fractions.split(",")):
                for given in {"both": (False, True), "free": (False,), "given": (True,)}[args.tasks]:
                    key = f"seed {seed}, {fraction:g}, {'given the primitive' if given else 'no primitive'}"
                    out[key] = one_task(run, test, fraction, given, args.folds)
                    print(key, json.dumps(out[key]), flush=True)
    right = sum(row["right"] for row in out.values())
    print(f"auto chose the candidate with the lowest held-out error in {right} of {len(out)} tasks")
    if args.json is not None:
        atomic_write_json(args.json, out)


if __name__ == "__main__":
    main()
