"""The closed loop measured fairly (issue 52): its settings chosen on the fitted demonstrations only
(:class:`~primspace.act.tuning.LoopTuner`), the move at the declared fractions, and the ProMP peer
that sees (:class:`~primspace.act.planners.SeeingProMPPlanner`).

The grid choice is checked on a constructed case (a scripted episode); the rest on the tiny
simulated set of test_scene_policy.py (touch and push, a 3 x 3 grid of blocks, T = 31, with frames)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from primspace.act.episode import MOVE_AT
from primspace.act.tuning import LOOP_CENTRE, LoopTuner, configured
from primspace.data.scaling import JointScaler
from test_scene_policy import T, held_out, simulate

pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)


def _constructed(n_per_label: int = 6):
    """Two labels of ``n_per_label`` demonstrations, with motor, params and (tiny) frames."""
    labels = np.repeat([0, 2], n_per_label)
    rng = np.random.default_rng(0)
    return SimpleNamespace(
        labels=labels,
        motor=rng.normal(size=(len(labels), T, 9)).astype(np.float32),
        params=np.tile([0.5, 0.0, 0.05], (len(labels), 1)),
        images=np.zeros((len(labels), T, 2, 2, 3), np.uint8),
    )


class _Identity:
    def transform(self, x):
        return np.asarray(x)


def test_the_chosen_setting_is_the_best_of_its_grid_and_every_point_is_recorded():
    fitted = _constructed()
    grid = {"threshold": (2.0, 4.5), "horizon": (2, 8), "every": (5,)}
    best = dict(LOOP_CENTRE, horizon=8)

    def runner(policy, settings, i, move):  # the best point wins every episode, the centre half of them
        return settings == best or (settings == LOOP_CENTRE and i % 2 == 0)

    tuner = LoopTuner(grid=grid, per_primitive=2, seed=3)
    record = tuner.tune(fitted, _Identity(), lambda *a: "policy", indices=np.arange(100, 112), runner=runner)
    assert record.chosen == best
    assert record.points[0] == LOOP_CENTRE and len(record.points) == 1 + 5  # the centre, then each value alone
    assert record.scores[record.points.index(best)] == 1.0 and max(record.scores) == 1.0
    assert record.episodes == len(record.points) * 4 * (len(MOVE_AT) + 1)  # 4 scenes, each move and still
    out = record.to_dict()
    assert len(out["grid"]) == len(record.points) and out["chosen"] == best
    assert set(out["grid"][0]["by_condition"]) == {"move at 0.2", "move at 0.3", "still"}


def test_a_tie_goes_to_the_centre():
    record = LoopTuner(grid={"threshold": (2.0, 4.5)}, per_primitive=1).tune(
        _constructed(), _Identity(), lambda *a: "policy", runner=lambda *a: True
    )
    assert record.chosen == LOOP_CENTRE


def test_the_tuner_fits_and_replays_only_the_demonstrations_it_is_given():
    """The policy of each fold is fitted on the other folds' demonstrations; the replayed scenes are the
    given demonstrations (their indices in the data file), never another index."""
    fitted = _constructed()
    indices = np.arange(200, 212)
    fits, replays = [], []

    def fit_policy(motor, labels, frames, steps):
        fits.append(len(motor))
        return SimpleNamespace(rows=len(motor))

    def runner(policy, settings, i, move):
        replays.append(i)
        return True

    record = LoopTuner(grid={"threshold": (2.0,)}, per_primitive=2, folds=3).tune(
        fitted, _Identity(), fit_policy, indices=indices, runner=runner
    )
    assert set(replays) <= set(range(len(fitted.labels)))
    assert set(record.replayed) <= set(indices.tolist()) and len(record.replayed) == 4
    assert all(n == 8 for n in fits)  # 12 demonstrations in 3 folds: each policy fitted on 8


def test_configured_changes_the_settings_and_not_the_fitted_policy():
    policy = SimpleNamespace(threshold=3.0, horizon=4, floor=0.25, visible=0.6, maps_={})
    other = configured(policy, dict(LOOP_CENTRE, threshold=2.0, horizon=8, visible=0.8))
    assert (other.threshold, other.horizon, other.visible) == (2.0, 8, 0.8) and other.maps_ is policy.maps_
    assert policy.threshold == 3.0 and policy.horizon == 4


def test_the_move_fractions_are_checked_and_give_their_steps():
    from primspace.act.episode import drawn_move
    from primspace.experiments.act import check_move_at, loop_rows
    from primspace.utils.errors import UserError

    assert check_move_at("0.2,0.3") == (0.2, 0.3) == MOVE_AT
    for bad in ("0.2,0.2", "1.5", "x", ""):
        with pytest.raises(UserError):
            check_move_at(bad)
    moves = [drawn_move(a, np.random.default_rng([0, 40, 1]), 0.5, 0.0, 0.05, 61) for a in MOVE_AT]
    assert [m.step for m in moves] == [12, 18] and moves[0].dx == moves[1].dx  # the same draw, another step
    rows = loop_rows(MOVE_AT)
    assert "closed loop, moved at 20 %" in rows and "contextual ProMP re-planned (sees), moved at 30 %" in rows


# ------------------------------------------------------------------------ on the simulator


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    data = simulate(tmp_path_factory.mktemp("tuning") / "sim.h5")
    held = held_out(data)
    fitted = np.setdiff1d(np.arange(len(data)), held)
    scaler = JointScaler().fit(data.motor[fitted])
    return dict(data=data, held=held, fitted=fitted, scaler=scaler)


@pytest.mark.slow
def test_the_seeing_promp_peer_replans_when_the_block_moves(sim):
    from primspace.act.planners import SeeingProMPPlanner
    from primspace.act.scene_peers import ContextualProMPPeer
    from primspace.sim.execute import Executor

    data, fitted, scaler = sim["data"], sim["fitted"], sim["scaler"]
    motor = scaler.transform(data.motor).astype(np.float64)
    peer = ContextualProMPPeer(features="blob").fit(
        motor[fitted], data.labels[fitted], None, np.asarray(data.images)[fitted]
    )
    i = int(sim["held"][1])  # the held-out push
    label, (x, y, size) = int(data.labels[i]), (float(v) for v in data.params[i, :3])
    with Executor(label, x, y, size, T) as executor:
        executor.step(data.motor[i, 0])
        still = executor.frame()
        executor.move_block(0.0, 0.04)
        moved = executor.frame()
    executed = motor[i, :4]
    plans = {}
    for name, later in (("still", still), ("moved", moved)):
        planner = SeeingProMPPlanner(peer, label, T, every=3)
        first = planner.plan(0, still, executed[:1])
        plans[name] = planner.plan(3, later, executed)
        assert np.allclose(plans[name][:4], executed) and plans[name].shape == (T, 9)
        assert len(planner.contexts) == 2
    np.testing.assert_allclose(plans["still"], SeeingProMPPlanner(peer, label, T, 3).plan(3, still, executed))
    assert np.abs(plans["moved"] - plans["still"]).max() > 1e-3  # it saw the move and re-planned
    assert np.abs(first - plans["still"]).max() > 0  # conditioned on the executed steps


@pytest.mark.slow
def test_the_tuner_replays_fitted_scenes_in_mujoco_and_the_policy_it_fits(sim):
    from primspace.act.scene_policy import ScenePolicy

    data, fitted, scaler = sim["data"], sim["fitted"], sim["scaler"]
    sub = data.subset(fitted).load_images()
    seen = []

    def fit_policy(motor, labels, frames, steps):
        seen.append((len(motor), steps))
        return ScenePolicy(steps=steps, label_names=sub.label_names).fit(motor, labels, None, frames)

    tuner = LoopTuner(grid={"threshold": (2.0,), "every": (5,)}, per_primitive=1, folds=2)
    record = tuner.tune(sub, scaler, fit_policy, indices=fitted)
    assert set(record.replayed) <= set(fitted.tolist()) and not set(record.replayed) & set(sim["held"].tolist())
    assert record.episodes == 3 * 2 * (len(MOVE_AT) + 1)  # 3 points, 2 scenes, each move and still
    assert all(0.0 <= s <= 1.0 for s in record.scores) and record.chosen in record.points
    assert all(n == 8 for n, _ in seen) and 5 in seen[0][1] and 3 in seen[0][1]  # maps at every point's looks


@pytest.mark.slow
def test_the_declared_fractions_reach_the_episodes_of_every_moved_row(sim, monkeypatch):
    import primspace.act
    from primspace.act.scene_peers import ContextualProMPPeer
    from primspace.act.scene_policy import ScenePolicy
    from primspace.experiments.act import CLOSED_STILL, loop_rows, loop_successes
    from primspace.predict.peers import ProMPPeer

    data, fitted, scaler = sim["data"], sim["fitted"], sim["scaler"]
    motor = scaler.transform(data.motor).astype(np.float64)
    frames = np.asarray(data.images)
    args = (motor[fitted], data.labels[fitted], None, frames[fitted])
    planners = (
        ScenePolicy(steps=tuple(range(0, T - 1, 5)), label_names=data.label_names).fit(*args),
        ProMPPeer().fit(*args[:3]),
        ContextualProMPPeer(features="blob").fit(*args),
    )
    steps, real = [], primspace.act.run_episode

    def recording(planner, executor, first, scaler_, length, move=None, record_frames=False):
        steps.append(None if move is None else move.step)
        return real(planner, executor, first, scaler_, length, move, record_frames)

    monkeypatch.setattr(primspace.act, "run_episode", recording)
    test = data.subset(sim["held"][:1]).load_images()
    move_at = (0.2, 0.5)
    success, latency = loop_successes(
        SimpleNamespace(scaler=scaler), test, dict(LOOP_CENTRE, every=5), 0, planners, move_at
    )
    assert set(success) == set(loop_rows(move_at)) and CLOSED_STILL in success
    assert sorted(steps, key=str) == sorted([None] + [6] * 4 + [15] * 4, key=str)  # round(a * 30)
    assert latency["median"] >= 0


def test_move_at_is_an_option_of_experiment_act_checked_before_any_work(run_cli, tmp_path):
    from conftest import assert_user_error

    assert_user_error(run_cli("experiment", "act", "--move-at", "0.2,1.5", "--out", tmp_path / "a"), "--move-at")
    assert_user_error(
        run_cli("experiment", "intra", "--move-at", "0.2", "--out", tmp_path / "b"), "--move-at", "experiment act"
    )
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_the_tables_name_both_fractions_and_the_tuned_interval():
    from primspace.experiments.act import act_summary, loop_rows
    from primspace.results.act import act_tables, every_text, move_text

    entry = {"all": {"n": 2, "success": 0.5, "model_share": 0.0}}
    by_seed = {
        str(s): {
            "loop": {row: entry for row in loop_rows()},
            "latency_ms": {"median": 1.0},
            "loop_settings": {"every": e},
        }
        for s, e in ((0, 3), (1, 5))
    }
    results = {
        "table": act_summary(by_seed),
        "loop_rows": list(loop_rows()),
        "by_seed": by_seed,
        "every": "tuned",
        "move_at": [0.2, 0.3],
        "perturbation": {"at": [0.2, 0.3], "distance_m": [0.02, 0.04]},
    }
    titles = [title for title, _, _ in act_tables(results)]
    assert "Block moved at 20 % and 30 %: success (2 seeds)" in titles
    assert move_text(results) == "20 % and 30 %" and "every 3, 5 steps" in every_text(results)
    assert move_text({"perturbation": {"at": 0.3}}) == "30 %" and every_text({"every": 3}) == "every 3 steps"
