"""The codes kept beside a summary (issue 42, item 6): every finished run's fitted, inferred
and initial codes and its samples, the data set's labels, read back exactly, written under
the summary's overwrite rules, and enough to cluster again without the experiment directory."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.experiments.intra import run_intra, split_indices
from primspace.experiments.presets import ExperimentPreset, default_train
from primspace.experiments.runs import load_codes
from primspace.experiments.summary_codes import write_summary_with_codes
from primspace.experiments.workspace import ExperimentDir
from primspace.results.codes import VERSION_KEY, codes_in_data_order, codes_path, read_codes
from primspace.results.layout import phase_dir
from primspace.results.summary import read_summary, summarize
from primspace.utils.errors import OutputExistsError, UserError

#: test_experiments.py's tiny grid, with the calibrated start (an inference from projection's fit)
TINY = ExperimentPreset(
    name="tiny",
    data_preset="demo",
    train_fraction=0.5,
    inits=("zero", "projection", "calibrated"),
    latent_dims=(4,),
    fit_epochs=3,
    infer_epochs=2,
    train=replace(default_train(), batch_size=8),
    images=False,
    cluster_latent_dim=4,
    cluster_r2=0.99,
    lasa_length=20,
)
KEYS = ["intra/zero-q4-s0", "intra/projection-q4-s0", "intra/calibrated-q4-s0"]
COMMAND = "primspace experiment intra --out tiny"


@pytest.fixture(scope="module")
def exp(tiny_data, tmp_path_factory):
    """The intra grid run on the tiny data set (conftest's ``tiny_data``)."""
    from primspace.experiments import intra

    exp = ExperimentDir(tmp_path_factory.mktemp("exp") / "out", TINY, data=tiny_data, workers=1, progress=False)
    with pytest.MonkeyPatch.context() as mp:  # figures and animations: not what a summary holds (seconds)
        mp.setattr(intra.figures, "draw_intra", lambda *a, **k: [])
        mp.setattr(intra, "write_animations", lambda *a, **k: None)
        run_intra(exp)
    return exp


@pytest.fixture(scope="module")
def stored(exp, tmp_path_factory):
    """The summary and its codes, written as ``primspace summarize`` writes them."""
    out = tmp_path_factory.mktemp("docs") / "tiny.json"
    summary = write_summary_with_codes(out, summarize(exp.path, "tiny", COMMAND), exp.path)
    return out, summary


@pytest.mark.slow
def test_the_codes_of_every_run_are_kept_exactly(exp, stored):
    out, summary = stored
    path = out.with_name("tiny.codes.npz")
    assert codes_path(out) == path and path.is_file()
    assert summary["codes"] == {"file": "tiny.codes.npz", "runs": 3, "missing": []}
    assert read_summary(out)["codes"] == summary["codes"]  # the docs find it by name
    codes = read_codes(path)
    assert list(codes["runs"]) == KEYS
    data = exp.dataset()
    train, evaluation = split_indices(data.labels, TINY.train_fraction, 0)
    for key, run in codes["runs"].items():
        init = key.split("/")[1].split("-")[0]
        for phase, samples in (("fit", train), ("infer", evaluation)):
            where = phase_dir(exp.path, init, 4, 0, phase)
            for part, file in (("latents", "latents.npy"), ("latents_init", "latents_init.npy")):
                assert run[f"{phase}/{part}"].dtype == np.float32
                assert np.array_equal(run[f"{phase}/{part}"], np.load(where / file)), (key, phase, part)
            config = json.loads((where / "config.json").read_text())
            assert run[f"{phase}/indices"].dtype == np.int64
            assert np.array_equal(run[f"{phase}/indices"], config["data"]["indices"])
            assert sorted(run[f"{phase}/indices"]) == sorted(samples)
    calibrated, projection = codes["runs"]["intra/calibrated-q4-s0"], codes["runs"]["intra/projection-q4-s0"]
    assert np.array_equal(calibrated["fit/latents"], projection["fit/latents"])  # the fit it inferred with
    assert not np.array_equal(calibrated["infer/latents_init"], projection["infer/latents_init"])
    assert np.array_equal(codes["labels"], data.labels) and codes["labels"].dtype == np.int64
    assert codes["label_names"] == list(data.label_names) and codes["n_samples"] == len(data)


@pytest.mark.slow
def test_clustering_is_checked_again_from_the_codes_alone(exp, stored):
    """The codes in data-set order are the directory's, so the clustering of the codes (as the
    clustering experiment runs it) comes out the same from the file alone, labels included."""
    from primspace.cluster import LowRankSubspaceClustering
    from primspace.cluster.metrics import clustering_accuracy

    out, _ = stored
    codes = read_codes(codes_path(out))
    for key, run in codes["runs"].items():
        init = key.split("/")[1].split("-")[0]
        z, is_train = codes_in_data_order(run, codes["n_samples"])
        z_dir, is_train_dir = load_codes(exp, init, 4, 0)
        assert np.array_equal(z, z_dir) and np.array_equal(is_train, is_train_dir)
        k = len(codes["label_names"])
        fitted = [LowRankSubspaceClustering(n_clusters=k, r2_target=0.99, random_state=0).fit(x) for x in (z, z_dir)]
        assert np.array_equal(fitted[0].labels_, fitted[1].labels_)
        assert 0 < clustering_accuracy(codes["labels"], fitted[0].labels_) <= 1


@pytest.mark.slow
def test_a_codes_file_is_replaced_only_when_asked_and_only_its_own(exp, tmp_path):
    out = tmp_path / "tiny.json"
    summary = summarize(exp.path, "tiny", COMMAND)
    write_summary_with_codes(out, summary, exp.path)
    codes = codes_path(out)
    before = codes.read_bytes()
    with pytest.raises(OutputExistsError):  # the summary exists: refused before the codes are written
        write_summary_with_codes(out, summary, exp.path)
    out.unlink()
    with pytest.raises(OutputExistsError):  # the codes exist: refused, and no summary written
        write_summary_with_codes(out, summary, exp.path)
    assert not out.exists() and codes.read_bytes() == before
    write_summary_with_codes(out, summary, exp.path, overwrite=True)  # an earlier codes file: replaced
    assert read_codes(codes)["runs"].keys() == set(KEYS)
    np.savez_compressed(codes, latents=np.zeros(3))  # someone else's archive at that name
    out.unlink()
    with pytest.raises(UserError, match="replaces only an earlier codes file"):
        write_summary_with_codes(out, summary, exp.path, overwrite=True)
    assert not out.exists()
    with pytest.raises(UserError, match="not a primspace codes file"):
        read_codes(codes)
    codes.write_text("not an archive")
    with pytest.raises(UserError, match="cannot read the codes"):
        read_codes(codes)
    assert not list(tmp_path.glob(".*.tmp"))  # nothing half-written left behind


@pytest.mark.slow
def test_runs_whose_folders_are_gone_are_named_and_labels_kept_when_readable(exp, tmp_path):
    copy = tmp_path / "exp"
    shutil.copytree(exp.path, copy)
    shutil.rmtree(copy / "runs" / "intra" / "zero-q4-s0" / "infer")
    meta = json.loads((copy / "experiment.json").read_text())
    meta["data"] = str(tmp_path / "gone.h5")  # the data file did not travel
    (copy / "experiment.json").write_text(json.dumps(meta))
    summary = write_summary_with_codes(tmp_path / "s.json", summarize(copy, "s", COMMAND), copy)
    assert summary["codes"] == {"file": "s.codes.npz", "runs": 2, "missing": ["intra/zero-q4-s0"]}
    codes = read_codes(tmp_path / "s.codes.npz")
    assert list(codes["runs"]) == KEYS[1:]
    assert codes["labels"] is None and codes["label_names"] is None and codes["n_samples"] is None


@pytest.mark.slow
def test_the_command_writes_the_codes_beside_the_summary(exp, tmp_path, run_cli):
    out = tmp_path / "docs" / "tiny.json"
    result = run_cli("summarize", exp.path, "--name", "tiny", "--command", COMMAND, "--out", out)
    assert result.code == 0, result.err
    assert f"wrote {out} and {tmp_path / 'docs' / 'tiny.codes.npz'} (the codes of 3 runs)" in result.out
    with np.load(tmp_path / "docs" / "tiny.codes.npz") as found:
        assert int(found[VERSION_KEY]) == 1
    out.unlink()
    result = run_cli("summarize", exp.path, "--name", "tiny", "--command", COMMAND, "--out", out)
    assert_user_error(result, "tiny.codes.npz")
    assert not out.exists()
    np.savez_compressed(tmp_path / "docs" / "tiny.codes.npz", other=np.ones(2))
    result = run_cli("summarize", exp.path, "--name", "tiny", "--command", COMMAND, "--out", out, "--overwrite")
    assert_user_error(result, "tiny.codes.npz", "replaces only an earlier codes file")
    assert not out.exists()


def test_the_runs_kept_are_intras_tunes_reruns_and_the_composite_grids_each_once(tmp_path):
    from primspace.experiments.summary_codes import stored_runs

    run = {"init": "projection", "latent_dim": 40, "seed": 0}
    results = {
        "intra": {"runs": [run | {"key": "intra/projection-q40-s0"}, {"init": "zero", "latent_dim": 40, "seed": 1}]},
        "tune": {"tuned": {"runs": [run | {"key": "intra/projection-q40-s0"}, run | {"init": "zero"}]}},
        "composite": {"runs": [run | {"key": "composite/projection-q40-s0"}]},
    }
    (tmp_path / "results").mkdir()
    for name, found in results.items():
        (tmp_path / "results" / f"{name}.json").write_text(json.dumps(found))
    assert stored_runs(tmp_path) == [
        ("intra/projection-q40-s0", "projection"),
        ("intra/zero-q40-s1", "zero"),
        ("tuned/zero-q40-s0", "zero"),
        ("composite/projection-q40-s0", "projection"),
    ]
