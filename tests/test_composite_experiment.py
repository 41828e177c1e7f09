"""The composite experiment (issue 15) on tiny long demonstrations: code sequences fitted
and inferred, segmented and scored beside the peers and bounds (issue 27), resumable,
reported; and ``primspace segment``."""

import json
from dataclasses import replace

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.experiments import presets as experiment_presets
from primspace.experiments.composite.experiment import run_composite, segment_codes, split_sequences
from primspace.experiments.presets import ExperimentPreset, default_model, default_train
from primspace.experiments.workspace import ExperimentDir
from primspace.sim.composite import CompositeConfig, generate_composite

TINY = ExperimentPreset(
    name="composite-tiny",
    data_preset="composite-demo",
    train_fraction=0.5,
    inits=("zero", "projection"),
    latent_dims=(4,),
    fit_epochs=3,
    infer_epochs=2,
    images=False,
    model=replace(default_model(), layer_sizes=(12, 6), code_window=8),
    train=replace(default_train(), batch_size=4),
)


@pytest.fixture(scope="module")
def long_data(tmp_path_factory):
    """Eight long demonstrations of two primitives (seconds)."""
    config = CompositeConfig(n_sequences=8, max_primitives=2, duration=(31, 34), transition_steps=4)
    return generate_composite(config, seed=0, out=tmp_path_factory.mktemp("data") / "long.h5", progress=False)


@pytest.fixture(scope="module")
def finished(long_data, tmp_path_factory):
    exp = ExperimentDir(tmp_path_factory.mktemp("exp") / "out", TINY, data=long_data, workers=1, progress=False)
    return exp, run_composite(exp)


def test_split_is_seeded_and_keeps_both_sides():
    train, evaluation = split_sequences(10, 0.3, seed=0)
    assert len(train) == 3 and len(evaluation) == 7 and not set(train) & set(evaluation)
    np.testing.assert_array_equal(train, split_sequences(10, 0.3, seed=0)[0])
    assert not np.array_equal(train, split_sequences(10, 0.3, seed=1)[0])
    assert len(split_sequences(2, 0.01, seed=0)[0]) == 1


@pytest.mark.slow
def test_runs_are_segmented_and_scored(finished):
    exp, results = finished
    assert [r["init"] for r in results["runs"]] == ["zero", "projection"]
    for r in results["runs"]:
        assert (r["window"], r["n_train"], r["n_eval"]) == (8, 4, 4)
        seg = r["segmentation"]
        assert (
            seg["tolerance"] == 8 and seg["segments_true"] == 8
        )  # two primitives in each of 4 held-out demonstrations
        assert seg["boundary_transition"]["f1"] >= seg["boundary"]["f1"]  # a 4-step transition widens the reach
        assert 0 <= seg["boundary"]["f1"] <= 1 and 0 < seg["accuracy"] <= 1
        assert len(r["infer"]) == 3  # epoch 0 and two inference epochs
    zero = results["runs"][0]["segmentation_untrained"]
    assert zero["segments_found"] == 4  # identical zero codes: no boundary anywhere
    for name in ("composite_loss_fit", "composite_loss_infer", "composite_timeline_projection"):
        assert (exp.path / "figures" / f"{name}.png").stat().st_size > 1000


@pytest.mark.slow
def test_peers_and_bounds_run_on_the_same_held_out_demonstrations(finished):
    from primspace.results.composite import bounds_table, composite_table, recall_table
    from primspace.segmentation.peers import PEERS

    _, results = finished
    block = results["peers"]["0"]
    assert (block["n_eval"], block["tolerance"], block["segments_true"]) == (4, 8, 8)
    assert block["inits"] == ["projection-q4", "zero-q4"]
    assert {
        "raw",
        "relative",
        "codes projection-q4",
        "codes trajectory projection-q4",
        "codes zero-q4",
        "untrained codes projection-q4",
    } <= set(block["bounds"])
    assert "untrained codes zero-q4" not in block["bounds"]  # all zero: nothing to read
    assert set(block["methods"]) | set(block["missing"]) == set(PEERS)
    for scores in block["methods"].values():
        assert 0 <= scores["boundary"]["f1"] <= 1 and 0 < scores["accuracy"] <= 1 and scores["segments_found"] >= 4
    rows = composite_table(results)[1]
    assert [r[0] for r in rows] == ["projection", "zero"] + [f"peer: {n}" for n in block["methods"]]
    assert len(bounds_table(results)[1]) == len(block["bounds"])
    assert recall_table(results) is not None or all(b["supervised"] is None for b in block["bounds"].values())


@pytest.mark.slow
def test_the_summary_keeps_the_peers_and_the_docs_render_them(finished):
    from primspace.report.markdown import render_composite
    from primspace.results.summary import summarize

    exp, results = finished
    summary = summarize(exp.path, "tiny", "primspace experiment composite --out tiny")
    assert summary["results"]["composite"]["peers"].keys() == results["peers"].keys()
    text = render_composite(summary)
    assert text.startswith("#### tiny") and "| projection | 4 | 1 |" in text and "raw joints (resampled)" in text
    assert all(f"peer: {name}" in text for name in results["peers"]["0"]["methods"])


@pytest.mark.slow
def test_rerun_skips_finished_runs_and_the_report_shows_them(finished):
    from primspace.report import build_report

    exp, results = finished
    again = run_composite(ExperimentDir(exp.path, TINY, data=exp.data_path, progress=False))
    assert again["runs"] == results["runs"] and again["peers"] == results["peers"]
    html = build_report(exp.path).read_text()
    assert "Long demonstrations: sequences of codes" in html and "composite_timeline_projection" in html
    assert "Upper bounds, on the true segments" in html and "raw joints minus the start pose" in html


def test_segment_codes_scores_planted_sequences(long_data):
    from primspace.data import MotionDataset

    data = MotionDataset.load(long_data)
    # a code per window that is its primitive's own direction: boundaries and labels are found
    windows = -(-data.length // 8)
    codes = np.zeros((len(data), windows, 16))
    rng = np.random.default_rng(0)
    centres = 5 * np.eye(len(data.label_names), 16)
    for i in range(len(data)):
        for k in range(windows):
            step = min(k * 8, int(data.lengths[i]) - 1)
            codes[i, k] = centres[data.step_labels[i, step]] + rng.normal(scale=0.01, size=16)
    result, scores = segment_codes(codes.reshape(len(data), -1), data, 8, 16)
    assert scores["boundary"]["f1"] == 1.0 and scores["accuracy"] > 0.9


@pytest.mark.slow
def test_segment_command(finished, tmp_path, run_cli):
    exp, _ = finished
    run = exp.path / "runs" / "composite" / "projection-q4-s0" / "infer"
    out = tmp_path / "seg"
    result = run_cli("segment", run, exp.data_path, "--out", out)
    assert result.code == 0, result.err
    assert "boundary F1" in result.out
    record = json.loads((out / "result.json").read_text())
    assert record["window"] == 8 and len(record["boundaries"]) == 4
    rows = (out / "segments.csv").read_text().splitlines()
    assert rows[0] == "sample,segment,start,stop,label" and len(rows) == 1 + record["scores"]["segments_found"]
    assert np.load(out / "step_labels.npy").shape == (4, exp.dataset().length)
    assert_user_error(run_cli("segment", run, exp.data_path, "--out", out), "output exists")
    assert run_cli("segment", run, exp.data_path, "--out", out, "--overwrite").code == 0
    assert_user_error(run_cli("segment", run, exp.data_path, "--out", exp.data_path), "is the input")


def test_segment_refuses_a_run_with_one_code_per_sequence(long_data, tmp_path, run_cli):
    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, fit

    data = MotionDataset.load(long_data)
    fit(
        data,
        tmp_path / "run",
        model_config=ModelConfig(latent_dim=3, layer_sizes=(8, 4)),
        train_config=TrainConfig(epochs=1, batch_size=4),
        progress=False,
    )
    assert_user_error(
        run_cli("segment", tmp_path / "run", long_data, "--method", "windows", "--out", tmp_path / "seg"),
        "one code per sequence",
        "--code-window",
    )


def test_composite_presets_are_named_by_demo_paper_and_lasa():
    from primspace.sim.composite import COMPOSITE_PRESETS

    data = {"demo": "composite-demo", "paper": "composite", "lasa": experiment_presets.LASA_CHAINS}
    for short, name in experiment_presets.COMPOSITE_PRESET_OF.items():
        preset = experiment_presets.resolve_preset(name)
        assert preset.model.code_window is not None and preset.data_preset == data[short]
    assert set(COMPOSITE_PRESETS) == {"composite-demo", "composite"}


def test_lasa_chains_are_continuous_real_shapes_with_their_steps_labelled():
    from primspace.data.importers import CHAIN_SHAPES, chain_lasa

    data = chain_lasa(6, n_shapes=(2, 3), duration=(30, 40), seed=1)
    assert data.label_names == list(CHAIN_SHAPES) and data.length == 120
    for i in range(len(data)):
        n = int(data.lengths[i])
        assert (
            60 <= n <= 120
            and (data.step_labels[i, n:] == -1).all()
            and (data.motor[i, n:] == data.motor[i, n - 1]).all()
        )
        steps = np.abs(np.diff(data.motor[i, :n], axis=0)).max(axis=1)
        junctions = np.flatnonzero(np.diff(data.step_segments[i, :n])) + 1
        assert len(junctions) in (1, 2) and (steps[junctions - 1] <= steps.max()).all()
        assert steps[junctions - 1].max() < 1e-9  # each shape starts where the one before ended
        labels = data.step_labels[i, :n]
        assert (labels[junctions] != labels[junctions - 1]).all()  # no shape twice in a row
    again = chain_lasa(6, n_shapes=(2, 3), duration=(30, 40), seed=1)
    np.testing.assert_array_equal(again.motor, data.motor)
    assert not np.array_equal(chain_lasa(6, n_shapes=(2, 3), duration=(30, 40), seed=2).step_labels, data.step_labels)


SINGLE_TINY = ExperimentPreset(
    name="single-tiny",
    data_preset="demo",
    latent_dims=(4,),
    fit_epochs=3,
    images=False,
    cluster_latent_dim=4,
    model=replace(default_model(), layer_sizes=(12, 6)),
    train=replace(default_train(), batch_size=4),
)


@pytest.fixture(scope="module")
def by_primitives(long_data, tmp_path_factory):
    """The composite experiment with a model of single primitives (one seed): the simulator's
    seven primitives at two block placements, made beside the experiment's data."""
    from primspace.experiments.composite.primitives import PRIMITIVES_FILE
    from primspace.sim.config import GenerationConfig
    from primspace.sim.generate import generate_dataset

    preset = replace(TINY, seeds=(0,), primitives="single-tiny", segment_steps=(20, 40))
    exp = ExperimentDir(tmp_path_factory.mktemp("prim") / "out", preset, data=long_data, workers=1, progress=False)
    generate_dataset(
        GenerationConfig(block_x=(0.5, 0.55), block_y=(0.0,), block_size=(0.05,), images=False),
        seed=0,
        out=exp.path / PRIMITIVES_FILE,
        progress=False,
    )
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(experiment_presets.PRESETS, "single-tiny", SINGLE_TINY)
        yield exp, run_composite(exp)


@pytest.mark.slow
def test_a_model_of_single_primitives_segments_by_synthesis_and_surprise(by_primitives):
    from primspace.report.markdown import render_composite
    from primspace.results.composite import composite_table
    from primspace.results.summary import summarize

    exp, results = by_primitives
    [row] = results["primitives"]
    assert (row["seed"], row["preset"], row["latent_dim"], row["n_templates"]) == (0, "single-tiny", 4, 14)
    for name in ("synthesis", "surprise"):
        scores = row[name]
        assert scores["tolerance"] == 8 and scores["segments_true"] == 8
        assert 0 <= scores["boundary"]["f1"] <= 1 and 0 < scores["accuracy"] <= 1
        assert 0 < scores["accuracy_template_labels"] <= 1
        found = scores["segments_found"]
        assert 4 <= found <= 4 * 80 // 20  # at least one per demonstration, none shorter than the least duration
    assert row["surprise"]["threshold"] > 0
    assert (exp.path / "runs" / "composite" / "primitives-s0" / "fit" / "checkpoint.pt").exists()
    for name in ("synthesis", "surprise"):  # the report's timeline of each method
        assert (exp.path / "figures" / f"composite_timeline_{name}.png").stat().st_size > 1000
    names = [r[0] for r in composite_table(results)[1]]
    assert names[2:4] == ["synthesis (single-tiny single primitives)", "surprise (single-tiny single primitives)"]
    text = render_composite(summarize(exp.path, "tiny", "primspace experiment composite --out tiny"))
    assert "| synthesis (single-tiny single primitives) | 4 | 1 |" in text
    again = run_composite(ExperimentDir(exp.path, exp.preset, data=exp.data_path, progress=False))
    assert again["primitives"] == results["primitives"]  # finished: read back, not re-run


def test_lasa_chains_leave_out_the_demonstrations_of_the_single_strokes():
    from primspace.data.importers import chain_lasa
    from primspace.data.importers.lasa import CHAIN_DEMOS
    from primspace.utils.errors import UserError

    data = chain_lasa(12, seed=0, demos=CHAIN_DEMOS)
    used = {int(p.rsplit(" ", 1)[1]) for s in data.source_ids for p in s.split(": ", 1)[1].split(" + ")}
    assert used <= set(CHAIN_DEMOS) and len(used) > 1
    np.testing.assert_array_equal(chain_lasa(12, seed=0).motor, chain_lasa(12, seed=0, demos=range(7)).motor)
    with pytest.raises(UserError, match="demos"):
        chain_lasa(2, demos=(7,))
    from primspace.experiments.composite.primitives import _check_unseen

    _check_unseen(data)  # chains of the held-out demonstrations pass
    with pytest.raises(UserError, match="fitted on"):
        _check_unseen(chain_lasa(12, seed=0))  # chains made before 0.8 drew from all seven
