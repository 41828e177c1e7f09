"""The Makefile's install, read through ``make -n`` (nothing runs): torch comes from PyTorch's CPU
index when it answers, from pip's configured index otherwise, and the plain install carries the
``predict`` extra (``primspace act`` needs it)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CPU_INDEX = "https://download.pytorch.org/whl/cpu"

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")


def _dry_run(tmp_path: Path, target: str, *variables: str) -> str:
    """The commands ``make TARGET`` would run in a fresh checkout (its Makefile and pyproject only)."""
    shutil.copy(ROOT / "Makefile", tmp_path / "Makefile")
    (tmp_path / "pyproject.toml").write_text("")
    done = subprocess.run(
        ["make", "-n", target, *variables], cwd=tmp_path, capture_output=True, text=True, check=True, timeout=60
    )
    return done.stdout


@pytest.mark.parametrize("target", ["install", "install-test"])
def test_torch_comes_from_the_cpu_index_with_a_fallback(tmp_path, target):
    script = _dry_run(tmp_path, target)
    probe, _, rest = script.partition(" then ")
    assert f"urlopen('{CPU_INDEX}/torch/'" in probe  # one quick look at the index before pip
    from_index, _, fallback = rest.partition(" else ")
    assert f"pip install --quiet --index-url {CPU_INDEX} torch==2.13.0" in from_index
    fallback = fallback.split(" fi", 1)[0]
    assert "does not answer" in fallback and "pip install" not in fallback  # the project's call resolves torch
    lines = script.splitlines()
    torch_step = next(i for i, line in enumerate(lines) if CPU_INDEX in line)
    project_step = next(i for i, line in enumerate(lines) if "-e '." in line)
    assert torch_step < project_step and "torch==2.13.0" in lines[project_step]  # the pin kept: no other torch


def test_the_index_and_the_pin_can_be_overridden(tmp_path):
    script = _dry_run(tmp_path, "install", "TORCH_INDEX=https://example.org/whl", "TORCH=torch==2.12.0")
    assert "--index-url https://example.org/whl torch==2.12.0" in script
    assert CPU_INDEX not in script


def test_the_plain_install_has_the_predict_extra(tmp_path):
    plain = _dry_run(tmp_path, "install")
    assert "-e '.[predict]'" in plain
    full = _dry_run(tmp_path, "install-test")
    extras = full.split("-e '.[", 1)[1].split("]", 1)[0].split(",")
    assert "predict" in extras and "test" in extras


def test_an_older_python_is_refused_in_one_line_before_the_venv(tmp_path):
    """``make`` with a Python below 3.11 stops before making .venv, naming the version and the fix."""
    shutil.copy(ROOT / "Makefile", tmp_path / "Makefile")
    (tmp_path / "pyproject.toml").write_text("")
    old = tmp_path / "python3.10"
    old.write_text("#!/bin/sh\nexit 1\n")  # what `python3.10 -c 'sys.exit(version < (3, 11))'` answers
    old.chmod(0o755)
    done = subprocess.run(
        ["make", "install", f"PYTHON={old}"], cwd=tmp_path, capture_output=True, text=True, timeout=60
    )
    assert done.returncode != 0
    assert f"primspace needs Python >= 3.11 (pyproject's requires-python); {old} is older" in done.stderr
    assert not (tmp_path / ".venv").exists()
