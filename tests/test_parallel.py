"""The job executor: every backend gives the same outcomes; a failure stops nothing else."""

import operator
import os
import subprocess
import sys

import pytest

from primspace.errors import UserError
from primspace.parallel import run_jobs

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
        "import operator, sys; from primspace.parallel import run_jobs; "
        "list(run_jobs(operator.add, [(1, 2), (3, 4)], workers=2, progress=False)); "
        "assert 'ray' not in sys.modules, 'ray imported'"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def _ray_or_skip():
    """CI sets PRIMSPACE_REQUIRE_RAY=1 so a missing ray fails instead of skipping."""
    if os.environ.get("PRIMSPACE_REQUIRE_RAY") == "1":
        import ray  # noqa: F401
    else:
        pytest.importorskip("ray")


@pytest.mark.ray
def test_ray_backend_on_a_local_instance_matches_local():
    _ray_or_skip()
    assert outcomes(backend="ray", workers=2) == EXPECTED
