"""Acting in the simulator (issue 40): an episode of a planner in MuJoCo (:func:`run_episode`) and
``primspace act RUN --primitive P --scene FILE:INDEX|x,y,size --out DIR``.

A tiny run (2 epochs) fitted on the simulated touch and push demonstrations of
test_scene_policy.py (their centre blocks held out as scenes); its data file has frames."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.act import PLANNERS, PolicyPlanner, run_episode
from primspace.act.episode import BlockMove
from primspace.act.planner import DEFAULT_EVERY
from primspace.data import MotionDataset
from primspace.train import TrainConfig, fit
from test_scene_policy import T, held_out, simulate
from test_train import SMALL

EVERY = 6
LOOKS = [0, 6, 12, 18, 24]  # 0, every, 2 every, ... before the last step (30)
CLI_LOOKS = list(range(0, 30, DEFAULT_EVERY))  # primspace act's default --every


pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """``data`` (frames), ``run`` fitted on all but the held-out scenes, ``bare`` (a run on the same motions
    without frames), ``held`` ({name: index in data})."""
    root = tmp_path_factory.mktemp("act")
    data = simulate(root / "data.h5")
    held = held_out(data)
    fitted = np.setdiff1d(np.arange(len(data)), held)
    config = dict(model_config=SMALL, train_config=TrainConfig(epochs=2, batch_size=16, threads=1), progress=False)
    fit(data, root / "run", indices=fitted, images=False, **config)
    data.without_images().save(root / "bare.h5")
    fit(MotionDataset.load(root / "bare.h5"), root / "bare", indices=fitted, **config)
    names = {data.label_names[int(data.labels[i])]: int(i) for i in held}
    return dict(root=root, data=root / "data.h5", run=root / "run", bare=root / "bare", held=names)


# ------------------------------------------------------------------------ run_episode


@pytest.mark.slow
def test_an_episode_looks_at_0_every_2_every_and_the_open_loop_once(files):
    from primspace.act.command import fit_planners
    from primspace.sim.execute import Executor
    from primspace.sim.scene import Scene
    from primspace.train import load_run
    from primspace.train.starts import fitted_samples

    run = load_run(files["run"])
    policy, _ = fit_planners(run, fitted_samples(run, None).load_images(), EVERY)
    data = MotionDataset.load(files["data"])
    i = files["held"]["push"]
    x, y, size = (float(v) for v in data.params[i, :3])
    k, first, scene = policy.primitives_.resolve("push"), data.motor[i, 0], Scene()
    episodes, corrections = {}, {}
    for name, every, move in (("closed", EVERY, None), ("open", None, None), ("moved", EVERY, BlockMove(9, 0, 0.04))):
        planner = PolicyPlanner(policy, k, every)
        with Executor("push", x, y, size, T, scene=scene) as ex:
            episodes[name] = run_episode(planner, ex, first, run.scaler, T, move, record_frames=name == "closed")
            assert ex.t == T
        corrections[name] = planner.corrections
    for name, e in episodes.items():
        assert e.motor.shape == e.first_plan.shape == (T, 9), name
        np.testing.assert_allclose(e.motor[0], first, atol=1e-5)  # the arm starts where it was put
        assert e.plan_steps == (LOOKS if name != "open" else [0]), name
        assert len(e.latencies_ms) == len(e.plan_steps) and all(0 <= v < 1e4 for v in e.latencies_ms)
        summary = e.summary()
        assert summary["looks"] == e.plan_steps and summary["reason"] == str(e.verdict.reason)
        assert summary["success"] == e.success and summary["latency_ms"]["max"] >= summary["latency_ms"]["median"]
    assert episodes["closed"].frames.shape == (T, 48, 64, 3) and episodes["closed"].frames.dtype == np.uint8
    assert episodes["open"].frames is None
    np.testing.assert_allclose(episodes["open"].motor, episodes["open"].first_plan, atol=1e-5)  # replayed
    assert episodes["moved"].move == BlockMove(9, 0, 0.04) and episodes["moved"].summary()["move"]["step"] == 9
    assert corrections["open"] == []
    assert corrections["moved"] and min(corrections["moved"]) > 9 and set(corrections["moved"]) <= set(LOOKS)


# ------------------------------------------------------------------------ primspace act


def _act(run_cli, files, out, *args):
    return run_cli("act", files["run"], "--primitive", "push", "--out", out, "--threads", "1", *args)


def _scene(files, name="push"):
    return f"{files['data']}:{files['held'][name]}"


@pytest.mark.slow
def test_act_writes_the_three_episodes_the_animation_and_the_result(run_cli, files, tmp_path):
    out = tmp_path / "out"
    res = _act(run_cli, files, out, "--scene", _scene(files), "--perturb")
    assert res.code == 0, res.err
    assert f"wrote {out}: push:" in res.out and "ms (median)" in res.out
    assert sorted(p.name for p in out.iterdir()) == ["act.gif", "executed.h5", "result.json"]
    executed = MotionDataset.load(out / "executed.h5")
    assert list(executed.source_ids) == list(PLANNERS) == ["closed loop", "open loop", "ProMP re-conditioned"]
    assert executed.motor.shape == (3, T, 9) and executed.has_images
    assert np.asarray(executed.images).shape == (3, T, 48, 64, 3)
    assert executed.label_names[int(executed.labels[0])] == "push" and len(set(executed.labels.tolist())) == 1
    data = MotionDataset.load(files["data"])
    i = files["held"]["push"]
    np.testing.assert_allclose(executed.params, np.tile(data.params[i, :3], (3, 1)), atol=1e-6)
    np.testing.assert_allclose(executed.motor[:, 0], np.tile(data.motor[i, 0], (3, 1)), atol=1e-5)
    assert (out / "act.gif").read_bytes()[:4] == b"GIF8"
    result = json.loads((out / "result.json").read_text())
    assert {"primitive", "scene", "move", "episodes", "corrections"} <= set(result)
    assert result["primitive"] == "push" and result["scene"]["source"] == _scene(files)
    assert result["scene"]["block_x"] == pytest.approx(float(data.params[i, 0]))
    move = result["move"]
    assert move["step"] == round(0.3 * (T - 1)) and 0.02 - 1e-9 <= np.hypot(move["dx"], move["dy"]) <= 0.04 + 1e-9
    assert list(result["episodes"]) == list(PLANNERS)
    for name, e in result["episodes"].items():
        assert isinstance(e["success"], bool) and isinstance(e["reason"], str)
        assert e["looks"] == ([0] if name == "open loop" else CLI_LOOKS), name
        assert e["latency_ms"]["median"] > 0 and e["latency_ms"]["max"] >= e["latency_ms"]["median"]
        assert e["move"] == move
    assert isinstance(result["corrections"], list) and set(result["corrections"]) <= set(CLI_LOOKS) - {0}


def _without_latency(result: dict) -> dict:
    for e in result["episodes"].values():
        e.pop("latency_ms")
    return result


@pytest.mark.slow
def test_the_same_seed_gives_the_same_result_and_overwrite_replaces_an_earlier_act(run_cli, files, tmp_path):
    out = tmp_path / "out"
    args = ("--scene", _scene(files), "--perturb", "--seed", "3")
    assert _act(run_cli, files, out, *args).code == 0
    first = json.loads((out / "result.json").read_text())
    motor = MotionDataset.load(out / "executed.h5").motor
    assert_user_error(_act(run_cli, files, out, *args), "exists")  # never replaced without --overwrite
    res = _act(run_cli, files, out, *args, "--overwrite")
    assert res.code == 0, res.err
    again = json.loads((out / "result.json").read_text())
    assert _without_latency(again) == _without_latency(first)
    np.testing.assert_array_equal(MotionDataset.load(out / "executed.h5").motor, motor)
    other = tmp_path / "other"
    assert _act(run_cli, files, other, "--scene", _scene(files), "--perturb", "--seed", "4").code == 0
    assert json.loads((other / "result.json").read_text())["move"] != first["move"]  # the seed draws the move


@pytest.mark.slow
def test_a_scene_given_as_x_y_size(run_cli, files, tmp_path):
    out = tmp_path / "out"
    res = _act(run_cli, files, out, "--scene", "0.5,0.02,0.05")
    assert res.code == 0, res.err
    result = json.loads((out / "result.json").read_text())
    assert result["scene"] == {"block_x": 0.5, "block_y": 0.02, "size": 0.05, "source": "given"}
    assert result["move"] is None and isinstance(result["corrections"], list)
    assert all(e["move"] is None for e in result["episodes"].values())
    executed = MotionDataset.load(out / "executed.h5")
    np.testing.assert_allclose(executed.params[0], [0.5, 0.02, 0.05], atol=1e-7)


# ------------------------------------------------------------------------ refusals


@pytest.mark.parametrize(
    "case, fragments",
    [
        ("outside", ("block_x = 0.9", "outside the workspace")),
        ("primitive", ("unknown primitive 'grasp'", "touch", "push")),
        ("index", ("sample 999999 is outside",)),
        ("every", ("re-planning interval", ">= 1", "0")),
        ("no frames", ("camera frames", "none")),
        ("bad scene", ("--scene", "x,y,size")),
        ("missing file", ("nowhere.h5",)),
    ],
)
@pytest.mark.slow
def test_bad_input_is_one_line_and_writes_nothing(run_cli, files, tmp_path, case, fragments):
    out = tmp_path / "out"
    run, primitive, scene, extra = files["run"], "push", _scene(files), []
    if case == "outside":
        scene = "0.9,0.0,0.05"
    elif case == "primitive":
        primitive = "grasp"
    elif case == "index":
        scene = f"{files['data']}:999999"
    elif case == "every":
        extra = ["--every", "0"]
    elif case == "no frames":
        run = files["bare"]
    elif case == "bad scene":
        scene = "0.5,zero,0.05"
    elif case == "missing file":
        scene = f"{tmp_path / 'nowhere.h5'}:0"
    res = run_cli("act", run, "--primitive", primitive, "--scene", scene, "--out", out, "--threads", "1", *extra)
    assert_user_error(res, *fragments)
    assert not out.exists()
    assert not any(p.name.startswith(".out") for p in tmp_path.iterdir())  # no temporary directory left


def _tree(path) -> dict:
    return {str(p.relative_to(path)): p.stat().st_mtime_ns for p in sorted(path.rglob("*"))}


def test_an_out_inside_the_run_or_over_another_commands_output_is_refused_and_nothing_deleted(run_cli, files, tmp_path):
    before = _tree(files["run"])
    res = _act(run_cli, files, files["run"] / "act", "--scene", _scene(files))
    assert_user_error(res, "lies inside the input")
    res = _act(run_cli, files, files["run"], "--scene", _scene(files), "--overwrite")
    assert_user_error(res, "is the input")
    assert _tree(files["run"]) == before
    data = files["data"].read_bytes()
    res = _act(run_cli, files, files["root"], "--scene", _scene(files), "--overwrite")
    assert_user_error(res, "contains the input")
    assert files["data"].read_bytes() == data and _tree(files["run"]) == before
    foreign = tmp_path / "notes"
    foreign.mkdir()
    (foreign / "result.json").write_text('{"mine": 1}')
    res = _act(run_cli, files, foreign, "--scene", _scene(files), "--overwrite")
    assert_user_error(res, "not a primspace act output")
    assert (foreign / "result.json").read_text() == '{"mine": 1}' and len(list(foreign.iterdir())) == 1
