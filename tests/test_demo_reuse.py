"""A second ``make demo`` reuses what the first left in its folder, and says so in one line."""

from __future__ import annotations

from primspace.demo import earlier_results


def test_a_fresh_folder_reuses_nothing(tmp_path):
    assert earlier_results(tmp_path / "demo-out") is None
    (tmp_path / "empty").mkdir()
    assert earlier_results(tmp_path / "empty") is None


def test_an_earlier_demo_is_named_with_what_is_reused(tmp_path):
    out = tmp_path / "demo-out"
    for key in ("a", "b"):
        (out / "runs" / key).mkdir(parents=True)
        (out / "runs" / key / "result.json").write_text("{}")
    (out / "runs" / "c").mkdir()  # interrupted: no result, not counted
    (out / "experiment.json").write_text("{}")
    (out / "data.h5").write_bytes(b"")
    line = earlier_results(out)
    assert line == (
        f"reusing its data set and 2 finished run(s) from an earlier demo in {out} "
        "(remove that folder or give --out elsewhere to start over)"
    )


def test_runs_count_only_in_an_experiment_folder(tmp_path):
    (tmp_path / "runs" / "a").mkdir(parents=True)
    (tmp_path / "runs" / "a" / "result.json").write_text("{}")
    assert earlier_results(tmp_path) is None
    (tmp_path / "data.h5").write_bytes(b"")
    assert earlier_results(tmp_path).startswith("reusing its data set from an earlier demo")
