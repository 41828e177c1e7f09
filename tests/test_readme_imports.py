"""Every ``primspace import`` line of README's own-data section, and of docs/data.md's list of
importers (which README links), runs as written (issue 26).

The inputs the lines name (``demos/``, ``demos.npz``, ``lab/``, ``lift.hdf5``, ``so100_pick/``)
are written here in their formats: a CSV folder, an npz archive, an EIPL-style folder of
padded ``.npy`` arrays, a robomimic file with ``mask/train`` and demo-level ``actions``,
and a LeRobot v3.0 data set of 21 episodes in two data files and two videos. Each line is
run verbatim in that folder, and what it wrote is checked against what the line says. The
``.ts`` line of docs/data.md reads the UEA archive's files (tests/test_import_ts.py covers
that importer), so it is the one line left out.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from test_data_import_frames import frames_of, joints_of
from test_import_lerobot import write_v3
from test_import_robomimic_splits import _write as write_robomimic_with_masks

ROOT = Path(__file__).resolve().parents[1]
README, DATA_DOC = ROOT / "README.md", ROOT / "docs" / "data.md"
TRAIN = ["demo_10", "demo_2", "demo_0", "demo_5"]  # mask/train, listed out of order


def import_lines(text: str) -> list[list[str]]:
    """The arguments of each ``primspace import`` line of the first code block of ``text``."""
    block = re.search(r"```\n(.*?)```", text, flags=re.S).group(1).replace("\\\n", " ")
    lines = [line.split("#", 1)[0].strip() for line in block.splitlines()]
    return [shlex.split(line)[1:] for line in lines if line.startswith("primspace import")]


def readme_imports() -> list[list[str]]:
    """README's own-data section's import lines, then docs/data.md's (its block after "Each format
    is one module"), the ``.ts`` line left out."""
    readme = README.read_text(encoding="utf-8").split("## Using it on your own demonstrations", 1)[1]
    data_doc = DATA_DOC.read_text(encoding="utf-8").split("Each format is one module", 1)[1]
    return import_lines(readme) + [args for args in import_lines(data_doc) if "ts" not in args]


def _inputs(root: Path) -> None:
    """Everything the README's import lines read, under ``root``."""
    for name, t in (("reach/a.csv", 9), ("push/b.csv", 12)):
        file = root / "demos" / name
        file.parent.mkdir(parents=True, exist_ok=True)
        file.write_text("x,y\n" + "\n".join(f"{a:.4f},{b:.4f}" for a, b in joints_of(t, 2, 0.0)) + "\n")
    np.savez(root / "demos.npz", motor_0=joints_of(8, 3, 0.0), motor_1=joints_of(11, 3, 1.0))
    (root / "lab").mkdir()
    real = [joints_of(t, 4, float(i)) for i, t in enumerate((9, 14, 11))]
    np.save(root / "lab" / "joints.npy", np.stack([np.pad(r, ((0, 14 - len(r)), (0, 0)), mode="edge") for r in real]))
    np.save(root / "lab" / "images.npy", np.stack([frames_of(14, 24, 32) for _ in real]))
    write_robomimic_with_masks(root / "lift.hdf5", masks={"train": TRAIN, "valid": ["demo_1"]})
    n = 21
    write_v3(
        root / "so100_pick",
        lengths=(5,) * n,
        tasks=("push", "lift", "place") * 7,
        data_files=tuple((0, int(e >= 11)) for e in range(n)),
        video_files=tuple((0, int(e >= 11)) for e in range(n)),
        meta_split=11,
    )


def test_every_readme_import_line_runs_as_written(run_cli, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _inputs(tmp_path)
    lines = readme_imports()
    sources = [args[1] for args in lines]
    assert sources == ["demos/", "demos/", "demos.npz", "lab/", "lift.hdf5", "lift.hdf5", "so100_pick/"]
    written = []
    for args in lines:
        out = args[args.index("--out") + 1]
        if Path(out).exists():  # several lines write demos.h5: each is checked, then removed
            Path(out).unlink()
        result = run_cli(*args)
        assert result.code == 0, (args, result.err)
        ds = MotionDataset.load(out)
        assert ds.length == 61 and ds.source_ids is not None
        written.append(ds)
    lab, train, pick = written[3], written[5], written[6]
    assert len(lab) == 3 and lab.has_images
    np.testing.assert_allclose(lab.motor[0, -1], joints_of(9, 4, 0.0)[-1], rtol=1e-6)  # padding trimmed
    assert [s.rsplit("/", 1)[1] for s in train.source_ids] == ["demo_0", "demo_2", "demo_5", "demo_10"]
    assert train.n_joints == 7 and all(n.startswith("actions") for n in train.joint_names)
    assert [s.rsplit(" ", 1)[1] for s in pick.source_ids] == [str(e) for e in (0, 3, *range(10, 21))]
    assert len(pick) == 13 and pick.has_images and pick.label_names == ["lift", "place", "push"]
