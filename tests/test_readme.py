"""The README's Python example runs as written (on a small data set made here)."""

import re
from pathlib import Path

import numpy as np
import pytest

from test_train import primitives

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.mark.slow
def test_readme_python_example_runs_as_written(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
    example = next(b for b in blocks if "AutoDecoder" in b)
    monkeypatch.chdir(tmp_path)
    # seven primitives (the example clusters into 7), short sequences: the 800 + 600 epochs take seconds;
    # the example fits the even samples and infers the odd ones, as the command-line walk-through does
    primitives(4, seed=0, T=20, K=7).save("demos.h5")
    namespace: dict = {}
    exec(compile(example, str(README), "exec"), namespace)
    Z, Z_new, labels, motor = namespace["Z"], namespace["Z_new"], namespace["labels"], namespace["motor"]
    assert Z.shape == (14, 20) and Z_new.shape == (14, 20) and motor.shape == (14, 20, 4)
    assert sorted(set(labels)) == list(range(7))
    assert namespace["frames"] is None  # these demonstrations have no camera frames
    np.testing.assert_array_equal(namespace["model"].codes_, Z)  # loaded back from runs/fit
    assert (tmp_path / "runs" / "fit" / "checkpoint.pt").is_file()


def test_readme_stays_a_front_door():
    """README is what, quick start, one picture, results at a glance and links: at most 1,500 words;
    detail lives in docs/."""
    words = len(README.read_text(encoding="utf-8").split())
    assert words <= 1500, f"README.md has {words} words"
