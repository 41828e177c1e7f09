"""Long work is never silent: lines in a log when stderr is not a terminal (issue 37)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from primspace.utils import progress

_STAMP = r"\[\d\d:\d\d:\d\d\] "


@pytest.fixture
def log_at_once(monkeypatch):
    """Steps write their log lines from the start (not only after LOG_AFTER seconds)."""
    monkeypatch.setattr(progress, "LOG_AFTER", 0.0)


def test_a_counted_step_writes_a_line_when_it_runs_each_tenth_and_when_it_ends(capsys, log_at_once):
    import time

    with progress.progress_bar(20, "epochs", fields="loss {task.fields[loss]:.3g}") as advance:
        time.sleep(0.05)  # the first line is the timer's
        for i in range(20):
            advance(loss=1.0 / (i + 1))
    lines = capsys.readouterr().err.splitlines()
    assert all(re.match(_STAMP, line) for line in lines), lines
    assert "epochs: running" in lines[0]
    assert 5 <= len(lines) <= 12, lines  # a line per tenth at most, not one per step
    assert re.search(r"epochs: done \(20/20, loss 0\.05\) in [\d.]+ s$", lines[-1]), lines[-1]
    tenths = [line for line in lines[1:-1] if "/20" in line]
    assert tenths and all(re.search(r", \d+ s, about \d+ s left$", line) for line in tenths), lines


def test_a_quick_step_writes_nothing_and_false_is_silent(capsys, monkeypatch):
    with progress.progress_bar(3, "quick") as advance:
        advance(3)
    monkeypatch.setattr(progress, "LOG_AFTER", 0.0)
    with progress.progress_bar(3, "off", enabled=False) as advance, progress.stage("off too", enabled=False):
        advance(3)
    progress.announce("not shown", enabled=False)
    assert capsys.readouterr().err == ""


def test_a_stage_and_an_announcement_write_lines(capsys, log_at_once):
    import time

    progress.announce("demo 1/5: data")
    with progress.stage("segment: 4 demonstrations by synthesis"):
        time.sleep(0.05)
    lines = capsys.readouterr().err.splitlines()
    assert re.match(_STAMP + "demo 1/5: data$", lines[0])
    assert "segment: 4 demonstrations by synthesis: running" in lines[1]
    assert re.search(r"by synthesis: done in [\d.]+ s$", lines[2])


def test_train_with_stderr_not_a_terminal_logs_its_epochs(run_cli, tmp_path, log_at_once):
    from primspace.data import MotionDataset

    rng = np.random.default_rng(0)
    data = tmp_path / "d.h5"
    MotionDataset(motor=rng.standard_normal((6, 10, 2)).astype(np.float32)).save(data)
    res = run_cli(
        "train",
        data,
        "--out",
        tmp_path / "run",
        "--epochs",
        "10",
        "--layers",
        "6,4",
        "--latent-dim",
        "2",
        "--batch-size",
        "3",
    )
    assert res.code == 0, res.err
    lines = [line for line in res.err.splitlines() if line.strip()]
    assert any(re.match(_STAMP + r"fit run: running", line) for line in lines), lines
    assert re.match(_STAMP + r"fit run: done \(10/10, loss [\d.e-]+, \d+ samples/s\) in", lines[-1]), lines
    assert "wrote" in res.out


def test_the_time_left_is_the_average_pace_since_the_start_and_unknown_before_a_step():
    assert progress.remaining_seconds(180.0, 0, 10) is None  # 3 minutes in, nothing done: no estimate
    assert progress.remaining_seconds(60.0, 2, 10) == pytest.approx(240.0)
    assert progress.remaining_seconds(None, 2, 10) is None and progress.remaining_seconds(60.0, 2, None) is None
    assert progress.remaining_seconds(60.0, 10, 10) == 0.0


def test_the_bar_does_not_claim_seconds_left_when_parallel_jobs_end_together():
    """Two jobs of ten end 0.1 s apart after six minutes (two workers): rich's own column, pacing
    from the first ended job, claims seconds; the bar's column says about 24 minutes."""
    from rich.progress import Progress, TimeRemainingColumn

    now = [0.0]
    bar = Progress(get_time=lambda: now[0], disable=True)
    task_id = bar.add_task("intra", total=10)
    task = bar.tasks[0]
    column = progress.AverageRemainingColumn()
    now[0] = 200.0
    assert column.render(task).plain == "-:--:--"
    now[0] = 360.0
    bar.update(task_id, advance=1)
    now[0] = 360.1
    bar.update(task_id, advance=1)
    assert column.render(task).plain == "0:24:00"  # 360.1 s for 2 of 10: 8 more at that pace
    rich_left = TimeRemainingColumn().render(task).plain
    assert rich_left in ("0:00:00", "0:00:01", "-:--:--")  # what the bar showed before: seconds
