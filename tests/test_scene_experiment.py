"""`experiment scene` (issue 25, item 4): success per primitive from the scene only, beside the
primitive's mean motion and the reproduction, on a tiny experiment with images; resumable,
reported, and refused in one line for a motor-only experiment."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import assert_user_error
from test_experiments import TINY

from primspace.utils.errors import UserError
from primspace.experiments.results import scene_table
from primspace.experiments.scene_only import SCENE_METHODS, run_scene
from primspace.experiments.workspace import ExperimentDir
from primspace.report import build_report

TINY_SCENE = replace(
    TINY,
    name="tiny-scene",
    inits=("projection",),
    fit_epochs=2,
    infer_epochs=2,
    images=True,
    train=replace(TINY.train, vision_frames=3),
)


@pytest.fixture(scope="module")
def scene_data(tmp_path_factory):
    """Three block positions per primitive: 21 motions of 31 steps with 48x64 frames."""
    from primspace.sim.generate import GenerationConfig, generate_dataset

    config = GenerationConfig(block_x=(0.45, 0.5, 0.55), block_y=(0.0,), block_size=(0.05,), length=31, images=True)
    path = tmp_path_factory.mktemp("data") / "tiny-scene.h5"
    generate_dataset(config, seed=0, out=path, progress=False)
    return path


@pytest.fixture(scope="module")
def scene(scene_data, tmp_path_factory):
    exp = ExperimentDir(tmp_path_factory.mktemp("exp") / "out", TINY_SCENE, data=scene_data, workers=1, progress=False)
    return exp, run_scene(exp, epochs=2)


def test_every_primitive_is_acted_judged_and_compared(scene):
    exp, results = scene
    names = exp.dataset().label_names
    assert results["failures"] == {} and results["judged"] and results["epochs"] == 2
    table = results["table"]
    assert list(table) == list(SCENE_METHODS)  # the scene only, the mean motion (labels), the reproduction
    for method, cells in table.items():
        assert set(cells) == set(names) | {"all"}, method
        for name, cell in cells.items():
            assert cell["n"][0] > 0 and cell["n"][2] == 1
            assert 0.0 <= cell["success"][0] <= 1.0
            assert np.isfinite(cell["mse"][0]) and cell["mse"][0] >= 0
    point = results["by_seed"]["0"]
    assert point["unassigned"] == 0 and point["n_test"] == point["n_eval"] == table["scene only"]["all"]["n"][0]
    assert point["clusters"]["n_clusters"] == len(names)
    assert sum(c["n"][0] for p, c in table["scene only"].items() if p != "all") == point["n_test"]
    columns, rows = scene_table(results)
    assert columns == ["primitive", "method", "n", "success", "MSE after step 1"]
    assert [r[:2] for r in rows] == [[n, m] for n in list(names) + ["all"] for m in SCENE_METHODS]


def test_a_second_call_reuses_the_points_and_the_report_has_the_section(scene):
    exp, results = scene
    (point,) = (exp.path / "runs").glob("scene1/projection-q4-s0*/result.json")
    before = point.stat().st_mtime_ns
    assert run_scene(exp, epochs=2)["table"] == results["table"]
    assert point.stat().st_mtime_ns == before
    text = build_report(exp.path).read_text()
    assert "Acting from the scene only" in text and "mean motion (labels)" in text


def test_the_stored_summary_keeps_the_scene_table_and_the_docs_print_it(scene):
    from primspace.report.markdown import blocks
    from primspace.experiments.summary import _round, summarize

    exp, results = scene
    summary = summarize(exp.path, "tiny", "primspace experiment scene --out tiny")
    assert summary["results"]["scene"]["table"] == _round(results["table"])  # 5 significant digits
    text = blocks({"tiny": summary})["scene"]
    assert "#### tiny" in text and "| primitive | method | n | success | MSE after step 1 |" in text
    assert text.count("| scene only |") == len(exp.dataset().label_names) + 1  # every primitive, then all


def test_a_motor_only_experiment_is_refused_in_one_line(run_cli, scene_data, tmp_path):
    res = run_cli("experiment", "scene", "--data", scene_data, "--out", tmp_path / "cli", "--no-images", "-j", "1")
    assert_user_error(res, "image head")
    assert not (tmp_path / "cli" / "runs").exists()  # refused before any training
    exp = ExperimentDir(tmp_path / "api", replace(TINY_SCENE, images=False), data=scene_data, workers=1, progress=False)
    with pytest.raises(UserError, match="needs runs with an image head"):
        run_scene(exp)
