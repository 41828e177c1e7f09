"""The scene only (issue 25, item 4): the first frame and joints, the primitive named as a
cluster of the fitted codes, the code searched in its affine subspace (``predict_scene``,
``ScenePredictor``: Python only). Since issue 40 `primspace predict --scene` runs the scene
policy (tests/test_predict_scene_policy.py); the command's checks before it predicts are here."""

import json

import numpy as np
import pytest

from primspace.data import MotionDataset
from primspace.utils.errors import UserError
from primspace.predict.scene import affine_subspace, cluster_codes, predict_scene, run_scene_point, scene_clusters
from primspace.train import TrainConfig, fit
from conftest import assert_user_error
from test_train import SMALL

FAST = dict(batch_size=12, threads=1)
# the small image run of the observation tests, shared (pytest registers the imported fixtures here)
from test_observe import image_run, image_set  # noqa: E402, F401


@pytest.fixture(scope="module")
def clusters(image_run, image_set):
    return scene_clusters(image_run, fitted_data=image_set)


def _off_subspace(codes, mean, basis) -> float:
    """The largest distance of ``codes`` from the affine subspace ``mean + span(basis)``."""
    centred = np.asarray(codes, dtype=np.float64) - mean
    return float(np.linalg.norm(centred - centred @ basis.T @ basis, axis=1).max())


def test_the_clusters_are_numbered_by_first_member_and_counted_from_the_labels(clusters, image_set):
    assert clusters.n_clusters == len(np.unique(image_set.labels)) == 3  # the count of labels, by default
    assert sum(clusters.sizes) == len(image_set) and min(clusters.sizes) >= 1
    firsts = clusters.summary()["first_members"]
    assert firsts[0] == 0 and firsts == sorted(firsts) and clusters.labels[0] == 0
    for k, name in enumerate(clusters.names):  # the majority label's name, for display
        own = image_set.labels[clusters.labels == k]
        assert name == image_set.label_names[np.bincount(own).argmax()]


def test_the_scene_code_lies_in_the_chosen_clusters_subspace(image_run, image_set, clusters):
    k = int(np.argmax(clusters.sizes))
    p = predict_scene(image_run, image_set, k, clusters=clusters, rank=1, epochs=4)
    mean, basis = clusters.subspace(k, rank=1)
    assert basis.shape == (1, SMALL.latent_dim)
    assert _off_subspace(p.codes, mean, basis) < 1e-5 * (1 + np.abs(mean).max())
    assert np.abs(p.codes - mean).max() > 1e-4  # the coordinates moved from the cluster mean
    assert p.init == "scene" and p.observation == {"motor": 1, "frames": "first"}
    assert p.motor_observed.sum(axis=1).tolist() == [1] * len(image_set)
    assert p.details["mode"] == "scene" and p.details["scene"]["rank"] == 1 and p.details["scene"]["primitive"] == k
    assert np.isfinite(p.errors["motor_mse"]).all() and (p.errors["vision_mse"] > 0).all()
    again = predict_scene(image_run, image_set, k, clusters=clusters, rank=1, epochs=4)
    assert np.array_equal(again.codes, p.codes)  # seeded, CPU: the same call gives the same codes


def test_changing_the_primitive_changes_the_motion(image_run, image_set, clusters):
    a = predict_scene(image_run, image_set, 0, clusters=clusters, epochs=5, indices=[0, 4])
    b = predict_scene(image_run, image_set, 2, clusters=clusters, epochs=5, indices=[0, 4])
    for p, k in ((a, 0), (b, 2)):
        mean, basis = clusters.subspace(k)
        assert _off_subspace(p.codes, mean, basis) < 1e-5 * (1 + np.abs(mean).max())
    gap = np.abs(a.motor - b.motor).max()
    assert gap > 0.05 * np.ptp(image_set.motor), gap


def test_the_subspace_rank_follows_the_variance_or_is_given():
    rng = np.random.default_rng(0)
    line = np.outer(rng.normal(size=20), [1.0, 2.0, -1.0, 0.5]) + 1e-3 * rng.normal(size=(20, 4)) + 3.0
    mean, basis = affine_subspace(line)
    assert basis.shape == (1, 4) and np.allclose(mean, line.mean(axis=0))
    assert abs(abs(basis[0] @ np.array([1.0, 2.0, -1.0, 0.5])) / np.linalg.norm([1.0, 2.0, -1.0, 0.5]) - 1) < 1e-4
    assert affine_subspace(line, rank=3)[1].shape == (3, 4)
    assert affine_subspace(line[:1])[1].shape == (0, 4)  # one code: the mean only
    with pytest.raises(UserError, match=r"spans 0\.\.4 directions"):
        affine_subspace(line, rank=5)


def test_bad_scene_requests_are_refused_in_one_line(image_run, image_set, clusters):
    with pytest.raises(UserError, match=r"primitive 3 is out of range: .* 3 clusters, choose 0\.\.2$"):
        predict_scene(image_run, image_set, 3, clusters=clusters, epochs=1)
    with pytest.raises(UserError, match="out of range"):
        predict_scene(image_run, image_set, -1, clusters=clusters, epochs=1)
    with pytest.raises(UserError, match="the data set has no frames"):
        predict_scene(image_run, image_set.without_images(), 0, clusters=clusters, epochs=1)
    no_head = fit(
        image_set, model_config=SMALL, train_config=TrainConfig(epochs=1, **FAST), images=False, progress=False
    )
    with pytest.raises(UserError, match="needs a run with an image head"):
        predict_scene(no_head, image_set, 0, n_clusters=3, epochs=1)
    with pytest.raises(UserError, match="give the number of clusters"):
        scene_clusters(image_run)  # in memory: no data file to count labels in
    with pytest.raises(UserError, match=r"1\.\.9"):
        scene_clusters(image_run, 10)
    other = cluster_codes(np.random.default_rng(0).normal(size=(9, SMALL.latent_dim)), 3)
    with pytest.raises(UserError, match="not of this run"):
        predict_scene(image_run, image_set, 0, clusters=other, epochs=1)


def test_run_scene_point_asks_each_sample_for_its_labels_cluster(image_run, image_set):
    out = run_scene_point(image_run, image_set, image_set, epochs=2)
    majority = out["clusters"]["cluster_names"]
    assert out["scaled"].shape == image_set.motor.shape and np.isfinite(out["mse"]).all()
    for i, k in enumerate(out["cluster"]):
        assert k >= 0
        if image_set.label_names[image_set.labels[i]] in majority:  # a cluster of its majority exists: that one
            assert majority[k] == image_set.label_names[image_set.labels[i]]
    assert set(out["clusters"]["ranks"]) == set(int(k) for k in np.unique(out["cluster"]))
    with pytest.raises(UserError, match="need labels"):
        run_scene_point(image_run, MotionDataset(image_set.motor, images=image_set.images), image_set, epochs=1)


# ------------------------------------------------------------------ the command


@pytest.fixture(scope="module")
def scene_files(image_set, tmp_path_factory):
    root = tmp_path_factory.mktemp("scene")
    image_set.save(root / "data.h5")
    data = MotionDataset.load(root / "data.h5")
    fit(data, root / "run", model_config=SMALL, train_config=TrainConfig(epochs=2, **FAST), progress=False)
    image_set.without_images().save(root / "no_frames.h5")
    return root


def test_predict_scene_command_runs_the_scene_policy_not_the_subspace_search(run_cli, scene_files, tmp_path):
    """Issue 40: the subspace search (``predict_scene``) is no longer behind the command."""
    out = tmp_path / "scene"
    res = run_cli("predict", scene_files / "run", scene_files / "data.h5", "--scene", "--primitive", "1", "--out", out)
    assert res.code == 0, res.err
    assert "subspace rank" not in res.out
    result = json.loads((out / "result.json").read_text())
    assert result["mode"] == result["init"] == "scene policy" and "scene" not in result
    assert result["primitive"] == 1 and result["command"]["scene"] is True


@pytest.mark.parametrize(
    "run_name, data_name, flags, match",
    [
        ("run", "data.h5", ["--primitive", "3"], "primitive 3 is out of range"),
        ("run", "no_frames.h5", ["--primitive", "0"], "has no frames"),
        ("run", "data.h5", ["--primitive", "0", "--observe", "0.5"], "do not give --observe"),
        ("run", "data.h5", ["--primitive", "0", "--init", "zero"], "do not give --init"),
        ("run", "data.h5", [], "--scene needs --primitive"),
    ],
)
def test_predict_scene_command_refuses_with_exit_2(run_cli, scene_files, tmp_path, run_name, data_name, flags, match):
    out = tmp_path / "o"
    res = run_cli(
        "predict", scene_files / run_name, scene_files / data_name, "--scene", "--epochs", "1", *flags, "--out", out
    )
    assert_user_error(res, match)
    assert not out.exists()


def test_primitive_without_scene_is_the_priors_and_refused_with_another_predictor(run_cli, scene_files, tmp_path):
    """Issue 39: without --scene, --primitive asks the prior predictor (tests/test_predict_primitive.py)."""
    args = ("predict", scene_files / "run", scene_files / "data.h5", "--primitive", "0", "--init", "zero")
    assert_user_error(run_cli(*args, "--out", tmp_path / "o"), "only the prior predictor takes --primitive")
    assert not (tmp_path / "o").exists()


def test_a_primitive_is_asked_for_by_its_label_name(image_run, image_set, clusters):
    """Issue 37: `--primitive push` performs the cluster mostly of label 'push' (clusters are
    numbered by first member, not by label), and a name no cluster holds is refused in one line."""
    for name in {n for n in clusters.names if n is not None}:
        k = clusters.check(name)
        assert clusters.names[k] == name
        assert clusters.sizes[k] == max(s for s, n in zip(clusters.sizes, clusters.names) if n == name)
    assert clusters.check(1) == 1
    if "7" not in clusters.names:
        with pytest.raises(UserError, match="choose 0..2"):
            clusters.check("7")  # digits that name no cluster: a cluster id
    with pytest.raises(UserError, match="no cluster of the fitted codes is mostly 'wave'"):
        clusters.check("wave")


def test_the_scene_predictor_is_the_scene_mode_with_the_predictor_interface(image_run, image_set, clusters):
    from primspace.predict.scene import ScenePredictor

    predictor = ScenePredictor(image_run, label_names=image_set.label_names, rank=1, epochs=3)
    predictor.fit(None, image_set.labels)
    assert predictor.needs_labels and np.array_equal(predictor.clusters_.labels, clusters.labels)
    k = int(np.argmax(clusters.sizes))
    scaled = image_run.scaler.transform(image_set.motor)
    forecast = predictor.forecast(scaled, None, [k] * len(image_set), image_set.lengths, image_set.images)
    direct = predict_scene(image_run, image_set, k, clusters=clusters, rank=1, epochs=3, frames=False)
    np.testing.assert_allclose(forecast.codes, direct.codes, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(forecast.motor, image_run.scaler.transform(direct.motor), rtol=1e-4, atol=1e-5)
    by_name = predictor.forecast(
        scaled, None, [clusters.names[k]] * len(image_set), image_set.lengths, image_set.images
    )
    np.testing.assert_array_equal(by_name.codes, forecast.codes)
