"""The prediction grid's two tasks (version 4 on, issue 39): the rows given the primitive and the
label-free rows in two tables, each with its verdict against the best peer; older results keep
their one table."""

import json

import pytest

from primspace.experiments.prediction_table import predict_table
from primspace.report.predict_tables import task_tables, verdict
from primspace.report.summary_tables import render_predict

GIVEN = ["prior (labels)", "promp (labels)", "mean motion (labels)", "mixture (labels; diagnostic)"]
#: Per row and fraction: (mean MSE, its step between seeds, mean success, mean accuracy or None).
#: Label-free: mixture beats the nearest neighbour at 10 % (holds), is within the spreads at 25 % (ties),
#: worse at 50 % (loses). Given: prior (labels) against promp (labels), the same outcomes at 50 %, 25 %, 10 %.
ROWS = {
    "mixture": {"0.1": (0.011, 0.001, 0.5, None), "0.25": (0.012, 0.002, 0.4, None), "0.5": (0.021, 0.001, 0.3, None)},
    "prior (posterior)": {
        "0.1": (0.05, 0.001, 0.1, 0.6),
        "0.25": (0.05, 0.001, 0.1, 0.7),
        "0.5": (0.05, 0.001, 0.1, 0.8),
    },
    "prior (clusters)": {
        "0.1": (0.06, 0.001, 0.1, 0.2),
        "0.25": (0.06, 0.001, 0.1, 0.3),
        "0.5": (0.06, 0.001, 0.1, 0.4),
    },
    "promp (one for all)": {k: (0.03, 0.001, 0.2, None) for k in ("0.1", "0.25", "0.5")},
    "nearest neighbour": {
        "0.1": (0.021, 0.001, 0.2, None),
        "0.25": (0.013, 0.002, 0.2, None),
        "0.5": (0.011, 0.001, 0.2, None),
    },
    "prior (labels)": {
        "0.1": (0.004, 0.001, 0.9, None),
        "0.25": (0.003, 0.001, 0.9, None),
        "0.5": (0.001, 0.0001, 0.9, None),
    },
    "promp (labels)": {
        "0.1": (0.002, 0.0001, 0.9, None),
        "0.25": (0.0035, 0.001, 0.9, None),
        "0.5": (0.002, 0.0001, 0.9, None),
    },
    "mean motion (labels)": {k: (0.04, 0.001, 0.0, None) for k in ("0.1", "0.25", "0.5")},
    "mixture (labels; diagnostic)": {k: (0.005, 0.001, None, None) for k in ("0.1", "0.25", "0.5")},
}


def _by_seed() -> dict:
    """Three seeds of the fake grid: seed i's value is mean + (i - 1) * step (std with ddof 1: step)."""
    out = {}
    for i in range(3):
        methods = {}
        for row, cells in ROWS.items():
            for key, (mse, step, success, accuracy) in cells.items():
                entry = {"mse": mse + (i - 1) * step}
                if success is not None:
                    entry["success"] = {"overall": success + (i - 1) * 0.1}
                if accuracy is not None:
                    entry["accuracy"] = accuracy + (i - 1) * 0.1
                methods.setdefault(row, {})[key] = entry
            if cells["0.1"][2] is not None:
                one = {"success": {"overall": 0.95}} | ({"accuracy": 0.9} if cells["0.1"][3] else {})
                methods[row]["1"] = one
        out[str(i)] = {"methods": methods}
    return out


def _summary(version: int | None = 4) -> dict:
    predict = {
        "latent_dim": 8,
        "fractions": [0.1, 0.25, 0.5],
        "starts": ["mixture"],
        "peers": ["promp (labels)", "promp (one for all)", "nearest neighbour", "mean motion (labels)"],
        "epochs": 2,
        "judged": True,
        "table": predict_table(_by_seed()),
        "failures": {},
        "seeds": [0, 1, 2],
    }
    if version is not None:
        predict |= {"version": version, "given_rows": GIVEN}
    return {"name": "fake", "command": "primspace experiment predict", "results": {"predict": predict}}


def test_accuracy_is_aggregated_over_seeds_like_the_error():
    table = predict_table(_by_seed())
    assert table["prior (posterior)"]["0.1"]["accuracy"] == pytest.approx([0.6, 0.1, 3])
    assert table["prior (posterior)"]["1"]["accuracy"] == pytest.approx([0.9, 0.0, 3])
    assert "accuracy" not in table["mixture"]["0.1"] and "success" not in table["mixture (labels; diagnostic)"]["0.1"]


def test_two_tables_split_by_the_given_rows_with_accuracy_in_the_label_free_one():
    given, free = task_tables(_summary()["results"]["predict"])
    assert given.title == "With the primitive given" and free.title == "Without the primitive"
    assert [r[0] for r in given.rows] == [r for r in ROWS if r in GIVEN]
    assert [r[0] for r in free.rows] == [r for r in ROWS if r not in GIVEN]
    mse = [f"MSE, {p}% observed" for p in (10, 25, 50)]
    success = [f"success, {p}%" for p in (10, 25, 50, 100)]
    assert given.columns == ["method", *mse, *success]
    assert free.columns == ["method", *mse, *success, *[f"top-1 accuracy, {p}%" for p in (10, 25, 50, 100)]]
    posterior = next(r for r in free.rows if r[0] == "prior (posterior)")
    assert posterior[-4:] == ["0.6 ± 0.1", "0.7 ± 0.1", "0.8 ± 0.1", "0.9 ± 0"]
    assert next(r for r in free.rows if r[0] == "mixture")[-4:] == ["–"] * 4
    assert next(r for r in given.rows if r[0] == "mixture (labels; diagnostic)")[4:] == ["–"] * 4


def test_each_table_says_per_fraction_whether_primspace_holds_ties_or_loses():
    given, free = task_tables(_summary()["results"]["predict"])
    assert "MSE at 10%: holds (mixture 0.011 ± 0.001 against nearest neighbour 0.021 ± 0.001)" in free.verdict
    assert "MSE at 25%: ties (mixture 0.012 ± 0.002 against nearest neighbour 0.013 ± 0.002)" in free.verdict
    assert "MSE at 50%: loses (mixture 0.021 ± 0.001 against nearest neighbour 0.011 ± 0.001)" in free.verdict
    assert "success at 10%: holds (mixture 0.5 ± 0.1 against promp (one for all) 0.2 ± 0.1)" in free.verdict
    assert "success at 100%: ties" in free.verdict
    assert "MSE at 10%: loses (prior (labels) 0.004 ± 0.001 against promp (labels) 0.002 ± 0.0001)" in given.verdict
    assert "MSE at 25%: ties (mixture (labels; diagnostic)" not in given.verdict  # 0.005: not the best of ours
    assert "MSE at 25%: ties (prior (labels) 0.003 ± 0.001 against promp (labels) 0.0035 ± 0.001)" in given.verdict
    assert "MSE at 50%: holds (prior (labels) 0.001 ± 0.0001 against promp (labels) 0.002 ± 0.0001)" in given.verdict


def test_the_verdict_needs_more_than_both_spreads():
    assert verdict([1.0, 0.1, 3], [1.5, 0.4, 3], lower_better=True) == "holds"
    assert verdict([1.0, 0.1, 3], [1.3, 0.4, 3], lower_better=True) == "ties"
    assert verdict([1.0, 0.1, 3], [0.5, 0.4, 3], lower_better=True) == "loses"
    assert verdict([0.9, 0.05, 3], [0.5, 0.1, 3], lower_better=False) == "holds"
    assert verdict([0.5, 0.0, 1], [0.5, 0.0, 1], lower_better=False) == "ties"


def test_docs_show_two_tables_from_version_4_and_one_before():
    text = render_predict(_summary())
    assert "##### With the primitive given" in text and "##### Without the primitive" in text
    assert text.index("With the primitive given") < text.index("| prior (labels) |") < text.index("Without the")
    assert "holds when primspace's is better by more than both standard deviations" in text
    assert text.count("Verdicts, primspace's best row against the best peer row. MSE at 10%: ") == 2
    for version in (None, 3):
        old = render_predict(_summary(version))
        assert "#####" not in old and "holds" not in old and old.count("| method |") == 1
        assert "| prior (labels) |" in old and "top-1 accuracy" not in old


def test_the_html_report_shows_the_same_two_tables(tmp_path):
    from primspace.report.page import HtmlReport
    from primspace.report.sections import prediction

    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "predict.json").write_text(json.dumps(_summary()["results"]["predict"]))
    report = HtmlReport("t")
    prediction(tmp_path, report)
    page = report.render()
    assert "<h3>With the primitive given</h3>" in page and "<h3>Without the primitive</h3>" in page
    assert "top-1 accuracy, 10%" in page and "MSE at 50%: loses" in page


def test_a_summary_keeps_the_grids_version_and_its_given_rows(tmp_path):
    from primspace.results.summary import summarize

    predict = _summary()["results"]["predict"] | {"by_seed": _by_seed()}
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "predict.json").write_text(json.dumps(predict))
    (tmp_path / "experiment.json").write_text(json.dumps({"primspace": "0.9.0"}))
    summary = summarize(tmp_path, "fake", "primspace experiment predict")
    kept = summary["results"]["predict"]
    assert kept["version"] == 4 and kept["given_rows"] == GIVEN and kept["seeds"] == [0, 1, 2]
    assert "##### Without the primitive" in render_predict(summary)
    del predict["version"], predict["given_rows"]
    (tmp_path / "results" / "predict.json").write_text(json.dumps(predict))
    assert not {"version", "given_rows"} & set(summarize(tmp_path, "old", "c")["results"]["predict"])


def test_a_row_that_does_not_use_the_model_is_marked():
    from primspace.report.predict_tables import NO_MODEL, share_text

    shares = {"prior (labels)": (0.0, 0.0), "promp (labels)": (0.0, 0.0), "mixture": (1.0, 1.0)}
    by_seed = {
        str(seed): {
            "methods": {
                row: {k: {"mse": 0.01 * (1 + i) + 0.001 * seed, "model_share": shares[row][0]} for k in ("0.1", "0.25")}
                for i, row in enumerate(shares)
            }
        }
        for seed in (0, 1)
    }
    results = {"version": 5, "fractions": [0.1, 0.25], "table": predict_table(by_seed), "given_rows": GIVEN}
    given = task_tables(results)[0]
    assert given.columns[-1] == "model share"
    assert given.rows[0][-1] == f"0 ({NO_MODEL})"  # the prior whose K-fold chose the raw data alone
    assert f"prior (labels), {NO_MODEL}" in given.verdict
    assert share_text({"0.1": {"model_share": [1.0, 0, 2]}, "0.25": {"model_share": [0.5, 0, 2]}}, ["0.1", "0.25"]) == (
        "1 / 0.5"
    )
    assert share_text({"0.1": {"mse": [0.1, 0, 2]}}, ["0.1"]) == ""
