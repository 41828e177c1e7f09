"""The intra experiment with images (issue 13, item 3): every run's final losses are
recomputed on all frames (motor, vision, PSNR), the report's table carries them, and the
generated-against-recorded frame strips are drawn; runs finished before this existed are
completed once, without retraining."""

import json
from dataclasses import replace

import numpy as np
import pytest

from primspace.data import MotionDataset
from primspace.experiments.intra import run_intra
from primspace.experiments.runs import psnr
from primspace.experiments.workspace import ExperimentDir
from primspace.report import build_report
from primspace.results.layout import intra_run_dir
from primspace.results.tables import final_loss_table
from test_experiments import TINY

TINY_IMAGES = replace(
    TINY, name="tiny-images", fit_epochs=2, infer_epochs=2, images=True, train=replace(TINY.train, vision_frames=3)
)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """14 motions of 31 steps with 48x64 frames; intra with K = 3 frames per step."""
    from primspace.sim.generate import GenerationConfig, generate_dataset

    config = GenerationConfig(block_x=(0.45, 0.55), block_y=(0.0,), block_size=(0.05,), length=31, images=True)
    data = tmp_path_factory.mktemp("data") / "tiny-images.h5"
    generate_dataset(config, seed=0, out=data, progress=False)
    exp = ExperimentDir(tmp_path_factory.mktemp("exp") / "out", TINY_IMAGES, data=data, workers=1, progress=False)
    return exp, run_intra(exp)


@pytest.mark.slow
def test_final_losses_are_the_exact_all_frame_losses(finished):
    from primspace.train import evaluate, load_run

    exp, results = finished
    data = MotionDataset.load(exp.data_path)
    assert len(results["runs"]) == 2
    for r in results["runs"]:
        run_dir = intra_run_dir(exp.path, r["init"], r["latent_dim"], r["seed"])
        for phase in ("fit", "infer"):
            run = load_run(run_dir / phase)
            assert run.train_config.vision_frames == 3
            exact = evaluate(run, data, indices=run.indices)
            got = r["final"][phase]
            assert got["motor"] == pytest.approx(exact["motor"], rel=1e-6)
            assert got["vision"] == pytest.approx(exact["vision"], rel=1e-6)
            assert 0 < got["vision"] < 1
            assert got["psnr"] == pytest.approx(10 * np.log10(1 / got["vision"]))


@pytest.mark.slow
def test_the_loss_table_shows_vision_and_psnr(finished):
    _, results = finished
    columns, rows = final_loss_table(results)
    assert columns[-6:] == [f"{p} {k} (all frames)" for p in ("fit", "eval") for k in ("motor", "vision", "PSNR dB")]
    for row, r in zip(rows, sorted(results["runs"], key=lambda r: r["init"])):
        assert row[-3:] == [r["final"]["infer"]["motor"], r["final"]["infer"]["vision"], r["final"]["infer"]["psnr"]]


@pytest.mark.slow
def test_frame_strips_are_drawn_and_reported(finished):
    from conftest import read_png

    exp, _ = finished
    strips = exp.figure("image_strips")
    # one recorded and one generated row per primitive: 14 rows of frames
    assert read_png(strips).shape[0] > 14 * 40
    html = build_report(exp.path).read_text()
    assert "generated frames under recorded frames" in html
    assert "PSNR dB" in html


@pytest.mark.slow
def test_old_runs_are_completed_once_without_retraining(finished, grid_only):
    exp, results = finished
    key = results["runs"][0]["key"]
    result_file = exp.path / "runs" / key / "result.json"
    stored = json.loads(result_file.read_text())
    expected = stored.pop("final")
    result_file.write_text(json.dumps(stored))  # as primspace 0.3.0 left it
    checkpoints = sorted(exp.path.glob("runs/intra/*/*/checkpoint.pt"))
    before = [p.stat().st_mtime_ns for p in checkpoints]
    again = run_intra(ExperimentDir(exp.path, TINY_IMAGES, data=exp.data_path, progress=False))
    assert [p.stat().st_mtime_ns for p in checkpoints] == before
    assert json.loads(result_file.read_text())["final"] == expected
    assert next(r for r in again["runs"] if r["key"] == key)["final"] == expected


def test_psnr_of_a_known_error():
    assert psnr(0.01) == pytest.approx(20.0)
    assert psnr(None) is None
