"""`primspace cluster`: outputs, scores, sweep, and one-line errors."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from conftest import assert_figure, assert_user_error, figure_stats, read_png
from primspace.data import MotionDataset


def subspace_latents(seed=0, n_per=30, k=3, dim=2, ambient=8, noise=0.01):
    rng = np.random.default_rng(seed)
    xs = []
    for _ in range(k):
        basis = np.linalg.qr(rng.standard_normal((ambient, dim)))[0]
        xs.append(rng.standard_normal(ambient) + rng.standard_normal((n_per, dim)) @ basis.T)
    x = np.vstack(xs) + noise * rng.standard_normal((n_per * k, ambient))
    return x, np.repeat(np.arange(k), n_per)


@pytest.fixture
def latents(tmp_path):
    x, y = subspace_latents()
    np.save(tmp_path / "z.npy", x)
    np.save(tmp_path / "y.npy", y)
    return tmp_path / "z.npy", tmp_path / "y.npy"


@pytest.fixture
def motion_file(tmp_path):
    """Three primitives: each a 2-parameter family of joint trajectories (a 2-D affine
    subspace of trajectory space), two joints on very different physical scales."""
    rng = np.random.default_rng(1)
    t = np.linspace(0, 1, 25)
    motor, labels = [], []
    for k in range(3):
        shapes = [np.sin((k + 1) * np.pi * t), t**2 * (k + 1), np.cos((k + 2) * t)]
        for _ in range(12):
            a, b = rng.uniform(-1, 1, 2)
            j0 = shapes[0] + a * shapes[1] + b * shapes[2]
            j1 = 1000.0 * (shapes[1] - a * shapes[0] + 0.5 * b * t)
            motor.append(np.stack([j0, j1], axis=1))
            labels.append(k)
    labels = np.array(labels)
    labels[[0, 13]] = -1  # unknown
    path = tmp_path / "motion.h5"
    MotionDataset(np.array(motor), labels=labels, label_names=["a", "b", "c"]).save(path)
    return path


@pytest.mark.slow
def test_latents_with_labels(run_cli, latents, tmp_path):
    z, y = latents
    out = tmp_path / "out"
    res = run_cli("cluster", z, "--k", 3, "--labels", y, "--out", out)
    assert res.code == 0, res.err
    assert "accuracy 1.0000" in res.out
    result = json.loads((out / "result.json").read_text())
    assert result["scores"]["accuracy"] == 1.0 and result["n_samples"] == 90
    # the default tau choice: held-out selection, recorded with every candidate's score
    assert result["tau_option"] == {"r2_target": "select"} and "auto" not in result
    chosen = result["selection"]["r2_target"]
    assert result["r2"] == pytest.approx(chosen) and chosen in [
        c["r2_target"] for c in result["selection"]["candidates"]
    ]
    assert "tau chosen by held-out stability: R^2 target" in res.out
    with open(out / "labels.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 90 and set(rows[0]) == {"sample", "predicted", "true"}
    # the affinity matrix (a colour map) and the coloured cluster markers: measured ~100000 chromatic pixels
    assert_figure(out / "clustering.png", width=(800, 2500), min_ink=0.15, min_coloured=30_000)
    assert sorted(p.name for p in out.iterdir()) == ["clustering.png", "labels.csv", "result.json"]


def test_motion_dataset_scales_joints_and_ignores_unknown_labels(run_cli, motion_file, tmp_path):
    out = tmp_path / "out"
    res = run_cli("cluster", motion_file, "--k", 3, "--tau-relative", 1e6, "--out", out, "--json")
    assert res.code == 0, res.err
    result = json.loads(res.out)
    assert result["n_features"] == 50 and "scaled to [-1, 1]" in result["points"]
    assert result["scores"]["n_ignored"] == 2 and result["scores"]["n_scored"] == 34
    assert result["scores"]["accuracy"] == 1.0
    assert result == json.loads((out / "result.json").read_text())


@pytest.mark.slow
def test_sweep_prints_the_table(run_cli, latents, tmp_path):
    z, y = latents
    out = tmp_path / "out"
    res = run_cli("cluster", z, "--k", 3, "--labels", y, "--sweep", "--out", out, "--linear")
    assert res.code == 0, res.err
    assert "tau sweep" in res.out and "R^2" in res.out
    table = [line for line in res.out.splitlines() if line.strip().startswith(("0.5 ", "0.9999"))]
    assert len(table) == 2
    with open(out / "sweep.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["value"]) for r in rows] == [0.5, 0.7, 0.8, 0.85, 0.9, 0.95, 0.99, 0.995, 0.999, 0.9999]
    # R² in black, accuracy / NMI / ARI in tab:blue / tab:green / tab:orange (measured 600-1500 px each)
    assert_figure(out / "sweep.png", colours=("black", "tab:blue", "tab:green", "tab:orange"), min_colour_pixels=250)
    res = run_cli("cluster", z, "--k", 3, "--sweep-taus", "0.01,0.1,1", "--out", out, "--overwrite")
    assert res.code == 0, res.err
    assert len(json.loads((out / "sweep.json").read_text())) == 3


@pytest.mark.slow
def test_existing_output_is_refused_unless_overwrite(run_cli, latents, tmp_path):
    z, _ = latents
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    assert_user_error(run_cli("cluster", z, "--k", 3, "--out", out), "out", "--overwrite")
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    # --overwrite replaces only an earlier cluster output: a folder of other files is refused
    assert_user_error(run_cli("cluster", z, "--k", 3, "--out", out, "--overwrite"), "not a primspace cluster output")
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    fresh = tmp_path / "fresh"
    assert run_cli("cluster", z, "--k", 3, "--out", fresh, "--sweep").code == 0
    (fresh / "notes.txt").write_text("mine")
    res = run_cli("cluster", z, "--k", 2, "--out", fresh, "--overwrite")
    assert res.code == 0, res.err
    assert json.loads((fresh / "result.json").read_text())["n_clusters"] == 2
    # the earlier run's sweep is gone (not asked for now), the user's file stays
    assert sorted(p.name for p in fresh.iterdir()) == ["clustering.png", "labels.csv", "notes.txt", "result.json"]
    assert (fresh / "notes.txt").read_text() == "mine"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp left


def test_cluster_never_deletes_its_input(run_cli, latents, tmp_path):
    """Found: `cluster d/lat.npy --out d --overwrite` deleted lat.npy and every file in d."""
    z, _ = latents
    d = tmp_path / "d"
    d.mkdir()
    lat = d / "lat.npy"
    lat.write_bytes(z.read_bytes())
    (d / "other.txt").write_text("x")
    for out in (d, lat, tmp_path):  # is the input's folder / the input / contains it
        assert_user_error(run_cli("cluster", lat, "--k", 3, "--out", out, "--overwrite"), "input")
    link = tmp_path / "link"
    link.symlink_to(d, target_is_directory=True)
    assert_user_error(run_cli("cluster", lat, "--k", 3, "--out", link, "--overwrite"), "input")
    assert sorted(p.name for p in d.iterdir()) == ["lat.npy", "other.txt"]
    assert lat.read_bytes() == z.read_bytes()


@pytest.mark.parametrize(
    "args, fragments",
    [
        (["--k", "0"], ["--k must be at least 1"]),
        (["--k", "91"], ["--k 91 exceeds the 90 samples"]),
        (["--k", "3", "--tau", "0"], ["--tau must be a positive number"]),
        (["--k", "3", "--tau", "-1"], ["--tau must be a positive number"]),
        (["--k", "3", "--tau-relative", "-1"], ["--tau-relative must be a positive number"]),
        (["--k", "3", "--r2", "1.5"], ["--r2 must lie in (0, 1)"]),
        (["--k", "3", "--tau", "1", "--r2", "0.9"], ["at most one of"]),
        (["--k", "3", "--tau", "1e-12"], ["keeps no component"]),
        (["--k", "3", "--affinity", "abs", "--spectral", "implicit"], ["affinity='squared'"]),
        (["--k", "3", "--sweep-taus", "a,b"], ["--sweep-taus"]),
    ],
)
def test_bad_options_are_one_line(run_cli, latents, tmp_path, args, fragments):
    z, _ = latents
    out = tmp_path / "out"
    assert_user_error(run_cli("cluster", z, *args, "--out", out), *fragments)
    assert not out.exists()


def test_bad_data_is_one_line_naming_the_file(run_cli, tmp_path):
    x, y = subspace_latents()
    x[7, 2] = np.nan
    np.save(tmp_path / "nan.npy", x)
    assert_user_error(
        run_cli("cluster", tmp_path / "nan.npy", "--k", 3, "--out", tmp_path / "o"), "nan.npy", "NaN or inf", "sample 7"
    )
    x[7, 2] = np.inf
    np.save(tmp_path / "inf.npy", x)
    assert_user_error(
        run_cli("cluster", tmp_path / "inf.npy", "--k", 3, "--out", tmp_path / "o"), "inf.npy", "NaN or inf"
    )
    np.save(tmp_path / "flat.npy", np.arange(10.0))
    assert_user_error(run_cli("cluster", tmp_path / "flat.npy", "--k", 2, "--out", tmp_path / "o"), "flat.npy", "2-D")
    np.save(tmp_path / "ok.npy", subspace_latents()[0])
    np.save(tmp_path / "short.npy", y[:5])
    assert_user_error(
        run_cli("cluster", tmp_path / "ok.npy", "--k", 3, "--labels", tmp_path / "short.npy", "--out", tmp_path / "o"),
        "short.npy",
        "labels",
        "(90,)",
    )
    assert_user_error(
        run_cli("cluster", tmp_path / "missing.npy", "--k", 3, "--out", tmp_path / "o"), "missing.npy", "no such file"
    )
    (tmp_path / "z.txt").write_text("1 2")
    assert_user_error(run_cli("cluster", tmp_path / "z.txt", "--k", 3, "--out", tmp_path / "o"), "z.txt", ".npy")
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_figures_handle_unknown_labels_extra_clusters_and_empty_sweeps(tmp_path):
    from primspace.plots import plot_clustering, plot_tau_sweep, save_figure

    rng = np.random.default_rng(2)
    w = rng.random((12, 12))
    w = w + w.T
    true = np.array([0, 0, 0, 1, 1, 1, 2, 2, -1, -1, 2, 1])
    pred = np.array([3, 3, 3, 0, 0, 1, 2, 2, 2, 0, 4, 0])  # 5 predicted clusters for 3 true ones
    fig = plot_clustering(w, pred, true, label_names=["a", "b", "c"], title="t")
    left, right = fig.axes[0], fig.axes[1]
    assert left.images[0].get_array().shape == (12, 12)
    shown = np.concatenate([c.get_offsets()[:, 1] for c in right.collections])
    assert sorted(set(shown)) == [0, 1, 2, 3, 4]  # matched ids 0-2, unmatched ones above
    save_figure(fig, tmp_path / "c.png")
    # the 12 x 12 affinity image and the markers of all 5 predicted clusters: measured ~180000 chromatic pixels
    assert_figure(tmp_path / "c.png", width=(800, 2500), min_ink=0.15, min_coloured=50_000)
    fig = plot_tau_sweep([{"tau": None, "rank": 0}, {"tau": 0.1, "r2": 0.9, "rank": 3, "accuracy": 0.8}])
    assert len(fig.axes) == 2 and len(fig.axes[0].lines) == 1
    save_figure(plot_tau_sweep([]), tmp_path / "empty.png")
    # an empty sweep still makes a readable figure: its message and axes, and no data drawn
    empty = figure_stats(read_png(tmp_path / "empty.png"))
    assert empty["coloured"] == 0 and empty["ink"] > 0.01, empty
