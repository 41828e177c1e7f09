"""Success rates of generated motions (paper, Table "Success rates of trained models").

The paper judged grasp, push and pull by watching videos of the generated motions. Here
the simulator judges every primitive objectively (:mod:`primspace.sim.success`): the
codes inferred for the eval part are decoded to joint trajectories (physical units) and
replayed through the arm's kinematics. The recorded (ground-truth) trajectories are
judged too, as a check of the judge: they must all succeed.

Every motion is replayed once and judged at each "held" distance of the declared
:data:`~primspace.sim.success.SEPARATION_SWEEP` (4-10 mm; the 10 mm default was chosen
after results were seen), and each rate comes with its Wilson 95 % interval
(:func:`primspace.utils.stats.wilson_interval`). Results files written before the sweep lack
``successes``, ``by_tolerance`` and ``intervals``: read them through
:func:`point_by_tolerance`, :func:`point_successes` and :func:`point_intervals`.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.intra import run_intra
from primspace.experiments.runs import focus_runs
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import intra_run_dir
from primspace.utils.stats import wilson_interval

__all__ = [
    "run_success",
    "run_success_point",
    "separation_key",
    "point_by_tolerance",
    "point_successes",
    "point_intervals",
]


def separation_key(separation: float) -> str:
    """The key of a judge tolerance (m) in ``by_tolerance``: ``0.01`` -> ``"0.010"``.

    Three decimals (whole millimetres, as :data:`~primspace.sim.success.SEPARATION_SWEEP`);
    a finer distance keeps its digits (``0.0045`` -> ``"0.0045"``).
    """
    s = float(separation)
    return f"{s:.3f}" if round(s, 3) == s else repr(s)


def _summary(results: list) -> tuple[dict, dict, dict, float]:
    """``(by_primitive, rates, successes, overall)`` of verdicts, primitives in order of appearance."""
    by_primitive: dict[str, list] = {}
    for r in results:
        by_primitive.setdefault(r.primitive, []).append(r)
    rates = {p: float(np.mean([r.success for r in rs])) for p, rs in by_primitive.items()}
    successes = {p: int(sum(r.success for r in rs)) for p, rs in by_primitive.items()}
    return by_primitive, rates, successes, float(np.mean([r.success for r in results]))


def _intervals(successes: dict, counts: dict) -> dict[str, list[float]]:
    """Wilson 95 % intervals per primitive and over all (``"all"``)."""
    out = {p: list(wilson_interval(successes[p], counts[p])) for p in successes}
    out["all"] = list(wilson_interval(sum(successes.values()), sum(counts.values())))
    return out


def run_success_point(run_dir: Path, data_path: str, infer_dir: str | None) -> dict:
    """Judge one run's generated eval motions (or, with ``infer_dir=None``, the recorded ones).

    Each motion is replayed once and judged at every ``held`` distance of
    :data:`~primspace.sim.success.SEPARATION_SWEEP`.

    Returns
    -------
    dict
        At the judge's default tolerance: ``rates`` ({primitive: rate}), ``counts``
        ({primitive: n}), ``successes`` ({primitive: int}), ``overall`` (rate over all),
        ``failed_criteria`` ({primitive: {criterion: failures}}) and ``intervals``
        ({primitive or "all": [low, high]}, Wilson 95 %); and ``by_tolerance``:
        {:func:`separation_key`: {"rates", "successes", "overall"}} for every distance
        of the sweep (the default's equal to the fields above).
    """
    from primspace.sim.success import SEPARATION_SWEEP, TOLERANCES, evaluate_dataset_sweep
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
    sweep = evaluate_dataset_sweep(judged, motor, SEPARATION_SWEEP, TOLERANCES)
    by_primitive, rates, successes, overall = _summary(sweep[TOLERANCES.separation])
    counts = {p: len(rs) for p, rs in by_primitive.items()}
    by_tolerance = {}
    for separation, results in sweep.items():
        _, rates_s, successes_s, overall_s = _summary(results)
        by_tolerance[separation_key(separation)] = {"rates": rates_s, "successes": successes_s, "overall": overall_s}
    return {
        "rates": rates,
        "counts": counts,
        "overall": overall,
        "failed_criteria": {  # how often each criterion failed, per primitive
            p: dict(Counter(c for r in rs for c, ok in r.criteria.items() if not ok).most_common())
            for p, rs in by_primitive.items()
        },
        "successes": successes,
        "by_tolerance": by_tolerance,
        "intervals": _intervals(successes, counts),
    }


def point_by_tolerance(point: dict, default_separation: float = 0.010) -> dict[str, dict]:
    """A judged point's ``by_tolerance``; for a point stored before the sweep, its
    default-tolerance numbers only: ``{separation_key(default_separation): {...}}``.

    Parameters
    ----------
    point : dict
        A result of :func:`run_success_point` (``recorded``, ``generated[init]``, ...).
    default_separation : float
        The tolerance (m) an old point was judged at (``default_separation`` of the
        results file when present; 10 mm, the judge's only one before the sweep).
    """
    if "by_tolerance" in point:
        return point["by_tolerance"]
    return {
        separation_key(default_separation): {
            "rates": point["rates"],
            "successes": point_successes(point),
            "overall": point["overall"],
        }
    }


def point_successes(point: dict) -> dict[str, int]:
    """``successes`` of a judged point, recovered as rate x count for a point stored before they were."""
    if "successes" in point:
        return point["successes"]
    return {p: int(round(rate * point["counts"][p])) for p, rate in point["rates"].items()}


def point_intervals(point: dict) -> dict[str, list[float]]:
    """``intervals`` of a judged point (Wilson 95 %), computed for a point stored before they were."""
    if "intervals" in point:
        return point["intervals"]
    return _intervals(point_successes(point), point["counts"])


def run_success(exp: ExperimentDir) -> dict:
    """Judge the generated eval motions of every init at the focus q (runs intra first if needed)."""
    from primspace.sim.success import JUDGE_VERSION, SEPARATION_SWEEP, SWEEP_VERSION, TOLERANCES, check_judgeable

    check_judgeable(exp.dataset())  # before any training: the judge needs simulator data
    intra = exp.read_results("intra") or run_intra(exp)
    q, seed, inits = focus_runs(exp, intra)
    # verdicts of an older judge, or stored before the tolerance sweep, are not reused
    judge = f"success/judge{JUDGE_VERSION}-sweep{SWEEP_VERSION}"
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
        "sweep_version": SWEEP_VERSION,
        "separation_sweep": list(SEPARATION_SWEEP),
        "default_separation": TOLERANCES.separation,
        "recorded": grid.results.get(f"{judge}/recorded"),
        "generated": {
            init: grid.results[f"{judge}/{init}-q{q}-s{seed}"]
            for init in inits
            if f"{judge}/{init}-q{q}-s{seed}" in grid.results
        },
        "by_seed": {  # the other seeds' verdicts, for the spread over seeds
            str(s): {
                i: grid.results[f"{judge}/{i}-q{q}-s{s}"]
                for i in exp.preset.inits
                if f"{judge}/{i}-q{q}-s{s}" in grid.results
            }
            for s in seeds
            if s != seed
        },
        "failures": grid.failures,
        "label_names": list(exp.dataset().label_names),
    }
    exp.write_results("success", results)
    return results
