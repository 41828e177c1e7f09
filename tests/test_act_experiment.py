"""The act experiment's point on a tiny case: every scene-only row, the kernel ridge map among them,
with each row's model share in the result and in the tables.

The tiny simulated set of test_scene_policy.py (touch and push, a 3 x 3 grid of blocks, T = 31,
with frames), a run of 2 epochs fitted on all but the centre block of each primitive, and its codes
inferred for those two (2 epochs): :func:`primspace.experiments.act.run_act_point` on them."""

from __future__ import annotations

import numpy as np
import pytest

from primspace.train import TrainConfig, fit, infer
from test_scene_policy import held_out, simulate
from test_train import SMALL

pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)


@pytest.fixture(scope="module")
def point(tmp_path_factory):
    """The result of one act point on the tiny case, and the data's label names."""
    from primspace.experiments.act import run_act_point

    root = tmp_path_factory.mktemp("act_experiment")
    data = simulate(root / "data.h5")
    held = held_out(data)
    fitted = np.setdiff1d(np.arange(len(data)), held)
    config = TrainConfig(epochs=2, batch_size=16, threads=1)
    fit(data, root / "fit", indices=fitted, images=False, model_config=SMALL, train_config=config, progress=False)
    infer(root / "fit", data.without_images(), root / "infer", epochs=2, indices=held, progress=False)
    result = run_act_point(None, str(root / "data.h5"), str(root / "fit"), str(root / "infer"), 6, None)
    return result, list(data.label_names)


@pytest.mark.slow
def test_the_act_point_has_the_kernel_ridge_row_and_every_rows_model_share(point):
    from primspace.experiments.act import KERNEL_RIDGE, LOOP_ROWS, SCENE_ROWS

    result, names = point
    assert list(result["scene"]) == list(SCENE_ROWS) and KERNEL_RIDGE in SCENE_ROWS
    row = result["scene"][KERNEL_RIDGE]
    assert set(row) == {"touch", "push", "all"} and row["all"]["n"] == 2
    assert 0.0 <= row["all"]["success"] <= 1.0 and row["all"]["mse"] > 0
    shares = {name: entry["all"]["model_share"] for name, entry in result["scene"].items()}
    assert shares == {
        "scene policy": 0.0,  # the motion map: the run is not used
        "scene policy (code)": 1.0,  # the codes map, decoded
        KERNEL_RIDGE: 0.0,
        "contextual ProMP (pixels)": 0.0,
        "contextual ProMP (blob)": 0.0,
        "nearest first frame": 0.0,
        "mean motion (labels)": 0.0,
        "reproduction (whole motion)": 1.0,
    }
    assert all(e["model_share"] == shares[n] for n, entry in result["scene"].items() for e in entry.values())
    assert list(result["loop"]) == list(LOOP_ROWS)
    assert all(entry["all"]["model_share"] == 0.0 for entry in result["loop"].values())
    # the settings chosen by K-fold on the fitted demonstrations, per primitive
    from primspace.act.scene_kernel import LENGTH_GRID, PENALTY_GRID

    settings = result["kernel_ridge_settings"]
    assert set(settings) == {"touch", "push"} <= set(names)
    assert all(set(s["length_scale"]) <= set(LENGTH_GRID) and s["penalty"] in PENALTY_GRID for s in settings.values())
    assert all(len(s["length_scale"]) == 3 for s in settings.values())  # one per feature: mass, column, row


@pytest.mark.slow
def test_the_act_tables_show_the_row_and_mark_the_rows_that_do_not_use_the_model(point):
    from primspace.experiments.act import KERNEL_RIDGE, LOOP_ROWS, SCENE_ROWS, act_summary
    from primspace.results.act import NO_MODEL, act_table, act_tables

    result, _ = point
    results = {"table": act_summary({"0": result}), "scene_rows": list(SCENE_ROWS), "loop_rows": list(LOOP_ROWS)}
    results["by_seed"] = {"0": result}
    tables = act_tables(results)
    for title, columns, rows in tables:
        assert columns[-1] == "model share", title
        shares = {row[0]: row[-1] for row in rows}
        for name in set(shares) - {"scene policy (code)", "reproduction (whole motion)"}:
            assert shares[name] == f"0 ({NO_MODEL})", (title, name)
    scene_rows = {row[0]: row for row in tables[0][2]}
    assert scene_rows["scene policy (code)"][-1] == scene_rows["reproduction (whole motion)"][-1] == "1"
    assert KERNEL_RIDGE in scene_rows
    columns, rows = act_table(results)
    assert columns[-1] == "model share" and f"scene only: {KERNEL_RIDGE}" in [r[0] for r in rows]


def test_the_act_tables_mark_is_the_prediction_tables_and_old_results_have_no_share_column():
    from primspace.report.predict_tables import NO_MODEL as PREDICT_MARK
    from primspace.results.act import NO_MODEL, act_table, act_tables, share_text
    from test_report_layers import fake_act_results

    assert NO_MODEL == PREDICT_MARK
    assert share_text({"all": {"model_share": [0.0, 0.0, 3]}}) == f"0 ({NO_MODEL})"
    assert share_text({"all": {"model_share": [1.0, 0.0, 3]}}) == "1" and share_text({"all": {}}) == ""
    old = fake_act_results()  # results before act version 4 record no share
    assert all(columns[-1] != "model share" for _, columns, _ in act_tables(old))
    assert act_table(old)[0] == ["method", "success (all primitives)"]


def test_one_fitted_demonstration_per_primitive_is_refused_before_any_training(tmp_path, run_cli, monkeypatch):
    """The scene policy maps each primitive's fitted demonstrations: with one per primitive in a
    seed's fitted split, `experiment act` says so in one line before training anything (it used to
    train, fail every point and say "re-run the same command to retry them")."""
    from dataclasses import replace

    from conftest import assert_user_error
    from primspace.experiments import presets as experiment_presets
    from test_experiments import TINY

    simulate(tmp_path / "data.h5")  # 9 motions per primitive
    monkeypatch.setitem(experiment_presets.PRESETS, "tiny", replace(TINY, train_fraction=0.1))
    out = tmp_path / "exp"
    res = run_cli("experiment", "act", "--preset", "tiny", "--data", tmp_path / "data.h5", "--out", out)
    assert_user_error(res, "at least 2 fitted demonstrations per primitive", "has 1 in seed 0", "--train-fraction")
    assert not (out / "runs").exists()
