"""Inputs that gave a traceback, a hang or a silent wrong answer (issue 38), each answered in
one line with exit status 2 and nothing written."""

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.utils.errors import UserError
from primspace.utils.seeds import MAX_SEED, check_seed
from test_train import primitives


@pytest.fixture(scope="module")
def data_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("hostile") / "d.h5"
    primitives(2, seed=0, T=12, J=2).save(path)
    return path


@pytest.mark.parametrize("seed", [-1, MAX_SEED + 1, 2.5, True])
def test_a_seed_out_of_range_is_one_line(seed):
    with pytest.raises(UserError, match=r"^seed must be a whole number in 0\.\.\d+, got"):
        check_seed(seed)
    assert check_seed(np.int64(3)) == 3 and check_seed(MAX_SEED) == MAX_SEED


def test_a_negative_seed_is_refused_by_every_command_that_takes_one(run_cli, data_file, tmp_path):
    train = ("train", data_file, "--epochs", "1", "--latent-dim", "2", "--layers", "4,2")
    assert_user_error(run_cli(*train, "--seed", "-1", "--out", tmp_path / "neg"), "seed", "-1")
    assert not (tmp_path / "neg").exists()
    assert run_cli(*train, "--out", tmp_path / "run").code == 0
    assert_user_error(
        run_cli("infer", tmp_path / "run", data_file, "--epochs", "1", "--seed", "-1", "--out", tmp_path / "inf"), "-1"
    )
    assert_user_error(
        run_cli(
            "predict",
            tmp_path / "run",
            data_file,
            "--init",
            "zero",
            "--epochs",
            "1",
            "--seed",
            "-1",
            "--out",
            tmp_path / "pred",
        ),
        "-1",
    )
    assert not (tmp_path / "inf").exists() and not (tmp_path / "pred").exists()
    assert_user_error(run_cli("generate", "--preset", "demo", "--seed", "-1", "--out", tmp_path / "g.h5"), "-1")
    assert not (tmp_path / "g.h5").exists()


def test_negative_experiment_seeds_are_refused_before_the_folder_is_made(run_cli, data_file, tmp_path):
    res = run_cli(
        "experiment", "intra", "--preset", "demo", "--data", data_file, "--seeds", "0,-1", "--out", tmp_path / "exp"
    )
    assert_user_error(res, "--seeds", "-1")
    assert not (tmp_path / "exp").exists()  # a corrected run is not refused by a half-made folder


@pytest.mark.parametrize(
    "text, match",
    [("0_1", "'0_1' is not a whole number"), ("1e3", "'1e3' is not a whole"), (str(2**70), "beyond 64-bit integers")],
)
def test_an_index_file_holds_plain_whole_numbers(tmp_path, text, match):
    """Issue 38: '0_1' read as 1 (Python's digit grouping) and 2**70 gave an OverflowError traceback."""
    from primspace.data.indices import read_indices
    from primspace.utils.errors import DataError

    path = tmp_path / "idx.txt"
    path.write_text(f"0 {text}\n")
    with pytest.raises(DataError, match=match):
        read_indices(path)


def test_an_image_size_beyond_reason_is_refused_before_any_allocation(run_cli, data_file, tmp_path):
    """Issue 38: --image-size 80000x80000 asked for 179 GiB; -T had a bound, the size none."""
    np.savez(tmp_path / "f.npz", motor=np.zeros((2, 5, 2)), images=np.zeros((2, 5, 8, 8, 3), np.uint8))
    res = run_cli("import", tmp_path / "f.npz", "-T", "5", "--image-size", "80000x80000", "--out", tmp_path / "x.h5")
    assert_user_error(res, "--image-size 80000x80000", "at most 1024")
    assert not (tmp_path / "x.h5").exists()


HOSTILE = [
    "/../../../victim",
    "../up",
    "/abs/path",
    "nul\x00byte",
    "new\nline",
    "x" * 300,
    "<script>alert(1)</script>",
    ".hidden",
    "..",
    "a/b",
    "a_b",
    "",
]


def test_a_name_from_data_never_reaches_a_path(tmp_path):
    """Issue 38, item 1: a label '/../../../victim' became figures/reconstruction_/../../../victim.png
    and replaced a file two levels above the experiment. Every figure and animation name goes
    through one function: the file stays in OUT/figures, its name is short, and two names never
    share a file."""
    from primspace.results.layout import animation_file, figure_file

    out = tmp_path / "exp"
    figures = (out / "figures").resolve()
    paths = [figure_file(out, f"reconstruction_{name}") for name in HOSTILE] + [animation_file(out, n) for n in HOSTILE]
    for path in paths:
        assert path.resolve().parent == figures, path
        assert len(path.name) < 120 and "\x00" not in path.name and "\n" not in path.name
    assert len({p.name for p in paths}) == len(paths)  # 'a/b' and 'a_b' differ
    assert figure_file(out, "reconstruction_push").name == "reconstruction_push.png"  # plain names unchanged


@pytest.fixture
def small_disk(tmp_path):
    """A 300 KiB file system of our own (tmpfs, as root), removed after the test; skipped where
    this machine does not allow one."""
    import subprocess

    mount = tmp_path / "disk"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=300k", "tmpfs", str(mount)], capture_output=True)
    if made.returncode != 0:
        pytest.skip(f"cannot mount a small file system here ({made.stderr.decode().strip()[:80]})")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=False)


def test_a_full_disk_is_one_line_naming_the_output_and_the_disk(run_cli, data_file, tmp_path, small_disk):
    """Issue 38, item 4: an HDF5 import segfaulted after pages of h5py errors; train printed a
    torch.save traceback. Now: one line, exit 2, the output and its disk named, nothing half-written."""
    np.savez(tmp_path / "big.npz", motor=np.random.default_rng(0).normal(size=(200, 100, 7)))
    res = run_cli("import", tmp_path / "big.npz", "-T", "100", "--out", small_disk / "x.h5")
    assert_user_error(res, str(small_disk / "x.h5"), "cannot write", "free")
    assert not any(small_disk.iterdir())
    big = primitives(40, seed=0, T=60, J=7)  # a checkpoint of this model does not fit in 300 KiB
    big.save(tmp_path / "big.h5")
    res = run_cli("train", tmp_path / "big.h5", "--epochs", "1", "--latent-dim", "16", "--out", small_disk / "run")
    assert_user_error(res, "checkpoint.pt", "cannot write", "no space left")
    assert not [p for p in (small_disk / "run").iterdir() if p.name.endswith(".tmp")]  # no half-written file


@pytest.mark.slow
def test_predict_options_are_never_ignored_without_a_word(run_cli, data_file, tmp_path):
    """Issue 38, item 7: --observe '' meant 0.25, --iterations without --online and --fitted-data
    with a start that does not read it were ignored, a fully observed motion trailed off."""
    train = ("train", data_file, "--epochs", "1", "--latent-dim", "2", "--layers", "4,2", "--out", tmp_path / "run")
    assert run_cli(*train).code == 0
    predict = ("predict", tmp_path / "run", data_file)
    assert_user_error(run_cli(*predict, "--observe", "", "--out", tmp_path / "a"), "--observe ''")
    assert_user_error(
        run_cli(*predict, "--iterations", "3", "--out", tmp_path / "b"), "--iterations goes with --online"
    )
    assert_user_error(
        run_cli(*predict, "--init", "zero", "--fitted-data", data_file, "--out", tmp_path / "c"),
        "--fitted-data is read by auto, mixture, nearest and calibrated",
    )
    assert not any((tmp_path / name).exists() for name in "abc")
    whole = run_cli(*predict, "--observe", "1.0", "--no-judge", "--out", tmp_path / "d")
    assert whole.code == 0, whole.err
    assert "no step left to score" in whole.out and not whole.out.rstrip().endswith(":")


@pytest.mark.parametrize("name", ["", "   ", "two\nlines", "nul\x00"])
def test_a_summary_name_is_one_line(tmp_path, name):
    """Issue 38, item 7: summarize --name empty or multi-line was accepted (it is a heading)."""
    from primspace.results.summary import summarize

    with pytest.raises(UserError, match="the summary's name is a heading on one line"):
        summarize(tmp_path, name)


def test_a_folder_of_another_command_is_named_for_what_it_is(run_cli, data_file, tmp_path):
    """Issue 38, item 8: '(no such result.json)' for a folder holding predict's result.json, and
    summarize calling predict's and segment's result.json 'not written by a primspace command'."""
    from primspace.utils.outputs import describe

    train = ("train", data_file, "--epochs", "1", "--latent-dim", "2", "--layers", "4,2", "--out", tmp_path / "run")
    assert run_cli(*train).code == 0
    pred = tmp_path / "pred"
    assert run_cli("predict", tmp_path / "run", data_file, "--no-judge", "--out", pred).code == 0
    assert describe(pred / "result.json") == "a JSON file written by primspace predict"
    res = run_cli("cluster", data_file, "--primitives", "2", "--out", pred, "--overwrite")
    assert_user_error(
        res, "is not a primspace cluster output", "its result.json is a JSON file written by primspace predict"
    )


def test_a_write_error_names_the_output_not_its_temporary(tmp_path):
    """Issue 38, item 8: a read-only folder's error named the temporary file instead of --out."""
    from primspace.utils.files import os_error, temp_prefix

    out = tmp_path / "result.h5"
    tmp = tmp_path / f"{temp_prefix(out.name)}abc.tmp"
    err = os_error(PermissionError(13, "Permission denied", str(tmp)), out)
    assert str(err) == f"{out}: cannot write (Permission denied)"
    other = os_error(PermissionError(13, "Permission denied", str(tmp_path / "x")), out)
    assert str(other).startswith(str(tmp_path / "x"))  # a file of the user's is named as it is


def test_segment_names_the_file_field_and_sample_of_a_short_demonstration(run_cli, tmp_path):
    """Issue 38, item 8: segment named a demonstration but not the file or field."""
    from primspace.data import MotionDataset
    from test_segmentation_synthesis import single_primitive_run

    pieces = single_primitive_run(run_cli, tmp_path)
    steps = np.full((2, 60), -1)
    steps[0], steps[1, :9] = 0, 0
    long = MotionDataset(
        np.repeat(pieces.motor[:2], 2, axis=1),
        lengths=[60, 9],
        step_labels=steps,
        step_segments=steps,
        joint_names=pieces.joint_names,
        label_names=["a"],
    )
    long.save(tmp_path / "long.h5")
    res = run_cli("segment", tmp_path / "run", tmp_path / "long.h5", "--min-steps", "12", "--out", tmp_path / "seg")
    assert_user_error(res, f"{tmp_path / 'long.h5'}, field 'lengths', sample 1: 9 steps, fewer than a segment's least")
    assert not (tmp_path / "seg").exists()


@pytest.mark.slow
def test_an_experiment_on_data_with_hostile_names_writes_inside_its_folder_only(tmp_path, tiny_data):
    """Issue 38, item 1, end to end: label names that are paths ('/../../../victim', '../up', an
    absolute path, a newline, 300 characters, markup) go through the intra experiment, its
    figures and its report; every file written lies inside the experiment folder, and a file
    beside it is untouched."""
    import dataclasses

    from primspace.data import MotionDataset
    from primspace.experiments.intra import run_intra
    from primspace.experiments.workspace import ExperimentDir
    from primspace.report import build_report
    from test_experiments import TINY

    data = MotionDataset.load(tiny_data)
    hostile = ["/../../../victim", "../up", "/abs/x", "new\nline", "x" * 300, "<script>alert(1)</script>", "a/b"]
    dataclasses.replace(data, label_names=hostile[: len(data.label_names)], path=None).save(tmp_path / "hostile.h5")
    victim = tmp_path / "victim.png"
    victim.write_bytes(b"mine")
    root = tmp_path / "deep" / "er"
    root.mkdir(parents=True)
    before = {p for p in tmp_path.rglob("*")}
    exp = ExperimentDir(root / "exp", TINY, data=tmp_path / "hostile.h5", workers=1, progress=False)
    run_intra(exp)
    build_report(exp.path)
    written = {p for p in tmp_path.rglob("*")} - before
    outside = [p for p in written if exp.path not in p.parents and p != exp.path]
    assert not outside, outside
    assert victim.read_bytes() == b"mine"
    figures = list((exp.path / "figures").iterdir())
    assert figures and all(p.parent == exp.path / "figures" for p in figures)
