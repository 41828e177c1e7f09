"""`primspace experiment regime`: n fitted demonstrations per primitive, the same evaluation motions,
the rows with the primitive given and without it; resumable, seeded; the hypothesis's rule judged from a
summary; the error-against-n figure; one-line errors for a bad n."""

import json
from dataclasses import replace

import numpy as np
import pytest

from conftest import assert_figure, assert_user_error
from primspace.experiments import presets as experiment_presets
from primspace.experiments.presets import ExperimentPreset, default_train
from primspace.experiments.regime import (
    REGIME_GIVEN,
    REGIME_ROWS,
    check_counts,
    few_primitive,
    per_label_subset,
    run_regime,
)
from primspace.experiments.workspace import ExperimentDir
from primspace.results.claim_rules_regime import FEW, RULE_VERSION, check_regime
from primspace.results.regime import comparisons, crossing, seed_crossings
from primspace.utils.errors import UserError

#: Three primitives, six motions each (three block x by two block y): 3 fitted and 3 evaluated per primitive.
REGIME_DATA = dict(
    block_x=(0.45, 0.5, 0.55),
    block_y=(-0.03, 0.03),
    block_size=(0.05,),
    length=31,
    images=False,
    primitives=("touch", "push", "grasp"),
)
TINY = ExperimentPreset(
    name="tiny-regime",
    data_preset="demo",
    train_fraction=0.5,
    inits=("projection",),
    latent_dims=(4,),
    seeds=(0,),
    fit_epochs=3,
    infer_epochs=1,
    train=replace(default_train(), batch_size=8),
    images=False,
    cluster_latent_dim=4,
)
#: The rows' settings, small: few draws, the ProMP's basis count fixed and few EM iterations.
CHEAP = {"prior": dict(n_samples=50), "promp_tuned": dict(n_basis=5, n_iter=20)}


@pytest.fixture(scope="module")
def regime_data(tmp_path_factory):
    from primspace.sim.generate import GenerationConfig, generate_dataset

    path = tmp_path_factory.mktemp("regime") / "data.h5"
    generate_dataset(GenerationConfig(**REGIME_DATA), seed=0, out=path, progress=False)
    return path


def test_the_fitted_subset_is_seeded_nested_and_per_primitive():
    labels = np.repeat([0, 1, 2], 7)
    indices = np.arange(100, 121)
    two, five = (per_label_subset(indices, labels, n, seed=3, salt=50) for n in (2, 5))
    assert np.array_equal(two, per_label_subset(indices, labels, 2, seed=3, salt=50))  # same seed, same subset
    assert not np.array_equal(two, per_label_subset(indices, labels, 2, seed=4, salt=50))
    assert set(two) <= set(five) and np.all(np.diff(five) > 0)
    assert np.bincount(labels[np.searchsorted(indices, five)]).tolist() == [5, 5, 5]
    mixed = per_label_subset(indices, labels, {0: 5, 1: 2, 2: 5}, seed=3, salt=50)
    assert np.bincount(labels[np.searchsorted(indices, mixed)]).tolist() == [5, 2, 5]
    assert set(mixed) <= set(five) and few_primitive(labels, 4) == 1


def test_the_tuned_promp_takes_a_grid_of_basis_counts():
    from primspace.predict.gaussian_peers import TunedProMPPeer

    assert {s["n_basis"] for s in TunedProMPPeer(n_basis=(10, 15)).settings()} == {10, 15}
    with pytest.raises(UserError, match="n_basis"):
        TunedProMPPeer(n_basis=(10, 1)).settings()


def test_a_bad_n_is_refused_naming_the_option():
    assert check_counts((5, 2, 2), 7) == (2, 5)
    for bad, words in (((0,), "not a whole number >= 1"), ((8,), "more than the 7"), ((), "is empty")):
        with pytest.raises(UserError, match=words):
            check_counts(bad, 7)


@pytest.mark.slow
def test_the_command_refuses_a_bad_n_in_one_line(regime_data, tmp_path, run_cli, monkeypatch):
    monkeypatch.setitem(experiment_presets.PRESETS, TINY.name, TINY)
    base = ("experiment", "regime", "--preset", TINY.name, "--data", regime_data, "--workers", "1")
    for n, words in (("0,2", "not a whole number"), ("2,4", "more than the 3 fitted")):
        result = run_cli(*base, "--out", tmp_path / f"out{n}", "--fitted-per-primitive", n)
        assert_user_error(result, "--fitted-per-primitive", words)
    result = run_cli(*base, "--out", tmp_path / "cap", "--fitted-per-primitive", "1", "--eval-per-primitive", "9")
    assert_user_error(result, "--eval-per-primitive", "more than the 3")
    assert not (tmp_path / "out0,2").exists()  # n < 1 is refused before anything is written


def _cell(mean, std):
    return {"mse": [mean, std, 3], "success": [1 - mean, std, 3]}


def _results(ours: dict, peer: dict) -> dict:
    """Regime results with the model's row and one peer per task, MSE ``{n: (mean, std)}``."""
    table = {}
    for model, other in (
        ("prior decoded (labels)", "raw gaussian (labels)"),
        ("prior decoded (posterior)", "raw gaussian"),
    ):
        table[model] = {n: {"0.25": _cell(*v)} for n, v in ours.items()}
        table[other] = {n: {"0.25": _cell(*v)} for n, v in peer.items()}
    return {"judged": True, "given_rows": list(REGIME_GIVEN), "fractions": [0.25], "table": table}


def test_the_rule_is_judged_from_a_summary_and_gives_the_crossing_point():
    wins = _results(
        {"2": (0.1, 0.01), "5": (0.2, 0.01), "10": (0.3, 0.01)}, {"2": (0.3, 0.01), "5": (0.4, 0.01), "10": (0.2, 0.01)}
    )
    row = check_regime(wins)
    assert row["verdict"] == "holds" and row["version"] == RULE_VERSION and "8 of 8" in row["ours"]
    compared = comparisons(wins, "given", "mse")
    assert crossing(compared) == FEW and compared["10"]["verdict"] == "loses"
    within = _results({"2": (0.1, 0.05), "5": (0.2, 0.01)}, {"2": (0.12, 0.01), "5": (0.4, 0.01)})
    assert check_regime(within)["verdict"] == "partly" and crossing(comparisons(within, "given", "mse")) is None
    assert check_regime(_results({"2": (0.5, 0.01)}, {"2": (0.1, 0.01)}))["verdict"] == "does not hold"
    assert check_regime(_results({"10": (0.1, 0.01)}, {"10": (0.5, 0.01)}))["verdict"] == "cannot be checked"
    by_seed = {
        "0": {
            "n": {
                "2": {
                    "methods": {
                        "prior decoded (labels)": {"0.25": {"mse": 0.1}},
                        "raw gaussian (labels)": {"0.25": {"mse": 0.2}},
                    }
                }
            }
        },
        "1": {
            "n": {
                "2": {
                    "methods": {
                        "prior decoded (labels)": {"0.25": {"mse": 0.3}},
                        "raw gaussian (labels)": {"0.25": {"mse": 0.2}},
                    }
                }
            }
        },
    }
    assert seed_crossings(wins | {"by_seed": by_seed}, "given", "mse") == {"0": 2, "1": None}


def test_the_figure_is_drawn_from_a_summary(tmp_path):
    from primspace.report.regime_tables import regime_figure

    results = _results(
        {"2": (0.1, 0.01), "5": (0.05, 0.01), "49": (0.01, 0.001)},
        {"2": (0.3, 0.01), "5": (0.1, 0.02), "49": (0.005, 0.001)},
    )
    regime_figure({"name": "fake", "results": {"regime": results}}, tmp_path / "regime.png")
    assert_figure(tmp_path / "regime.png", min_colours=100)


@pytest.mark.slow
def test_the_regime_grid_is_resumable_and_seeded(regime_data, tmp_path):
    from primspace.report.regime_tables import render_regime
    from primspace.results.summary import summarize

    exp = ExperimentDir(tmp_path / "a", TINY, data=regime_data, workers=1, progress=False)
    results = run_regime(exp, (2, 3), fractions=(0.25,), settings=CHEAP)
    table = results["table"]
    assert set(table) == {name for name, _ in REGIME_ROWS} and not results["failures"]
    for row, ns in table.items():
        assert set(ns) == {"2", "3"}, row
        cell = ns["2"]["0.25"]
        assert np.isfinite(cell["mse"][0]) and 0 <= cell["success"][0] <= 1, row
    assert table["prior decoded (labels)"]["3"]["0.25"]["model_share"][0] == 1.0
    assert table["raw gaussian"]["3"]["0.25"]["model_share"][0] == 0.0
    assert results["by_seed"]["0"]["n_eval"] == 9 and results["by_seed"]["0"]["n"]["2"]["n_fitted"] == 6
    mixed = results["by_seed"]["0"]["mixed"]
    assert mixed["n_fitted"] == 2 + 3 + 3 and mixed["n_test"] == 3 and set(results["mixed"]) == set(table)
    assert exp.figure("regime_errors").is_file()
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "a" / "runs").rglob("result.json")}
    assert len(stamps) == 3
    # the mixed point's key names the others' count: with n = 5 added it is another point, not this one
    assert {p.parent.name for p in stamps} == {"projection-n2-s0", "projection-n3-s0", "projection-mixed2of3-s0"}
    assert run_regime(exp, (2, 3), fractions=(0.25,), settings=CHEAP)["table"] == table  # finished points skipped
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    alone = run_regime(
        ExperimentDir(tmp_path / "b", TINY, data=regime_data, workers=1, progress=False),
        (2,),
        fractions=(0.25,),
        mixed=False,
        settings=CHEAP,
    )
    assert {row: ns["2"] for row, ns in alone["table"].items()} == {row: ns["2"] for row, ns in table.items()}
    summary = summarize(exp.path, "tiny-regime", "primspace experiment regime --out tiny")
    assert json.loads(json.dumps(summary))["results"]["regime"]["table"] == json.loads(
        json.dumps(summary["results"]["regime"]["table"])
    )
    text = render_regime(summary)
    assert "Hypothesis" in text and "n = 3" in text and "Verdict: **" in text
