"""The job executor: every backend gives the same outcomes; a failure stops nothing else."""

import operator
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from primspace.utils.errors import UserError
from primspace.utils.parallel import run_jobs

ITEMS = [(6, 3), (1, 0), (5, 2), (9, 4), (7, 7)]


def outcomes(**kwargs):
    got = sorted(run_jobs(operator.truediv, ITEMS, progress=False, **kwargs), key=lambda o: o.index)
    return [(o.index, o.value, o.error) for o in got]


EXPECTED = [
    (0, 2.0, None),
    (1, None, "ZeroDivisionError: division by zero"),
    (2, 2.5, None),
    (3, 2.25, None),
    (4, 1.0, None),
]


def test_in_process_runs_every_job_and_reports_the_failure():
    assert outcomes(workers=1) == EXPECTED


def test_process_pool_gives_the_same_outcomes():
    assert outcomes(workers=2) == EXPECTED


def test_unknown_backend():
    with pytest.raises(UserError, match="unknown backend"):
        outcomes(backend="dask")


def test_the_local_path_never_imports_ray():
    code = (
        "import operator, sys; from primspace.utils.parallel import run_jobs; "
        "list(run_jobs(operator.add, [(1, 2), (3, 4)], workers=2, progress=False)); "
        "assert 'ray' not in sys.modules, 'ray imported'"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def _pool_workers(driver_pid: int) -> list[int]:
    """PIDs of the live spawn workers whose parent is ``driver_pid`` (Linux /proc)."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            stat = (proc / "stat").read_text()
            cmdline = (proc / "cmdline").read_bytes()
        except OSError:
            continue
        state, ppid = stat.rsplit(")", 1)[1].split()[:2]
        if int(ppid) == driver_pid and state != "Z" and b"spawn_main" in cmdline:
            found.append(int(proc.name))
    return found


def _alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_pool_workers_exit_when_the_driver_is_killed():
    code = (
        "import time; from primspace.utils.parallel import run_jobs; print('go', flush=True); "
        "list(run_jobs(time.sleep, [(300,), (300,)], workers=2, progress=False))"
    )
    driver = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert driver.stdout.readline().strip() == "go"
        deadline = time.monotonic() + 120
        workers = []
        while len(workers) < 2 and time.monotonic() < deadline:
            time.sleep(0.2)
            workers = _pool_workers(driver.pid)
        assert len(workers) == 2, "the pool did not start its workers"
    finally:
        driver.kill()  # SIGKILL: no finally blocks, no pool shutdown in the driver
        driver.wait()
    deadline = time.monotonic() + 60
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(_alive(pid) for pid in workers), "orphaned pool workers kept running their jobs"


def _ray_or_skip():
    """CI sets PRIMSPACE_REQUIRE_RAY=1 so a missing ray fails instead of skipping."""
    if os.environ.get("PRIMSPACE_REQUIRE_RAY") == "1":
        import ray  # noqa: F401
    else:
        pytest.importorskip("ray")


@pytest.mark.ray
@pytest.mark.slow
def test_ray_backend_on_a_local_instance_matches_local():
    _ray_or_skip()
    assert outcomes(backend="ray", workers=2) == EXPECTED
