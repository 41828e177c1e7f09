"""The README's command-line walk-through runs as written, on a robomimic-style file with
camera frames made here: import -> info -> one session split by index files (the ``seq``
line, run by the shell) -> train (with images) on one half -> predict and infer the other
half -> reconstruct -> cluster (learned codes and raw trajectories).

It trains 800 + 600 epochs with images as the README says: about 5 minutes on 2 idle
cores (10 min measured under load), too long for every CI run, so it runs only with
``PRIMSPACE_WALKTHROUGH=1`` (``PRIMSPACE_WALKTHROUGH=1 make test PYTEST_ARGS=tests/test_readme_walkthrough.py``).
"""

import json
import os
import re
import shlex
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import read_png

README = Path(__file__).resolve().parents[1] / "README.md"
# other importers, or other options of the same one (tests/test_readme_imports.py runs those lines);
# a primitive by name needs labelled data, which robomimic files lack (tests/test_predict_primitive.py
# runs `predict --primitive` on a CSV folder labelled by its folder names)
ALTERNATIVES = ("--format csv", "demos.npz", "--format lerobot", "--format npy", "--filter-key", "--primitive push")


def _lines() -> list[str]:
    section = README.read_text(encoding="utf-8").split("## Using it on your own demonstrations", 1)[1]
    block = re.search(r"```\n(.*?)```", section, flags=re.S).group(1).replace("\\\n", " ")
    lines = [line.split("#", 1)[0].strip() for line in block.splitlines()]
    return [line for line in lines if line and not any(a in line for a in ALTERNATIVES)]


def _commands() -> list[list[str]]:
    return [shlex.split(line)[1:] for line in _lines() if line.startswith("primspace")]


def _robomimic(path: Path, n: int, seed: int) -> None:
    """``n`` demonstrations of 7 kinds: 7 arm joints, 2 gripper joints, 32x32 camera frames."""
    rng = np.random.default_rng(seed)
    with h5py.File(path, "w") as f:
        for i in range(n):
            t = int(rng.integers(25, 40))
            s = np.linspace(0, 1, t)[:, None]
            kind, x = i % 7, rng.uniform(0, 1)
            arm = np.sin((kind + 1) * s + np.arange(7)) * (0.5 + x)
            frames = np.zeros((t, 32, 32, 3), dtype=np.uint8)
            for k in range(t):
                r = int(4 + 20 * s[k, 0])
                frames[k, r : r + 6, 4 * kind : 4 * kind + 6] = 255
            obs = f.create_group(f"data/demo_{i}/obs")
            obs["robot0_joint_pos"] = arm
            obs["robot0_gripper_qpos"] = np.c_[s, -s] * 0.04
            obs["agentview_image"] = frames


@pytest.mark.slow
@pytest.mark.skipif(os.environ.get("PRIMSPACE_WALKTHROUGH") != "1", reason="5 min: set PRIMSPACE_WALKTHROUGH=1")
def test_readme_walkthrough_runs_as_written(run_cli, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _robomimic(tmp_path / "lift.hdf5", 14, seed=0)
    commands = _commands()
    assert [c[0] for c in commands] == [
        "import",
        "info",
        "train",
        "predict",
        "infer",
        "reconstruct",
        "cluster",
        "cluster",
    ]
    for line in _lines():
        if not line.startswith("primspace"):  # the split: index files written by the shell
            subprocess.run(line, shell=True, check=True, cwd=tmp_path)
            continue
        args = shlex.split(line)[1:]
        result = run_cli(*args)
        assert result.code == 0, (args, result.err)
    fitted, new = (np.loadtxt(name, dtype=int).tolist() for name in ("fit.txt", "new.txt"))
    assert fitted == list(range(0, 14, 2)) and new == list(range(1, 14, 2))
    with h5py.File("demos.h5") as f:
        assert f["images"].shape == (14, 61, 48, 64, 3) and f["motor"].shape == (14, 61, 9)
    last = json.loads(Path("runs/fit/metrics.jsonl").read_text().splitlines()[-1])
    assert last["epoch"] == 800 and last["vision"] is not None  # trained with the frames
    assert np.load("runs/fit/latents.npy").shape == (7, 20) and np.load("runs/new/latents.npy").shape == (7, 20)
    with h5py.File("pred/predicted.h5") as f:
        assert f["motor"].shape == (7, 61, 9)
    assert Path("pred/result.json").is_file() and read_png("pred/prediction.png").shape[0] > 100
    assert read_png("sample0.png").shape[0] > 100
    assert Path("clusters/labels.csv").is_file() and Path("clusters-raw/labels.csv").is_file()
