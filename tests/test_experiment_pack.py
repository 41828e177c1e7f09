"""``primspace experiment ... --pack N``: the intra grid's unfinished runs trained packed
(primspace.train.packed) before the grid, which then finds them finished: the same results
within float tolerance, nothing trained again, a failed pack left to the grid."""

import json
from dataclasses import replace

import pytest

from conftest import assert_user_error
from primspace.experiments import figures, intra
from primspace.experiments.intra import run_intra, split_indices
from primspace.experiments.presets import ExperimentPreset, default_train
from primspace.experiments.runs import fit_and_infer, load_run_data, pack_grid_runs
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import intra_run_dir, phase_dir
from primspace.train import load_run

#: 14 motions, 7 fitted and 7 inferred per seed; calibrated infers with projection's fit (shared).
TINY = ExperimentPreset(
    name="tiny-pack",
    data_preset="demo",
    train_fraction=0.5,
    inits=("zero", "projection", "calibrated"),
    latent_dims=(4,),
    seeds=(0, 1),
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


def _points(exp: ExperimentDir, preset: ExperimentPreset) -> list[tuple]:
    """The intra grid points of ``preset`` as pack_grid_runs takes them."""
    labels = exp.dataset().labels
    points = []
    for seed in preset.seeds:
        train, evaluation = split_indices(labels, preset.train_fraction, seed)
        for q in preset.latent_dims:
            for init in preset.inits:
                points.append((intra_run_dir(exp.path, init, q, seed), init, q, seed, train, evaluation))
    return points


def _files(exp: ExperimentDir) -> dict:
    """Every file under OUT/runs with its modification time."""
    return {p: p.stat().st_mtime_ns for p in sorted((exp.path / "runs").rglob("*")) if p.is_file()}


def test_pack_zero_is_refused(run_cli, tmp_path):
    assert_user_error(run_cli("experiment", "intra", "--out", tmp_path / "e", "--pack", "0"), "--pack 0")
    assert not (tmp_path / "e").exists()


@pytest.mark.slow
def test_a_packed_grid_gives_the_results_of_each_run_alone(tiny_data, tmp_path):
    import primspace.train.packed as packed

    sizes = []
    train_packed = packed.train_packed

    def spy(prepared, progress=None, label="fit"):
        sizes.append((label, len(prepared)))
        return train_packed(prepared, progress, label)

    results = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(packed, "train_packed", spy)
        for name in ("draw_intra",):  # figures and animations: not what this test is about (seconds)
            mp.setattr(figures, name, lambda *a, **k: None)
        mp.setattr(intra, "write_animations", lambda *a, **k: None)
        for pack in (2, 1):
            exp = ExperimentDir(tmp_path / f"pack{pack}", TINY, data=tiny_data, workers=1, progress=False, pack=pack)
            run_intra(exp)
            results[pack] = json.loads(exp.results_file("intra").read_text())
    # four fits (calibrated's is projection's) in two packs, six inferences in three
    assert sizes == [("fit", 2)] * 2 + [("infer", 2)] * 3
    packed_runs, alone = ({r["key"]: r for r in results[p]["runs"]} for p in (2, 1))
    assert results[2]["failures"] == {} and sorted(packed_runs) == sorted(alone) and len(alone) == 6
    for key, run in packed_runs.items():
        for phase in ("fit", "infer"):
            assert [h["epoch"] for h in run[phase]] == [h["epoch"] for h in alone[key][phase]]
            assert run[phase][-1]["loss"] == pytest.approx(alone[key][phase][-1]["loss"], rel=1e-4), (key, phase)
            assert run[phase][-1]["loss"] != alone[key][phase][0]["loss"]  # trained
            epochs = TINY.fit_epochs if phase == "fit" else TINY.infer_epochs
            assert load_run(phase_dir(tmp_path / "pack2", run["init"], 4, run["seed"], phase)).epoch == epochs


def test_packing_trains_nothing_that_is_finished(tiny_data, tmp_path):
    preset = replace(TINY, inits=("zero", "projection"), seeds=(0,))
    exp = ExperimentDir(tmp_path / "out", preset, data=tiny_data, workers=1, progress=False, pack=2)
    data, use_images = load_run_data(str(exp.data_path), preset)
    points = _points(exp, preset)
    first = pack_grid_runs(points, data, preset, use_images, 2)
    assert len(first["trained"]) == 4 and first["left"] == []
    before = _files(exp)
    assert pack_grid_runs(points, data, preset, use_images, 2) == {"trained": [], "left": []}
    assert _files(exp) == before
    # the grid's run of a point finds both phases finished
    run_dir, init, q, seed, train, evaluation = points[1]
    fitted, inferred, _ = fit_and_infer(run_dir, data, preset, init, q, seed, train, evaluation, use_images)
    assert (fitted.epoch, inferred.epoch) == (preset.fit_epochs, preset.infer_epochs)


def test_a_failed_pack_is_left_to_the_grid(tiny_data, tmp_path, monkeypatch):
    import primspace.train.packed as packed
    from primspace.utils.errors import UserError

    def refuse(prepared, progress=None, label="fit"):
        raise UserError("refused for the test")

    monkeypatch.setattr(packed, "train_packed", refuse)
    preset = replace(TINY, inits=("zero", "projection"), seeds=(0,))
    exp = ExperimentDir(tmp_path / "out", preset, data=tiny_data, workers=1, progress=False, pack=2)
    data, use_images = load_run_data(str(exp.data_path), preset)
    points = _points(exp, preset)
    done = pack_grid_runs(points, data, preset, use_images, 2)
    assert done["trained"] == [] and sorted(done["left"]) == sorted(p[0] / "fit" for p in points)
    # no run keeps its writer's lock: each point trains alone in this process
    for run_dir, init, q, seed, train, evaluation in points:
        fitted, _, _ = fit_and_infer(run_dir, data, preset, init, q, seed, train, evaluation, use_images)
        assert fitted.epoch == preset.fit_epochs
