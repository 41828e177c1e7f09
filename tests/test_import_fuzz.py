"""Fuzz ``primspace import``: damaged inputs end in a data set or in one line, never a traceback.

For each importer format a small valid input is written, then damaged ``N_MUTATIONS`` times
(seeded: truncated at a random byte, or a few bytes changed, either anywhere or in the
first 2 KiB where the headers and metadata lie; text files also get characters that
matter to their syntax). Each damaged copy is imported through the command line, in this
process. Every outcome must be exit 0 with a data set that loads, or exit 2 with exactly
one line on stderr starting ``primspace: error:``; never another exit status, never a
traceback, never an output file (or a temporary one) left behind by a failed import.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from primspace.data import MotionDataset
from test_data_import_frames import frames_of, joints_of, robomimic_demos, write_robomimic
from test_import_lerobot import write_v2, write_v3

SEED = 24
N_MUTATIONS = int(os.environ.get("PRIMSPACE_FUZZ_N", 30))  # more to search longer: PRIMSPACE_FUZZ_N=1000
LENGTH = 9
_SYNTAX = b'",{}[]:0-.e\n 9N\\/'  # characters that change what a CSV or JSON line means


def _mutation(data: bytes, rng: np.random.Generator, i: int) -> tuple[str, bytes]:
    """Damaged copy ``i`` of ``data``: ``(description, bytes)``."""
    kind = ("truncate", "change", "change-head")[i % 3]
    if kind == "truncate":
        cut = int(rng.integers(0, len(data)))
        return f"#{i}: truncated to {cut} of {len(data)} bytes", data[:cut]
    damaged = bytearray(data)
    span = min(len(damaged), 2048) if kind == "change-head" else len(damaged)
    changes = []
    for _ in range(int(rng.integers(1, 9))):
        at = int(rng.integers(0, span))
        if rng.random() < 0.5:
            damaged[at] = _SYNTAX[int(rng.integers(len(_SYNTAX)))]
        else:
            damaged[at] ^= int(rng.integers(1, 256))
        changes.append(at)
    return f"#{i}: bytes {sorted(changes)} changed", bytes(damaged)


# ------------------------------------------------------------------ small valid inputs


def _npz(root, compressed=False):
    path = root / "demos.npz"
    seqs = {f"motor_{i}": joints_of(t, 2, float(i)) for i, t in enumerate((5, 7, 6))}
    frames = {f"images_{i}": frames_of(t, 8, 8) for i, t in enumerate((5, 7, 6))}
    (np.savez_compressed if compressed else np.savez)(
        path, **seqs, **frames, labels=np.array(["a", "b", "a"]), joint_names=np.array(["x", "y"]), dt=0.05
    )
    return path, [path], ("--image-size", "8x8")


def _csv(root):
    folder = root / "demos"
    for name, t in (("a/one.csv", 5), ("b/two.csv", 7), ("three.csv", 6)):
        file = folder / name
        file.parent.mkdir(parents=True, exist_ok=True)
        rows = [f"{0.1 * k:.2f},{v[0]:.4f},{v[1]:.4f}" for k, v in enumerate(joints_of(t, 2, 1.0))]
        file.write_text("time,x,y\n" + "\n".join(rows) + "\n")
    return folder, sorted(folder.rglob("*.csv")), ("--format", "csv")


def _robomimic(root):
    path = root / "lift.hdf5"
    demos = robomimic_demos((6, 8))
    for obs in demos.values():
        obs["agentview_image"] = obs["agentview_image"][:, :8, :8]
    write_robomimic(path, demos)
    return (
        path,
        [path],
        ("--joints", "robot0_joint_pos,robot0_gripper_qpos", "--images", "agentview_image", "--image-size", "8x8"),
    )


def _lerobot(root, what):
    """A LeRobot v3.0 data set (two episodes in one data file and video); v2.x for ``v2-meta``."""
    folder = root / "ds"
    if what == "v2-meta":
        write_v2(folder, lengths=(6, 5), tasks=("a", "b"))
        return folder, [folder / "meta" / "info.json", folder / "meta" / "episodes.jsonl"], ()
    write_v3(folder, lengths=(6, 5), tasks=("a", "b"), data_files=((0, 0),) * 2, video_files=((0, 0),) * 2)
    if what == "meta":
        meta = [folder / "meta" / "info.json", folder / "meta" / "tasks.parquet"]
        return folder, meta + sorted((folder / "meta" / "episodes").rglob("*.parquet")), ()
    if what == "parquet":
        return folder, sorted((folder / "data").rglob("*.parquet")), ()
    return (
        folder,
        sorted((folder / "videos").rglob("*.mp4")),
        ("--images", "observation.images.top", "--image-size", "8x8"),
    )


def _npy(root):
    """An EIPL-style folder: padded joints (N, Tmax, J), frames, lengths of two of three, labels."""
    folder = root / "lab"
    folder.mkdir()
    joints = np.stack(
        [np.pad(joints_of(t, 2, float(i)), ((0, 7 - t), (0, 0)), mode="edge") for i, t in enumerate((5, 7, 6))]
    )
    np.save(folder / "joints.npy", joints)
    np.save(folder / "images.npy", np.stack([frames_of(7, 8, 8) for _ in range(3)]))
    np.save(folder / "labels.npy", np.array(["a", "b", "a"]))
    return folder, sorted(folder.glob("*.npy")), ("--format", "npy", "--image-size", "8x8")


def _ts(root):
    """Two UEA .ts files of one problem: two channels, two classes, series of different lengths."""
    head = "@problemName Tiny\n@univariate false\n@dimensions 2\n@classLabel true a b\n@data\n"
    train, test = root / "Tiny_TRAIN.ts", root / "Tiny_TEST.ts"
    train.write_text(head + "1,2,3,4:0.5,0.25,0,-1:a\n4,3.5,3:2,2,2:b\n", encoding="utf-8")
    test.write_text(head + "0,0,1,1,2:1e-3,2e-3,3e-3,4e-3,5e-3:b\n", encoding="utf-8")
    return root, [train, test], ("--format", "ts")


FORMATS = {
    "npz": _npz,
    "npz-compressed": lambda root: _npz(root, compressed=True),
    "csv": _csv,
    "robomimic": _robomimic,
    "lerobot-meta": lambda root: _lerobot(root, "meta"),
    "lerobot-parquet": lambda root: _lerobot(root, "parquet"),
    "lerobot-video": lambda root: _lerobot(root, "video"),
    "lerobot-v2-meta": lambda root: _lerobot(root, "v2-meta"),
    "npy": _npy,
    "ts": _ts,
}


def _outcome(run_cli, src, args, out) -> str:
    """'' when the import ended as it should, else what went wrong."""
    try:
        res = run_cli("import", src, *args, "-T", str(LENGTH), "--out", out)
    except Exception as exc:  # noqa: BLE001 - the point: anything that escapes the command is a finding
        return f"escaped the command: {type(exc).__name__}: {str(exc)[:300]}"
    left = sorted(p.name for p in out.parent.iterdir())
    if res.code == 0:
        try:
            ds = MotionDataset.load(out)
        except Exception as exc:  # noqa: BLE001
            return f"exit 0 but the output does not load: {exc}"
        if ds.length != LENGTH or not np.isfinite(ds.motor).all():
            return f"exit 0 but the output is not a {LENGTH}-step data set"
        out.unlink()
        return f"files left beside the output: {left}" if left != [out.name] else ""
    lines = [line for line in res.err.splitlines() if line.strip()]
    if res.code != 2 or len(lines) != 1 or not lines[0].startswith("primspace: error:") or "Traceback" in res.err:
        return f"exit {res.code}, stderr {res.err[-600:]!r}"
    return f"failed import left {left}" if left else ""


@pytest.mark.slow
@pytest.mark.parametrize("fmt", list(FORMATS))
def test_damaged_inputs_import_or_fail_in_one_line(run_cli, tmp_path, fmt):
    (tmp_path / "in").mkdir()
    src, targets, args = FORMATS[fmt](tmp_path / "in")
    out = tmp_path / "out" / "demos.h5"
    out.parent.mkdir()
    assert _outcome(run_cli, src, args, out) == ""  # the undamaged input imports
    rng = np.random.default_rng([SEED, list(FORMATS).index(fmt)])
    findings = []
    for i in range(N_MUTATIONS):
        target = targets[int(rng.integers(len(targets)))]
        original = target.read_bytes()
        description, damaged = _mutation(original, rng, i)
        target.write_bytes(damaged)
        problem = _outcome(run_cli, src, args, out)
        if problem:
            findings.append(f"{target.name} {description}: {problem}")
        target.write_bytes(original)
    assert not findings, "\n".join(findings)
