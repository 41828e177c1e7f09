"""The declared sweep of the judge's "held" distance and the Wilson intervals: each motion
replayed once, the default tolerance's verdicts unchanged, a push that backs off 7 mm
after delivery passing at 8 and 10 mm only, rates monotone in the tolerance."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from primspace.data import MotionDataset
from primspace.experiments.success import (
    point_by_tolerance,
    point_intervals,
    point_successes,
    run_success_point,
    separation_key,
)
from primspace.sim import success as success_module
from primspace.sim.primitives import PRIMITIVES, Script, min_jerk, script_motion
from primspace.sim.scene import JOINT_NAMES
from primspace.sim.success import (
    SEPARATION_SWEEP,
    TOLERANCES,
    evaluate,
    evaluate_batch_sweep,
    evaluate_dataset,
    evaluate_dataset_sweep,
    success_rates,
)
from primspace.utils.errors import UserError
from primspace.utils.stats import normal_quantile, wilson_interval
from test_sim_success import BLOCKS, joints_of, scene  # noqa: F401 (scene: the shared fixture)

BACK_OFF_GAP = 0.007  # the hold-window gap of the backed-off motions (m)


def backed_off(scene, primitive: str, block, gap: float = BACK_OFF_GAP) -> np.ndarray:
    """Joints of a push or pull that delivers the block, then backs the hand off it (along
    the push axis, after t = 0.90) until the closer finger is ``gap`` from the block.

    The gap is not exactly the TCP's back-off (the fingertips' shape, the IK): one
    correction step brings it within 0.5 mm."""
    script = script_motion(scene, primitive, *block, 61)
    t = np.linspace(0.0, 1.0, len(script.tcp))
    ramp = min_jerk(np.clip((t - 0.90) / 0.10, 0.0, 1.0))

    def moved(back: float) -> tuple[np.ndarray, float]:
        tcp = script.tcp.copy()
        tcp[:, 0] -= script.push_sign * back * ramp
        joints = joints_of(
            scene,
            Script(
                script.primitive,
                tcp,
                script.fingers.copy(),
                script.block_xy.copy(),
                script.size,
                script.contact_start,
                script.push_axis,
                script.push_sign,
            ),
        )
        return joints, evaluate(primitive, joints, block).measures["held"]

    _, held = moved(0.0)  # the script's own gap, < 1 mm
    back = gap - held
    _, held = moved(back)
    joints, held = moved(back + gap - held)
    return joints


@pytest.fixture(scope="module")
def motions(scene):  # noqa: F811 (the imported fixture)
    """Every primitive's ground truth at one block, a push and a pull backed off by 7 mm, a
    push displaced 2 cm sideways and a reversed pull: 11 motions (solved once)."""
    block = BLOCKS[2]
    names = list(PRIMITIVES) + ["push", "pull", "push", "pull"]
    motor = [joints_of(scene, script_motion(scene, p, *block, 61)) for p in PRIMITIVES]
    motor += [backed_off(scene, "push", block), backed_off(scene, "pull", block)]
    motor.append(joints_of(scene, script_motion(scene, "push", *block, 61).displaced((0.0, 0.02, 0.0))))
    motor.append(motor[PRIMITIVES.index("pull")][::-1])
    return MotionDataset(
        np.stack(motor),
        labels=[PRIMITIVES.index(n) for n in names],
        params=[block] * len(names),
        joint_names=list(JOINT_NAMES),
        label_names=list(PRIMITIVES),
        param_names=["block_x", "block_y", "block_size"],
    )


def test_the_sweep_is_declared_and_holds_the_default():
    assert SEPARATION_SWEEP == (0.004, 0.006, 0.008, 0.010)
    assert TOLERANCES.separation in SEPARATION_SWEEP
    assert list(SEPARATION_SWEEP) == sorted(set(SEPARATION_SWEEP))
    assert [separation_key(s) for s in SEPARATION_SWEEP] == ["0.004", "0.006", "0.008", "0.010"]
    assert separation_key(0.0045) == "0.0045"


def test_default_tolerance_verdicts_equal_evaluate_dataset(motions):
    sweep = evaluate_dataset_sweep(motions)
    assert list(sweep) == list(SEPARATION_SWEEP)
    today = evaluate_dataset(motions)
    at_default = sweep[TOLERANCES.separation]
    assert len(at_default) == len(today) == len(motions)
    for new, old in zip(at_default, today):
        assert (new.primitive, new.success, new.reason, new.criteria, new.measures) == (
            old.primitive,
            old.success,
            old.reason,
            old.criteria,
            old.measures,
        )
    # the set is a mix: ground truth passes, the displaced push and reversed pull fail
    assert [r.success for r in today] == [True] * 9 + [False, False]


def test_a_push_backed_off_7mm_passes_at_8_and_10mm_only(motions):
    sweep = evaluate_dataset_sweep(motions)
    for i, name in ((7, "push"), (8, "pull")):
        verdicts = {s: sweep[s][i] for s in SEPARATION_SWEEP}
        assert verdicts[0.010].primitive == name
        gap = verdicts[0.010].measures["held"]
        assert gap == pytest.approx(BACK_OFF_GAP, abs=5e-4), (name, gap)
        assert [verdicts[s].success for s in SEPARATION_SWEEP] == [False, False, True, True], (name, gap)
        for s in (0.004, 0.006):  # only "held" fails, and the reason names the distance
            failed = [c for c, ok in verdicts[s].criteria.items() if not ok]
            assert failed == ["held"], (name, s, verdicts[s].reason)
            assert f"at most {s * 1e3:.1f} mm" in verdicts[s].reason
    # the ground-truth push stays within 1 mm: it passes at every distance
    assert all(sweep[s][PRIMITIVES.index("push")].success for s in SEPARATION_SWEEP)


def test_rates_are_monotone_in_the_tolerance_and_other_primitives_unchanged(motions):
    sweep = evaluate_dataset_sweep(motions)
    rates = {s: success_rates(sweep[s]) for s in SEPARATION_SWEEP}
    for p in rates[TOLERANCES.separation]:
        row = [rates[s][p] for s in SEPARATION_SWEEP]
        assert row == sorted(row), (p, row)
    for i in range(len(motions)):  # per motion: a success stays a success at a larger distance
        ok = [sweep[s][i].success for s in SEPARATION_SWEEP]
        assert ok == sorted(ok), (i, ok)
    for i, p in enumerate(PRIMITIVES):  # no "held" criterion: one verdict at every distance
        if p not in ("push", "pull"):
            assert "held" not in sweep[0.010][i].criteria
            assert all(sweep[s][i] is sweep[0.010][i] for s in SEPARATION_SWEEP), p
    assert rates[0.004]["push"] < rates[0.008]["push"]


def test_each_motion_is_replayed_once(motions, monkeypatch):
    calls = []
    real = success_module.replay

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(success_module, "replay", counting)
    sweep = evaluate_dataset_sweep(motions)
    assert len(calls) == len(motions)
    assert all(len(v) == len(motions) for v in sweep.values())
    calls.clear()
    evaluate_dataset(motions)  # the plain judge still replays each motion once too
    assert len(calls) == len(motions)


def test_bad_sweeps_are_refused(motions):
    with pytest.raises(UserError, match="must include the judge's own"):
        evaluate_dataset_sweep(motions, separations=(0.004, 0.006))
    with pytest.raises(UserError, match="positive"):
        evaluate_dataset_sweep(motions, separations=(-0.004, 0.010))
    with pytest.raises(UserError, match=r"joints \(N, T, 9\)"):
        evaluate_batch_sweep(["push"], np.zeros((61, 9)), [[0.5, 0.0, 0.05]])
    # a sweep of two distances, given unsorted and with a duplicate
    two = evaluate_dataset_sweep(motions, separations=(0.010, 0.004, 0.010))
    assert list(two) == [0.004, 0.010]


def test_wilson_interval_known_values():
    z = 1.959963984540054
    assert normal_quantile(0.95) == pytest.approx(z, abs=1e-12)
    assert normal_quantile(0.99) == pytest.approx(2.5758293035489, abs=1e-9)
    # 0 of 10 and 10 of 10: (0, z^2 / (n + z^2)) and (n / (n + z^2), 1)
    assert wilson_interval(0, 10) == (0.0, pytest.approx(z**2 / (10 + z**2), abs=1e-12))
    assert wilson_interval(0, 10)[1] == pytest.approx(0.2775, abs=5e-5)  # the textbook value
    assert wilson_interval(10, 10) == (pytest.approx(10 / (10 + z**2), abs=1e-12), 1.0)
    assert wilson_interval(10, 10)[0] == pytest.approx(0.7225, abs=5e-5)
    # 5 of 10: centre 1/2, half-width z / (1 + z^2/n) * sqrt(1/40 + z^2/400)
    low, high = wilson_interval(5, 10)
    half = z / (1 + z**2 / 10) * math.sqrt(0.25 / 10 + z**2 / 400)
    assert (low, high) == (pytest.approx(0.5 - half, abs=1e-12), pytest.approx(0.5 + half, abs=1e-12))
    assert (round(low, 4), round(high, 4)) == (0.2366, 0.7634)
    # 196 of 196: 196 / (196 + z^2) = 0.98078
    assert wilson_interval(196, 196) == (pytest.approx(196 / (196 + z**2), abs=1e-12), 1.0)
    assert wilson_interval(196, 196)[0] == pytest.approx(0.98078, abs=5e-6)
    # 8 of 10, hand-computed: centre (0.8 + 0.19207) / 1.38415 = 0.71674, half 0.22658
    assert wilson_interval(8, 10) == (pytest.approx(0.4902, abs=5e-5), pytest.approx(0.9433, abs=5e-5))


def test_wilson_interval_properties_and_errors():
    assert wilson_interval(0, 0) == (0.0, 1.0)
    for k, n in ((3, 7), (1, 50), (37, 40)):
        low, high = wilson_interval(k, n)
        mirrored = wilson_interval(n - k, n)
        assert (low, high) == (pytest.approx(1 - mirrored[1], abs=1e-12), pytest.approx(1 - mirrored[0], abs=1e-12))
        assert 0 <= low < k / n < high <= 1
        wide = wilson_interval(k, n, confidence=0.99)
        assert wide[0] < low and wide[1] > high
        narrow = wilson_interval(10 * k, 10 * n)
        assert narrow[1] - narrow[0] < high - low
    assert wilson_interval(np.int64(4), np.int64(8)) == wilson_interval(4, 8)
    for bad in ((11, 10), (-1, 10), (2, -1), (1.5, 10)):
        with pytest.raises(ValueError):
            wilson_interval(*bad)
    with pytest.raises(ValueError, match="confidence"):
        wilson_interval(1, 2, confidence=1.0)


def test_run_success_point_reports_every_tolerance_and_intervals(tiny_data, tmp_path, monkeypatch):
    import primspace.train

    monkeypatch.setattr(primspace.train, "configure_process", lambda tc: None)  # keep this process's threads
    res = json.loads(json.dumps(run_success_point(tmp_path, str(tiny_data), None)))  # as stored
    data = MotionDataset.load(tiny_data)
    verdicts = evaluate_dataset(data.without_images())
    names = [PRIMITIVES[i] for i in data.labels]
    assert res["counts"] == {p: names.count(p) for p in dict.fromkeys(names)}
    assert res["rates"] == success_rates(verdicts) and res["overall"] == 1.0
    assert res["failed_criteria"] == {p: {} for p in res["counts"]}
    assert res["successes"] == res["counts"]
    assert list(res["by_tolerance"]) == ["0.004", "0.006", "0.008", "0.010"]
    for entry in res["by_tolerance"].values():
        assert set(entry) == {"rates", "successes", "overall"}
        assert set(entry["rates"]) == set(entry["successes"]) == set(res["counts"])
    default = res["by_tolerance"][separation_key(TOLERANCES.separation)]
    assert default == {"rates": res["rates"], "successes": res["successes"], "overall": res["overall"]}
    assert set(res["intervals"]) == set(res["counts"]) | {"all"}
    for p, n in res["counts"].items():
        assert res["intervals"][p] == list(wilson_interval(res["successes"][p], n))
    assert res["intervals"]["all"] == list(wilson_interval(len(names), len(names)))
    # an old point, stored before the sweep, reads back with its default tolerance only
    old = {k: res[k] for k in ("rates", "counts", "overall", "failed_criteria")}
    assert point_successes(old) == res["successes"]
    assert point_intervals(old) == res["intervals"]
    assert point_by_tolerance(old) == {"0.010": default}
    assert point_by_tolerance(res) == res["by_tolerance"]
