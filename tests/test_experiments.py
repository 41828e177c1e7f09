"""The paper's experiments on a tiny simulated data set: grids, results, figures, report,
resuming, failures, and the Ray backend giving the same numbers as the local one."""

import json
import os
from dataclasses import replace

import numpy as np
import pytest

from conftest import assert_figure, assert_user_error
from primspace.experiments import presets as experiment_presets
from primspace.experiments.clustering import run_clustering
from primspace.experiments.inter import run_inter
from primspace.experiments.intra import run_intra, split_indices
from primspace.experiments.presets import ExperimentPreset, default_train
from primspace.experiments.success import run_success
from primspace.experiments.workspace import ExperimentDir
from primspace.report import build_report
from primspace.results.tables import qualitative_check
from primspace.utils.errors import UserError

TINY = ExperimentPreset(
    name="tiny",
    data_preset="demo",
    train_fraction=0.5,
    inits=("zero", "projection"),
    latent_dims=(4,),
    fit_epochs=3,
    infer_epochs=2,
    train=replace(default_train(), batch_size=8),
    images=False,
    cluster_latent_dim=4,
    cluster_r2=0.99,
    inter_inits=("projection",),
    inter_epochs=(2, 2),
    lasa_length=20,
)


@pytest.fixture(scope="module")
def finished(tiny_data, tmp_path_factory):
    """An experiment directory with intra, clustering and success done."""
    exp = ExperimentDir(tmp_path_factory.mktemp("exp") / "out", TINY, data=tiny_data, workers=1, progress=False)
    intra = run_intra(exp)
    clustering = run_clustering(exp)
    success = run_success(exp)
    return exp, intra, clustering, success


def test_split_is_random_per_primitive_and_seeded():
    labels = np.repeat(np.arange(7), 10)
    train, evaluation = split_indices(labels, 0.2, seed=0)
    assert len(train) == 14 and len(evaluation) == 56
    assert set(np.bincount(labels[train])) == {2}
    assert np.array_equal(split_indices(labels, 0.2, seed=0)[0], train)
    assert not np.array_equal(split_indices(labels, 0.2, seed=1)[0], train)
    assert not set(train) & set(evaluation)


@pytest.mark.slow
def test_intra_grid_results_and_figures(finished):
    exp, intra, _, _ = finished
    assert intra["failures"] == {}
    assert sorted(r["key"] for r in intra["runs"]) == ["intra/projection-q4-s0", "intra/zero-q4-s0"]
    for run in intra["runs"]:
        assert [h["epoch"] for h in run["fit"]] == [0, 1, 2, 3]
        assert [h["epoch"] for h in run["infer"]] == [0, 1, 2]
        assert run["n_train"] == 7 and run["n_eval"] == 7
    # drawn figures, not blank ones (the thresholds: measured values over ~2, and an empty figure
    # measured ink 0.03 and no chromatic pixel), with the data in their colours
    for phase in ("fit", "infer"):  # a curve per init: zero in tab:blue, projection in tab:green (~700-900 px each)
        assert_figure(exp.figure(f"intra_loss_{phase}"), colours=("tab:blue", "tab:green"), min_colour_pixels=300)
    for name in ("latent_pca2d", "latent_pca3d"):  # 3 panels of 2 dots coloured by block position (~90 px)
        assert_figure(exp.figure(name), width=(900, 2500), min_ink=0.035, min_coloured=40)
    # the generated joint curves (tab:orange, dashed, ~4300 px) over the black ground truth
    assert_figure(
        exp.figure("reconstruction_grasp"), width=(900, 2500), colours=("tab:orange", "black"), min_colour_pixels=1500
    )
    ok, text = qualitative_check(intra)
    assert ok is None and "not enough runs" in text  # no random init in this grid
    assert json.loads((exp.path / "experiment.json").read_text())["timings"]["intra"] > 0


def _hungarian_accuracy(true, pred) -> float:
    """Fraction of samples in a cluster matched one-to-one to their primitive (maximum matching)."""
    from scipy.optimize import linear_sum_assignment

    _, t = np.unique(true, return_inverse=True)
    _, p = np.unique(pred, return_inverse=True)
    counts = np.zeros((p.max() + 1, t.max() + 1), dtype=int)
    np.add.at(counts, (p, t), 1)
    rows, cols = linear_sum_assignment(-counts)
    return counts[rows, cols].sum() / len(true)


@pytest.mark.slow
def test_clustering_and_success_results(finished):
    from primspace.cluster import LowRankSubspaceClustering
    from primspace.experiments.runs import load_codes
    from primspace.results.layout import INITIAL_CODES, LEARNED_CODES, intra_key, run_dir_of
    from primspace.sim.success import evaluate_dataset
    from primspace.train import load_run, reconstruct

    exp, _, clustering, success = finished
    data = exp.dataset()
    q, seed = clustering["latent_dim"], clustering["seed"]
    rows = {(r["init"], r["codes"]) for r in clustering["latent"]}
    assert rows == {("zero", LEARNED_CODES), ("projection", LEARNED_CODES), ("projection", INITIAL_CODES)}
    for r in clustering["latent"]:
        assert r["rank"] >= 1 and r["r2"] >= 0.99 - 1e-9
        # the stored accuracy is that of clustering these codes at the preset's R², Hungarian-matched
        if r["codes"] == LEARNED_CODES:
            z = load_codes(exp, r["init"], q, seed)[0].astype(np.float64)
        else:
            run_dir = run_dir_of(exp.path, intra_key("projection", q, seed))
            z = np.empty((len(data), q))
            for part in ("fit", "infer"):
                run = load_run(run_dir / part)
                z[run.indices] = run.initial_latents
        est = LowRankSubspaceClustering(n_clusters=7, r2_target=TINY.cluster_r2, random_state=0).fit(z)
        assert r["tau"] == pytest.approx(est.tau_, rel=1e-9) and r["rank"] == est.rank_, r
        assert r["accuracy"] == pytest.approx(_hungarian_accuracy(data.labels, est.labels_), abs=1e-12), r
    # the untrained projection P m already separates the primitives: 14 samples, 2 per primitive,
    # randomly paired clusters score 0.54 on average and >= 0.8 in < 0.1% of draws; measured 12/14
    initial = next(r for r in clustering["latent"] if r["codes"] == INITIAL_CODES)
    assert initial["accuracy"] >= 0.8, initial
    assert clustering["trajectory"]["lasa"]["n"] == 182 and clustering["trajectory"]["lasa"]["k"] == 26
    assert clustering["trajectory"]["data"]["n"] == 14

    # every recorded trajectory passes the judge: both samples of every primitive
    names = list(data.label_names)
    assert success["label_names"] == names
    recorded = success["recorded"]
    assert recorded["counts"] == dict.fromkeys(names, 2) and recorded["rates"] == dict.fromkeys(names, 1.0)
    assert recorded["overall"] == 1.0 and not any(recorded["failed_criteria"].values())
    # each generated rate is the mean of the judge's verdicts on that init's reconstructed eval motions
    assert set(success["generated"]) == {"zero", "projection"}
    for init, res in success["generated"].items():
        inferred = load_run(run_dir_of(exp.path, intra_key(init, q, seed)) / "infer")
        motor, _ = reconstruct(inferred, images=False)
        verdicts = evaluate_dataset(data.without_images().subset(inferred.indices), motor)
        by_primitive: dict = {}
        for v in verdicts:
            by_primitive.setdefault(v.primitive, []).append(v.success)
        assert res["counts"] == {p: len(v) for p, v in by_primitive.items()}
        assert sum(res["counts"].values()) == len(inferred.indices) == 7
        assert res["rates"] == pytest.approx({p: np.mean(v) for p, v in by_primitive.items()}, abs=1e-12)
        assert res["overall"] == pytest.approx(np.mean([v.success for v in verdicts]), abs=1e-12)
        weighted = sum(res["rates"][p] * res["counts"][p] for p in res["rates"]) / sum(res["counts"].values())
        assert res["overall"] == pytest.approx(weighted, abs=1e-12)
        for p, rate in res["rates"].items():  # failed criteria are listed exactly where a motion failed
            assert bool(res["failed_criteria"][p]) == (rate < 1), (init, p, res["failed_criteria"][p])


@pytest.mark.slow
def test_report_embeds_every_section(finished):
    exp = finished[0]
    html = build_report(exp.path).read_text()
    for heading in (
        "Summary",
        "Data",
        "Intra-primitive generalisation",
        "Subspace clustering",
        "Success rates of generated motions",
        "Latent space and reconstructions",
        "Appendix A",
        "Configuration, versions, timings",
    ):
        assert f">{heading}" in html, heading
    assert html.count("<img") >= 10 and "data:image/png;base64," in html
    assert "trains on joint angles only" in html  # the preset's lack of a vision loss is said


@pytest.mark.slow
def test_figures_are_drawn_from_the_results_alone(finished, tmp_path):
    """Copied without its runs and data, a directory's results redraw the same figures."""
    import shutil

    from conftest import read_png
    from primspace.experiments import figures

    exp = finished[0]
    copy = tmp_path / "copy"
    shutil.copytree(exp.path / "results", copy / "results")
    drawn = figures.draw_intra(copy) + figures.draw_latent_accuracy(copy)
    names = sorted(p.name for p in drawn)
    assert names == sorted(
        [
            "intra_loss_fit.png",
            "intra_loss_infer.png",
            "latent_pca2d.png",
            "latent_pca3d.png",
            "reconstruction_grasp.png",
            "reconstruction_push.png",
            "reconstruction_circle_cw.png",
            "latent_accuracy_vs_r2.png",
        ]
    )
    for path in drawn:
        assert np.array_equal(read_png(path), read_png(exp.figure(path.stem))), path.name


@pytest.mark.slow
def test_rerun_skips_finished_runs(finished, grid_only):
    exp = finished[0]
    metrics = sorted(exp.path.glob("runs/intra/*/*/metrics.jsonl"))
    before = [p.stat().st_mtime_ns for p in metrics]
    again = run_intra(ExperimentDir(exp.path, TINY, data=exp.data_path, progress=False))
    assert [p.stat().st_mtime_ns for p in metrics] == before
    assert len(again["runs"]) == 2


@pytest.mark.slow
def test_a_failed_run_is_reported_and_the_others_finish(tiny_data, tmp_path, run_cli, monkeypatch, grid_only):
    broken = ExperimentPreset(**{**TINY.to_dict(), "name": "broken", "inits": ("zero", "bogus")})
    monkeypatch.setitem(experiment_presets.PRESETS, "broken", broken)
    out = tmp_path / "exp"
    res = run_cli("experiment", "intra", "--preset", "broken", "--data", tiny_data, "--out", out, "--workers", "1")
    assert_user_error(res, "1 run(s) failed", "intra/bogus-q4-s0", "re-run")
    assert (out / "runs/intra/bogus-q4-s0/error.txt").exists()
    assert (out / "runs/intra/zero-q4-s0/result.json").exists()
    assert (out / "report.html").exists()
    results = json.loads((out / "results/intra.json").read_text())
    assert [r["init"] for r in results["runs"]] == ["zero"]


@pytest.mark.slow
def test_experiment_dir_refuses_another_preset_or_data(finished, tmp_path):
    from primspace.utils.errors import UserError

    exp = finished[0]
    with pytest.raises(UserError, match="made with preset 'tiny'"):
        ExperimentDir(exp.path, ExperimentPreset(name="other", data_preset="demo"))
    other = tmp_path / "other.h5"
    other.write_bytes(exp.data_path.read_bytes())
    with pytest.raises(UserError, match="made with data"):
        ExperimentDir(exp.path, TINY, data=other)


@pytest.fixture(scope="module")
def inter_done(tiny_data, tmp_path_factory):
    """The tiny preset's inter-primitive folds, run once for the tests that read them."""
    exp = ExperimentDir(tmp_path_factory.mktemp("inter") / "inter", TINY, data=tiny_data, workers=1, progress=False)
    return exp, run_inter(exp)


@pytest.mark.slow
def test_inter_primitive_folds(inter_done):
    exp, results = inter_done
    assert results["failures"] == {}
    assert sorted(r["fold"] for r in results["runs"]) == list(range(7))
    for r in results["runs"]:
        assert r["n_new"] == 2 and r["n_phase1"] == 12 and r["n_replay"] == 1
        assert len(r["phase2"]) == 3
    # the projection init's mean curve and its std band, in tab:green (~1100 px)
    assert_figure(exp.figure("inter_loss"), colours=("tab:green",), min_colour_pixels=400)


def _scaled_targets(run_dir, data):
    from primspace.train import load_run

    run = load_run(run_dir)
    return run.scaler.transform(data.motor[run.indices])


@pytest.mark.slow
def test_every_fold_scales_its_targets_into_the_unit_range(inter_done, tiny_data):
    """The paper scales each joint "over all motions": a phase-2 primitive whose joints did
    not move in phase 1 (grasp's fingers) must not keep its targets in physical units."""
    from primspace.data import MotionDataset

    data = MotionDataset.load(tiny_data)
    exp, results = inter_done
    grasp = data.label_names.index("grasp")
    fingers = [j for j, name in enumerate(data.joint_names) if "finger" in name]
    assert fingers, data.joint_names
    for r in results["runs"]:
        for phase in ("phase1", "phase2"):
            y = _scaled_targets(exp.path / "runs" / r["key"] / phase, data)
            assert np.abs(y).max() <= 1 + 1e-6, (r["key"], phase, np.abs(y).max())
        if r["fold"] == grasp:  # the held-out grasp's fingers span the whole range
            y = _scaled_targets(exp.path / "runs" / r["key"] / "phase2", data)
            assert np.ptp(y[..., fingers]) > 1.0


@pytest.mark.slow
def test_intra_fit_and_infer_targets_lie_in_the_unit_range(finished, tiny_data):
    from primspace.data import MotionDataset

    exp, intra, _, _ = finished
    data = MotionDataset.load(tiny_data)
    for r in intra["runs"]:
        fit_y = _scaled_targets(exp.path / "runs" / r["key"] / "fit", data)
        infer_y = _scaled_targets(exp.path / "runs" / r["key"] / "infer", data)
        assert np.abs(fit_y).max() <= 1 + 1e-6 and np.abs(infer_y).max() <= 1 + 1e-6
        both = np.concatenate([fit_y, infer_y])  # the extremes are reached over all motions
        assert np.allclose(both.reshape(-1, both.shape[-1]).max(0)[np.ptp(data.motor, axis=(0, 1)) > 0], 1.0)


@pytest.mark.ray
@pytest.mark.slow
def test_ray_backend_gives_the_same_numbers_as_local(tiny_data, tmp_path, grid_only):
    from test_parallel import _ray_or_skip

    _ray_or_skip()
    small = ExperimentPreset(**{**TINY.to_dict(), "name": "small", "inits": ("projection",)})
    local = run_intra(ExperimentDir(tmp_path / "local", small, data=tiny_data, workers=1, progress=False))
    ray = run_intra(ExperimentDir(tmp_path / "ray", small, data=tiny_data, backend="ray", workers=2, progress=False))
    assert local["failures"] == ray["failures"] == {}
    assert [r["fit"] for r in local["runs"]] == [r["fit"] for r in ray["runs"]]
    assert [r["infer"] for r in local["runs"]] == [r["infer"] for r in ray["runs"]]


@pytest.mark.slow
def test_demo_runs_end_to_end_and_says_whether_the_paper_holds(tiny_data, tmp_path, monkeypatch):
    from primspace.demo import run_demo

    demo = ExperimentPreset(**{**TINY.to_dict(), "name": "demo", "inits": ("zero", "random", "projection")})
    monkeypatch.setitem(experiment_presets.PRESETS, "demo", demo)
    out = tmp_path / "demo"
    out.mkdir()
    os.symlink(tiny_data, out / "data.h5")  # the demo's data, already simulated
    summary = run_demo(out, workers=1, progress=False)
    assert f"report: {out / 'report.html'}" in summary
    assert "paper's qualitative result" in summary and ("HOLDS" in summary)
    html = (out / "report.html").read_text()
    for title in ("Summary", "claims, checked", "Subspace clustering", "Success rates of generated motions"):
        assert title in html, title
    assert html.count('src="data:image/png;base64,') >= 8
    # the table's cluster accuracy is that of the learned codes; the untrained P m codes get their own line
    latent = json.loads((out / "results" / "clustering.json").read_text())["latent"]
    learned = next(r["accuracy"] for r in latent if r["init"] == "projection" and r["codes"] == "learned")
    initial = next(r["accuracy"] for r in latent if r["init"] == "projection" and r["codes"] != "learned")
    row = next(line for line in summary.splitlines() if line.startswith("projection"))
    assert float(row.split()[-2]) == pytest.approx(learned, abs=5e-4)
    assert f"projection codes before training (initial (P m, untrained)): {initial:.3f}" in summary


@pytest.mark.slow
def test_cli_overrides_are_checked_and_recorded(tiny_data, tmp_path, run_cli, monkeypatch, grid_only):
    monkeypatch.setitem(experiment_presets.PRESETS, "tiny", TINY)
    out = tmp_path / "exp"
    bad = run_cli(
        "experiment", "intra", "--preset", "tiny", "--data", tiny_data, "--out", out, "--inits", "zero,projektion"
    )
    assert_user_error(bad, "unknown initialisation(s) projektion")
    assert not out.exists()
    ok = run_cli(
        "experiment",
        "intra",
        "--preset",
        "tiny",
        "--data",
        tiny_data,
        "--out",
        out,
        "--inits",
        "zero",
        "--epochs",
        "2,1",
        "--workers",
        "1",
        "--no-report",
    )
    assert ok.code == 0, ok.err
    meta = json.loads((out / "experiment.json").read_text())
    assert meta["preset_config"]["inits"] == ["zero"] and meta["preset_config"]["fit_epochs"] == 2
    assert not (out / "report.html").exists()
    again = run_cli(
        "experiment",
        "intra",
        "--preset",
        "tiny",
        "--data",
        tiny_data,
        "--out",
        out,
        "--inits",
        "zero",
        "--epochs",
        "3,1",
    )
    assert_user_error(again, "made with other settings", "fit_epochs=2")
    # the command that made the runs is kept, and a summary names it without being told
    command = (
        f"primspace experiment intra --preset tiny --data {tiny_data} --out {out} --inits zero --epochs 2,1 "
        "--workers 1 --no-report"
    )
    assert [i["command"] for i in json.loads((out / "experiment.json").read_text())["invocations"]] == [command]
    summary = tmp_path / "summary.json"
    made = run_cli("summarize", out, "--name", "tiny", "--out", summary)
    assert made.code == 0, made.err
    assert json.loads(summary.read_text())["command"] == command


def test_preset_json_roundtrip_and_unknown_field():
    again = ExperimentPreset.from_dict(json.loads(json.dumps(TINY.to_dict())))
    assert again == TINY
    with pytest.raises(UserError, match="unknown experiment preset field.*: warmup"):
        ExperimentPreset.from_dict({**TINY.to_dict(), "warmup": 3})


@pytest.mark.slow
def test_the_papers_claims_are_quoted_verbatim_and_checked(finished):
    """Every quoted sentence appears word for word in the paper; every claim whose
    experiment ran gets a verdict, and a rule can fail."""
    import re
    from pathlib import Path

    from primspace.results.claims import CLAIMS, check_claims

    paper = Path(__file__).resolve().parents[2] / "shared" / "paper.tex"
    if not paper.exists():
        pytest.skip("shared/paper.tex is not beside the checkout")
    text = re.sub(r"\s+", " ", paper.read_text(encoding="utf-8"))
    for claim in CLAIMS:
        assert claim.quote in text, claim.quote
    exp, intra, _, _ = finished
    rows = {r["key"]: r for r in check_claims(exp.path)}
    assert rows["inter"]["verdict"] == "not run"
    # the tiny grid has zero and projection: the zero-vs-projection claims get a verdict
    assert rows["infer_similar"]["verdict"] in ("holds", "does not hold")
    assert rows["fit_random"]["verdict"] == "cannot be checked"  # no random runs in TINY
    # a rule that can fail: doctor the results so zero's eval loss is 100x projection's
    doctored = json.loads(json.dumps(intra))
    for r in doctored["runs"]:
        if r["init"] == "zero":
            for h in r["infer"]:
                h["loss"] *= 1e3
    from primspace.results.claims import CLAIMS as C

    similar = next(c for c in C if c.key == "infer_similar")
    assert similar.check(doctored)[0] is False
    html = build_report(exp.path).read_text()
    assert "claims, checked" in html and "differs very slightly from random linear projection case." in html


@pytest.mark.slow
def test_a_summary_holds_what_the_claims_and_docs_read(finished):
    """The stored summary of a directory gives the same verdicts and numbers as the
    directory itself (the docs are generated from summaries), and stays small."""
    from primspace.report.markdown import render_summary
    from primspace.results.claims import check_claims
    from primspace.results.summary import read_summary, summarize

    exp, intra, _, success = finished
    with pytest.raises(UserError, match="recorded no commands"):  # made from Python: no command to name
        summarize(exp.path, "tiny")
    summary = summarize(exp.path, "tiny", "primspace experiment success --out tiny")
    assert set(summary["results"]) >= {"intra", "success", "clustering", "probe"}
    assert check_claims(summary["results"]) == check_claims(exp.path)
    last = {r["key"].split("/")[1]: r["infer"][-1]["loss"] for r in intra["runs"]}
    kept = {
        f"{r['init']}-q{r['latent_dim']}-s{r['seed']}": r["infer"][-1]["loss"]
        for r in summary["results"]["intra"]["runs"]
    }
    assert kept.keys() == last.keys()
    assert all(kept[k] == pytest.approx(last[k], rel=1e-4) for k in last)  # 5 significant digits kept
    assert summary["results"]["success"]["generated"]["zero"]["by_tolerance"]  # the judge's sweep is kept
    path = exp.path / "summary.json"
    path.write_text(json.dumps(summary))
    assert len(path.read_bytes()) < 50_000
    assert read_summary(path) == summary
    text = render_summary(summary)
    assert "| 4 | projection | 1 |" in text and "The paper's sentences, checked" in text
    path.write_text("{}")
    with pytest.raises(UserError, match="not a primspace summary"):
        read_summary(path)


@pytest.mark.slow
def test_tune_gives_every_init_the_same_grid_on_a_validation_split(finished, tmp_path, grid_only):
    """Fair baselines: each init is tuned over the same settings and epochs on a validation
    part carved from the fitted part (never the evaluation part), and the intra protocol
    reruns with each init's choice beside the shared setting."""
    from primspace.experiments.intra import split_indices
    from primspace.experiments.tuning import TUNING_GRID, run_tune, settings_of, validation_split
    from primspace.results.tables import tuning_table
    from primspace.sim.generate import GenerationConfig, generate_dataset

    with pytest.raises(UserError, match="one sample per primitive, so none is left to validate on"):
        run_tune(finished[0])  # two motions per primitive, half fitted: nothing to validate on
    config = GenerationConfig(
        block_x=(0.42, 0.47, 0.52, 0.57), block_y=(0.0,), block_size=(0.05,), length=31, images=False
    )
    generate_dataset(config, seed=0, out=tmp_path / "four.h5", progress=False)
    exp = ExperimentDir(tmp_path / "tune", TINY, data=tmp_path / "four.h5", workers=1, progress=False)
    data = exp.dataset()
    train, evaluation = split_indices(data.labels, TINY.train_fraction, 0)
    fit_idx, val_idx = validation_split(data.labels, train, 0)
    assert set(fit_idx) | set(val_idx) == set(train) and not set(fit_idx) & set(val_idx)
    assert not set(val_idx) & set(evaluation)
    settings = settings_of(TINY)
    assert len(settings) == len(TUNING_GRID["taus"]) * len(
        TUNING_GRID["latent_lr_factor"]
    )  # the preset's is in the grid
    tune = run_tune(exp)
    assert tune["failures"] == {}
    for init in ("zero", "projection"):  # the same grid for both, scored on the validation part
        tried = [v for v in tune["validation"] if v["init"] == init]
        assert len(tried) == len(settings) and {v["n_validation"] for v in tried} == {len(val_idx)}
        best = min(tried, key=lambda v: v["validation_loss"])
        assert tune["chosen"][init]["validation_loss"] == best["validation_loss"]
    assert {(r["init"], r["seed"]) for r in tune["tuned"]["runs"]} == {("zero", 0), ("projection", 0)}
    columns, rows = tuning_table(tune)
    assert columns[-2:] == ["final eval loss, tuned", "projection lower, seeds (shared → tuned)"] and len(rows) == 2
    assert rows[1][1] == "projection" and rows[1][-1] == "—" and rows[0][-1].endswith("of 1")
    again = run_tune(exp)  # resumable: every point is found finished
    assert again["chosen"] == tune["chosen"]


def test_a_summary_names_every_version_that_ran_into_the_directory():
    """A stage added to an older directory by a newer version shows beside the version
    that made it (0.8's summaries named only the first)."""
    from primspace.results.summary import recorded_versions

    meta = {
        "primspace": "0.5.0",
        "invocations": [
            {"command": "a", "primspace": "0.6.1"},
            {"command": "b", "primspace": "0.5.0"},
            {"command": "c", "primspace": "0.8.0"},
            {"command": "d", "primspace": "0.8.0"},
        ],
    }
    assert recorded_versions(meta) == "0.5.0, 0.6.1, 0.8.0"
    assert recorded_versions({"primspace": "0.4.0"}) == "0.4.0" and recorded_versions({}) is None


def test_tuning_table_names_the_tuned_q_on_rows_of_another_q():
    """The setting is chosen at one q and applied at every q: a row of another q says whose
    choice it is and shows no validation loss (it had none); the last column counts, seed by
    seed, where projection ends below the init, shared and tuned."""
    from primspace.results.tables import tuning_table

    def run(init, q, seed, loss):
        return {"init": init, "latent_dim": q, "seed": seed, "infer": [{"loss": 1.0}, {"loss": loss}]}

    chosen = {"taus": [4.0, 16.0], "latent_lr": 0.01, "validation_loss": 0.5}
    shared = [
        run("zero", 8, 0, 0.4),
        run("zero", 40, 0, 0.3),
        run("zero", 40, 1, 0.3),
        run("projection", 40, 0, 0.1),
        run("projection", 40, 1, 0.1),
    ]
    tuned = [
        run("zero", 8, 0, 0.2),
        run("zero", 40, 0, 0.05),
        run("zero", 40, 1, 0.2),
        run("projection", 40, 0, 0.1),
        run("projection", 40, 1, 0.1),
    ]
    tune = {
        "latent_dim": 40,
        "chosen": {"zero": chosen, "projection": chosen},
        "tuned": {"runs": tuned},
        "shared": {"runs": shared},
    }
    _, rows = tuning_table(tune)
    assert rows[0][:4] == [8, "zero", "q = 40's choice", "—"] and rows[0][-1] == "0 of 0 → 0 of 0"
    assert rows[2][:4] == [40, "zero", "τ 4, 16; latent lr 0.01", "0.5"]
    assert rows[2][-1] == "2 of 2 → 1 of 2"  # tuning closed the gap in seed 0
    assert rows[3][-1] == "—"


@pytest.mark.slow
def test_tiny_experiment_numbers_are_pinned(finished):
    """Same seed, same numbers: the tiny grid's losses, clustering accuracies and success
    rates as of 0.2 (CPU). A refactor that changes any of them changes results, and must
    say so (re-pin with the reason in the commit)."""
    _, intra, clustering, success = finished
    losses = {r["key"]: (r["fit"][-1]["loss"], r["infer"][0]["loss"], r["infer"][-1]["loss"]) for r in intra["runs"]}
    pinned = {
        "intra/zero-q4-s0": (0.28391703963279724, 0.2757866084575653, 0.2735570967197418),
        "intra/projection-q4-s0": (0.25451040267944336, 0.25507625937461853, 0.25482308864593506),
    }
    assert losses.keys() == pinned.keys()
    for key, values in pinned.items():
        np.testing.assert_allclose(losses[key], values, rtol=1e-5, err_msg=key)
    accuracy = {(r["init"], r["codes"]): r["accuracy"] for r in clustering["latent"]}
    assert accuracy == pytest.approx(
        {
            ("zero", "learned"): 5 / 14,
            ("projection", "learned"): 12 / 14,
            ("projection", "initial (P m, untrained)"): 12 / 14,
        }
    )
    assert {i: g["overall"] for i, g in success["generated"].items()} == {"zero": 0.0, "projection": 0.0}
    assert success["recorded"]["overall"] == 1.0


@pytest.mark.slow
def test_clustering_and_success_over_seeds(finished, tiny_data, tmp_path, grid_only):
    """Two seeds: the first seed's results are those of the one-seed tiny grid, bit for bit;
    the second's are under ``by_seed``; the outcome table averages both."""
    from primspace.results.tables import outcome_spread_table

    _, _, c1, s1 = finished
    two = ExperimentDir(tmp_path / "two", replace(TINY, seeds=(0, 1)), data=tiny_data, workers=1, progress=False)
    c2, s2 = run_clustering(two), run_success(two)
    assert c2["latent"] == c1["latent"] and s2["generated"] == s1["generated"]
    assert c1["by_seed"] == {} and s1["by_seed"] == {}
    assert {r["init"] for r in c2["by_seed"]["1"]} == {"zero", "projection"} and len(c2["by_seed"]["1"]) == 3
    assert set(s2["by_seed"]["1"]) == {"zero", "projection"}
    assert outcome_spread_table(c1, s1) is None
    columns, rows = outcome_spread_table(c2, s2)
    row = next(r for r in rows if r[0] == "projection")
    rates = [s2["generated"]["projection"]["overall"], s2["by_seed"]["1"]["projection"]["overall"]]
    assert row[1] == 2 and row[2] == f"{np.mean(rates):.3g} ± {np.std(rates, ddof=1):.2g}"  # sample std
    assert any(r[0] == "untrained P m" for r in rows)


@pytest.mark.slow
def test_lasa_preset_imports_real_demonstrations_and_runs_the_protocol(tmp_path):
    """The intra-primitive protocol on LASA (issue 14): the preset imports the data itself
    (offline), fits 2 of each shape's 7 demonstrations and infers the other 5."""
    from primspace.experiments.presets import PRESETS

    preset = PRESETS["lasa"].with_overrides(
        latent_dims=(4,), seeds=(0,), fit_epochs=2, infer_epochs=2, inits=("zero", "projection")
    )
    preset = replace(preset, cluster_latent_dim=4)
    exp = ExperimentDir(tmp_path / "lasa", preset, workers=1, progress=False)
    results = run_intra(exp)
    data = exp.dataset()
    assert data.source.startswith("lasa:") and len(data) == 182 and len(data.label_names) == 26
    assert results["splits"]["0"] == {"n_train": 52, "n_eval": 130}
    assert {r["init"] for r in results["runs"]} == {"zero", "projection"}
    clustering = run_clustering(exp)
    assert {r["init"] for r in clustering["latent"]} >= {"zero", "projection"}


@pytest.mark.slow
def test_experiment_all_leaves_out_success_on_data_the_simulator_cannot_judge(tmp_path, run_cli):
    from primspace.cli.experiments import _judgeable_steps
    from primspace.data import import_lasa
    from primspace.experiments.presets import PRESETS
    from primspace.utils.errors import DataError

    lasa = tmp_path / "lasa.h5"
    import_lasa(length=20, shapes=["Angle", "Sine"]).save(lasa)
    exp = ExperimentDir(tmp_path / "out", PRESETS["lasa"], data=lasa, workers=1, progress=False)
    steps = ("intra:run_intra", "success:run_success", "inter:run_inter")
    assert _judgeable_steps(exp, "all", steps) == ("intra:run_intra", "inter:run_inter")
    with pytest.raises(DataError):
        _judgeable_steps(exp, "success", steps)
    res = run_cli("experiment", "success", "--preset", "lasa", "--data", lasa, "--out", tmp_path / "out2")
    assert res.code == 2 and "judging needs" in res.err and len(res.err.strip().splitlines()) == 1


@pytest.mark.slow
def test_calibrated_points_infer_with_projections_fit_trained_once(tiny_data, tmp_path, grid_only):
    """The intra grid's calibrated point has no fit of its own: it and the projection point
    share ``projection-q4-s0/fit`` under a lock (two workers: trained once, every epoch logged
    once), and its codes start at that fit's calibration map applied to P m."""
    from primspace.results.calibration import calibration_table, calibration_verdict
    from primspace.results.layout import intra_run_dir
    from primspace.train import load_run

    preset = replace(TINY, inits=("projection", "calibrated"))
    exp = ExperimentDir(tmp_path / "cal", preset, data=tiny_data, workers=2, progress=False)
    intra = run_intra(exp)
    assert intra["failures"] == {}
    by_init = {r["init"]: r for r in intra["runs"]}
    assert not (intra_run_dir(exp.path, "calibrated", 4, 0) / "fit").exists()
    fit_dir = intra_run_dir(exp.path, "projection", 4, 0) / "fit"
    epochs = [json.loads(line)["epoch"] for line in (fit_dir / "metrics.jsonl").read_text().splitlines()]
    assert epochs == [0, 1, 2, 3]
    assert by_init["calibrated"]["fit"] == by_init["projection"]["fit"]
    assert by_init["calibrated"]["calibration"] == by_init["projection"]["calibration"] is not None
    fitted = load_run(fit_dir)
    inferred = load_run(intra_run_dir(exp.path, "calibrated", 4, 0) / "infer")
    data = exp.dataset()
    start = fitted.calibration.transform(
        fitted.initializer.transform(fitted.scaler.transform(data.subset(inferred.indices).motor))
    )
    np.testing.assert_allclose(inferred.initial_latents, start, rtol=1e-5, atol=1e-6)
    columns, rows = calibration_table(intra)
    assert rows[0][0] == 4 and "start calibrated" in columns
    assert calibration_verdict(intra)[0] in (True, False)
    html = build_report(exp.path).read_text()
    assert "Calibrated projection (beyond the paper)" in html


@pytest.mark.slow
def test_inter_calibrated_shares_projections_phase_one(tiny_data, tmp_path):
    from primspace.train import load_run

    preset = replace(TINY, inter_inits=("projection", "calibrated"))
    exp = ExperimentDir(tmp_path / "inter-cal", preset, data=tiny_data, workers=1, progress=False)
    results = run_inter(exp)
    assert results["failures"] == {}
    runs = exp.path / "runs" / "inter"
    assert not (runs / "calibrated-fold0-s0" / "phase1").exists()
    phase1 = load_run(runs / "projection-fold0-s0" / "phase1")
    phase2 = load_run(runs / "calibrated-fold0-s0" / "phase2")
    assert phase2.init == "calibrated" and phase2.parent == str((runs / "projection-fold0-s0" / "phase1").resolve())
    data = exp.dataset()
    new = phase2.indices[data.labels[phase2.indices] == 0]
    start = phase1.calibration.transform(phase1.initializer.transform(phase1.scaler.transform(data.subset(new).motor)))
    np.testing.assert_allclose(phase2.initial_latents[: len(new)], start, rtol=1e-5, atol=1e-6)


@pytest.mark.slow
def test_an_experiment_directory_takes_more_inits_but_not_fewer(finished, tmp_path, grid_only):
    """A directory of an older version (four inits) gains calibrated runs beside its own;
    dropping an init or changing any other setting is still refused."""
    import shutil

    from primspace.utils.errors import UserError

    shutil.copytree(finished[0].path, tmp_path / "grow", symlinks=True)  # the tiny grid, run
    exp = ExperimentDir(tmp_path / "grow", TINY, workers=1, progress=False)
    exp.save_meta()
    more = replace(TINY, inits=("zero", "projection", "calibrated"))
    grown = ExperimentDir(exp.path, more, workers=1, progress=False)
    intra = run_intra(grown)
    assert sorted(r["init"] for r in intra["runs"]) == ["calibrated", "projection", "zero"]
    assert json.loads((exp.path / "experiment.json").read_text())["preset_config"]["inits"] == list(more.inits)
    with pytest.raises(UserError, match="made with other settings"):
        ExperimentDir(exp.path, replace(TINY, inits=("zero",)))
    with pytest.raises(UserError, match="made with other settings"):
        ExperimentDir(exp.path, replace(more, fit_epochs=4))


@pytest.mark.slow
def test_predict_grid_compares_starts_and_peers_over_fractions(finished):
    """`experiment predict`: every start and peer at every fraction, judged on simulator data, resumable."""
    from primspace.experiments.prediction import PEERS, PREDICT_VERSION, run_predict
    from primspace.predict.grid import PRIOR_ROWS
    from test_predict_pinned import CHEAP_PEERS, CHEAP_PRIORS  # the priors' and tuned peers' rows small and fast

    exp = finished[0]
    args = dict(
        fractions=(0.25, 0.5),
        starts=("zero", "mixture"),
        epochs=2,
        prior_settings=CHEAP_PRIORS,
        peer_settings=CHEAP_PEERS,
    )
    results = run_predict(exp, **args)
    table = results["table"]
    assert set(table) == {
        "zero",
        "mixture",
        "mixture (posterior mean)",
        "mixture (no continuity)",
        "mixture (labels; diagnostic)",
        *PEERS,
        *PRIOR_ROWS,
    }
    assert (
        0 <= table["prior (posterior)"]["0.5"]["accuracy"][0] <= 1 and "accuracy" not in table["prior (labels)"]["0.5"]
    )
    for method, cells in table.items():
        assert set(cells) >= {"0.25", "0.5"}, method
        assert all(np.isfinite(cells[k]["mse"][0]) and cells[k]["mse"][2] == 1 for k in ("0.25", "0.5"))
    assert results["judged"] and "1" in table["mixture"] and 0 <= table["mixture"]["1"]["success"][0] <= 1
    assert table["mean motion (labels)"]["0.5"]["mse"][0] > 0
    assert_figure(exp.figure("predict_errors"))
    assert "Predicting the rest of a motion" in build_report(exp.path).read_text()
    assert run_predict(exp, **args)["table"] == table
    points = list((exp.path / "runs" / f"predict{PREDICT_VERSION}").iterdir())
    assert points and all(p.name.endswith("-e2") for p in points)  # other epochs than the grid's: other points


@pytest.mark.slow
def test_clustering_again_after_rescaling_the_codes(finished):
    # issue 42: is the gap between inits a matter of the codes' scale? every run, both rescalings
    from primspace.experiments.clustering import RESCALINGS, rescale

    _, intra, clustering, _ = finished
    rows = clustering["rescaled"]
    assert {(r["init"], r["rescaling"]) for r in rows} == {(r["init"], h) for r in intra["runs"] for h in RESCALINGS}
    assert all(0 <= r["accuracy"] <= 1 and r["rms"] > 0 for r in rows)
    z = np.random.default_rng(0).normal(size=(50, 4)) * [1, 10, 100, 1000] + 7
    common, standard = (rescale(z, how) for how in RESCALINGS)
    assert np.isclose(np.sqrt((common**2).sum(axis=1).mean()), 1.0) and np.allclose(
        common * 1e3, rescale(z * 1e3, RESCALINGS[0]) * 1e3
    )
    assert np.allclose(standard.std(axis=0), 1.0) and np.allclose(standard.mean(axis=0), 0.0)
