"""The experiment grid runner: finished points are skipped, failures reported, others go on."""

import json

from primspace.experiments.sweep import GridPoint, run_grid
from primspace.results.layout import ERROR_FILE, RESULT_FILE


def square_job(run_dir, x):
    calls = run_dir / "calls"
    calls.write_text(str(int(calls.read_text()) + 1 if calls.exists() else 1))
    if x < 0:
        raise ValueError(f"negative input {x}")
    return {"x": x, "square": x * x}


def test_grid_runs_skips_and_reports(tmp_path):
    points = [GridPoint(f"sq/{i}", (x,)) for i, x in enumerate([2, -1, 3])]
    first = run_grid(square_job, points, tmp_path, progress=False)
    assert first.results == {"sq/0": {"x": 2, "square": 4}, "sq/2": {"x": 3, "square": 9}}
    assert first.failures == {"sq/1": "ValueError: negative input -1"}
    assert not first.ok and first.skipped == []
    assert "negative input -1" in (tmp_path / "runs/sq/1" / ERROR_FILE).read_text()
    assert json.loads((tmp_path / "runs/sq/2" / RESULT_FILE).read_text())["square"] == 9

    # re-run with the failing point fixed: only that one runs again
    points[1] = GridPoint("sq/1", (4,))
    second = run_grid(square_job, points, tmp_path, progress=False)
    assert second.ok and sorted(second.skipped) == ["sq/0", "sq/2"]
    assert second.results["sq/1"] == {"x": 4, "square": 16}
    assert [(tmp_path / f"runs/sq/{i}/calls").read_text() for i in range(3)] == ["1", "2", "1"]
    assert not (tmp_path / "runs/sq/1" / ERROR_FILE).exists()


def test_grid_on_a_process_pool_gives_the_same_results(tmp_path):
    points = [GridPoint(f"p/{x}", (x,)) for x in range(4)]
    a = run_grid(square_job, points, tmp_path / "a", workers=1, progress=False)
    b = run_grid(square_job, points, tmp_path / "b", workers=2, progress=False)
    assert a.results == b.results and len(a.results) == 4
