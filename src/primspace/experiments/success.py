"""Success rates of generated motions (paper, Table "Success rates of trained models").

The paper judged grasp, push and pull by watching videos of the generated motions. Here
the simulator judges every primitive objectively (:mod:`primspace.sim.success`): the
codes inferred for the eval part are decoded to joint trajectories (physical units) and
replayed through the arm's kinematics. The recorded (ground-truth) trajectories are
judged too, as a check of the judge: they must all succeed.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.intra import run_intra
from primspace.experiments.runs import focus_runs, intra_run_dir
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir

__all__ = ["run_success", "run_success_point"]


def run_success_point(run_dir: Path, data_path: str, infer_dir: str | None) -> dict:
    """Judge one run's generated eval motions (or, with ``infer_dir=None``, the recorded ones)."""
    from primspace.sim.success import evaluate_dataset
    from primspace.train import TrainConfig, configure_process, load_run, reconstruct

    configure_process(TrainConfig(device="cpu", threads=1))  # reconstruct runs on the CPU, one thread per job
    data = MotionDataset.load(data_path)
    if infer_dir is None:
        judged = data.without_images()
        motor = None
    else:
        run = load_run(infer_dir)
        judged = data.without_images().subset(run.indices)
        motor, _ = reconstruct(run, images=False)
    results = evaluate_dataset(judged, motor)
    by_primitive: dict[str, list] = {}
    for r in results:
        by_primitive.setdefault(r.primitive, []).append(r)
    return {
        "rates": {p: float(np.mean([r.success for r in rs])) for p, rs in by_primitive.items()},
        "counts": {p: len(rs) for p, rs in by_primitive.items()},
        "overall": float(np.mean([r.success for r in results])),
        "failed_criteria": {  # how often each criterion failed, per primitive
            p: dict(Counter(c for r in rs for c, ok in r.criteria.items() if not ok).most_common())
            for p, rs in by_primitive.items()
        },
    }


def run_success(exp: ExperimentDir) -> dict:
    """Judge the generated eval motions of every init at the focus q (runs intra first if needed)."""
    from primspace.sim.success import JUDGE_VERSION, check_judgeable

    check_judgeable(exp.dataset())  # before any training: the judge needs simulator data
    intra = exp.read_results("intra") or run_intra(exp)
    q, seed, inits = focus_runs(exp, intra)
    judge = f"success/judge{JUDGE_VERSION}"  # verdicts of an older judge are not reused
    points = [GridPoint(f"{judge}/recorded", (str(exp.data_path), None))]
    seeds = sorted({r["seed"] for r in intra["runs"] if r["latent_dim"] == q})
    done = {(r["init"], r["seed"]) for r in intra["runs"] if r["latent_dim"] == q}
    for s in [seed] + [s for s in seeds if s != seed]:  # the focus seed's points first, as before
        for init in [i for i in exp.preset.inits if (i, s) in done]:
            infer_dir = intra_run_dir(exp.path, init, q, s) / "infer"
            points.append(GridPoint(f"{judge}/{init}-q{q}-s{s}", (str(exp.data_path), str(infer_dir))))
    with exp.stage("success"):
        grid = exp.grid(run_success_point, points, "success judging")
    results = {
        "latent_dim": q,
        "seed": seed,
        "judge_version": JUDGE_VERSION,
        "recorded": grid.results.get(f"{judge}/recorded"),
        "generated": {init: grid.results[f"{judge}/{init}-q{q}-s{seed}"] for init in inits if f"{judge}/{init}-q{q}-s{seed}" in grid.results},
        "by_seed": {  # the other seeds' verdicts, for the spread over seeds
            str(s): {i: grid.results[f"{judge}/{i}-q{q}-s{s}"] for i in exp.preset.inits if f"{judge}/{i}-q{q}-s{s}" in grid.results}
            for s in seeds if s != seed
        },
        "failures": grid.failures,
        "label_names": list(exp.dataset().label_names),
    }
    exp.write_results("success", results)
    return results

