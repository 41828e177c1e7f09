"""Tau without labels: ``LowRankSubspaceClustering(r2_target="auto")`` and ``--r2 auto``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.cluster import (
    R2_GRID,
    LowRankSubspaceClustering,
    cluster_points,
    clustering_scores,
    sweep,
)
from primspace.cluster.auto import (
    AUTO_CRITERIA,
    AUTO_R2_GRID,
    choose_tau,
    eigengap_score,
    stability_score,
    top_eigenvalues,
)
from primspace.utils.errors import UserError


def planted(noise, seed=0, k=4, n_per=40, dim=2, ambient=40, offset_scale=0.3):
    """``k`` random affine ``dim``-subspaces of R^ambient (offsets ~ N(0, offset_scale^2 I)),
    ``n_per`` points on each, isotropic Gaussian noise; rows = points, labels."""
    rng = np.random.default_rng(seed)
    xs = []
    for _ in range(k):
        basis = np.linalg.qr(rng.standard_normal((ambient, dim)))[0]
        xs.append(offset_scale * rng.standard_normal(ambient) + rng.standard_normal((n_per, dim)) @ basis.T)
    x = np.vstack(xs) + noise * rng.standard_normal((k * n_per, ambient))
    return x, np.repeat(np.arange(k), n_per)


def accuracy(y, labels):
    return clustering_scores(y, labels)["accuracy"]


@pytest.mark.parametrize("criterion", AUTO_CRITERIA)
@pytest.mark.parametrize("noise", [0.05, 0.2, 0.3, 0.5])
@pytest.mark.slow
def test_auto_recovers_planted_affine_subspaces(noise, criterion):
    """At every noise level auto reaches (nearly) the oracle's accuracy over the grid; where
    the noise is large the fixed 0.99 keeps noise directions and fails, auto does not."""
    X, y = planted(noise)
    model = LowRankSubspaceClustering(4, r2_target="auto", auto_criterion=criterion, random_state=0).fit(X)
    oracle = max(r["accuracy"] for r in sweep(X, 4, labels_true=y, random_state=0))
    default = accuracy(y, LowRankSubspaceClustering(4, r2_target=0.99, random_state=0).fit(X).labels_)
    got = accuracy(y, model.labels_)
    assert got >= 0.9 and got >= oracle - 0.02, (got, oracle)
    if noise >= 0.3:
        assert default < 0.8 and got - default > 0.15, (got, default)


def test_auto_records_candidates_and_matches_the_fixed_fit():
    X, _ = planted(0.3)
    model = LowRankSubspaceClustering(4, r2_target="auto", random_state=0).fit(X)
    choice = model.auto_choice_
    assert choice.criterion == "relative_eigengap" and choice.grid == AUTO_R2_GRID == R2_GRID
    assert model.auto_scores_ is choice.scores and model.auto_scores_.shape == (len(R2_GRID),)
    assert choice.index == int(np.nanargmax(choice.scores))
    assert model.tau_ == choice.tau and model.r2_ == pytest.approx(choice.r2[choice.index])
    assert model.r2_ >= choice.r2_target - 1e-9
    # the chosen tau gives exactly the fit at that fixed target
    fixed = LowRankSubspaceClustering(4, r2_target=choice.r2_target, random_state=0).fit(X)
    np.testing.assert_array_equal(model.labels_, fixed.labels_)
    assert fixed.auto_choice_ is None and fixed.auto_scores_ is None
    # every score is the criterion at that candidate
    svd = model.decompose(X)
    seed = int(np.random.RandomState(0).randint(np.iinfo(np.int32).max))
    for tau, score in zip(choice.taus, choice.scores):
        assert score == pytest.approx(eigengap_score(svd, tau, 4, random_state=seed, relative=True), abs=1e-9)
    assert 0 <= np.nanmin(choice.scores) and np.nanmax(choice.scores) <= 1 + 1e-9


@pytest.mark.parametrize("criterion", AUTO_CRITERIA)
@pytest.mark.slow
def test_auto_is_deterministic(criterion):
    X, _ = planted(0.3, seed=1)
    fits = [
        LowRankSubspaceClustering(4, r2_target="auto", auto_criterion=criterion, random_state=3).fit(X)
        for _ in range(2)
    ]
    np.testing.assert_array_equal(fits[0].labels_, fits[1].labels_)
    np.testing.assert_array_equal(fits[0].auto_scores_, fits[1].auto_scores_)
    assert fits[0].tau_ == fits[1].tau_


def test_criteria_scores_on_separated_subspaces():
    """Perfectly separated clusters: stability 1; eigengap in (0, 1]; NaN for Q* = 0."""
    X, _ = planted(0.0, k=3, dim=1, ambient=12)
    model = LowRankSubspaceClustering(3)
    svd = model.decompose(X)
    tau = svd.tau_for_r2(0.99)
    assert stability_score(svd, tau, 3, random_state=0) == pytest.approx(1.0)
    assert 0 < eigengap_score(svd, tau, 3, random_state=0) <= 1 + 1e-9
    choice = choose_tau(svd, 3, grid=(0.9, 0.99), random_state=0)
    assert choice.scores.shape == (2,) and np.all(np.isfinite(choice.scores))


def test_relative_eigengap_vanishes_where_q_tends_to_the_identity():
    """Fewer points than dimensions: at R^2 -> 1, Q* -> I and every eigenvalue of M -> 1, which
    lambda_k alone would score best; the relative gap scores it below a low target and the
    auto choice stays low."""
    X, y = planted(0.3, n_per=10, ambient=60)
    svd = LowRankSubspaceClustering(4).decompose(X)
    values = top_eigenvalues(svd, svd.tau_for_r2(0.9999), 5)
    assert np.all(values > 0.99)
    scores = [eigengap_score(svd, svd.tau_for_r2(g), 4, random_state=0, relative=True) for g in (0.7, 0.9999)]
    assert scores[0] > scores[1], scores
    model = LowRankSubspaceClustering(4, r2_target="auto", random_state=0).fit(X)
    assert model.auto_choice_.r2_target < 0.99 and accuracy(y, model.labels_) >= 0.9


def test_stability_scores_a_degenerate_labelling_zero(monkeypatch):
    """Labels of all points with fewer than k values are perfectly stable and useless: 0."""
    from primspace.cluster import auto

    X, _ = planted(0.3)
    svd = LowRankSubspaceClustering(4).decompose(X)
    assert stability_score(svd, svd.tau_for_r2(0.9), 4, random_state=0) > 0.5
    monkeypatch.setattr(auto, "_labels", lambda factor, *args: np.zeros(factor.shape[0], dtype=np.int64))
    assert stability_score(svd, svd.tau_for_r2(0.9), 4, random_state=0) == 0.0


def test_choose_tau_rejects_bad_settings():
    X, _ = planted(0.1)
    svd = LowRankSubspaceClustering(4).decompose(X)
    with pytest.raises(UserError, match="criterion"):
        choose_tau(svd, 4, criterion="silhouette")
    with pytest.raises(UserError, match="R\\^2 targets"):
        choose_tau(svd, 4, grid=(0.5, 1.5))
    with pytest.raises(ValueError, match="r2_target"):
        LowRankSubspaceClustering(4, r2_target="best").fit(X)
    with pytest.raises(ValueError, match="auto_criterion"):
        LowRankSubspaceClustering(4, r2_target="auto", auto_criterion="x").fit(X)


def test_pipeline_records_the_auto_choice():
    X, y = planted(0.3)
    result = cluster_points(X, LowRankSubspaceClustering(4, r2_target="auto", random_state=0), labels_true=y)
    record = result.to_dict()
    assert record["tau_option"] == {"r2_target": "auto"}
    assert record["auto"]["criterion"] == "relative_eigengap" and record["auto"]["grid"] == list(R2_GRID)
    assert record["auto"]["r2_target"] in R2_GRID and len(record["auto"]["scores"]) == len(R2_GRID)
    assert result.summary()["auto_criterion"] == "relative_eigengap"
    fixed = cluster_points(X, LowRankSubspaceClustering(4, random_state=0), labels_true=y)
    assert "auto" not in fixed.to_dict() and "auto_criterion" not in fixed.summary()


@pytest.fixture
def noisy_latents(tmp_path):
    X, y = planted(0.3)
    np.save(tmp_path / "z.npy", X)
    np.save(tmp_path / "y.npy", y)
    return tmp_path / "z.npy", tmp_path / "y.npy"


@pytest.mark.slow
def test_cli_r2_auto(run_cli, noisy_latents, tmp_path):
    z, y = noisy_latents
    res = run_cli("cluster", z, "--k", 4, "--labels", y, "--r2", "auto", "--out", tmp_path / "a")
    assert res.code == 0, res.err
    assert "tau chosen without labels by relative_eigengap: R^2 target" in res.out
    record = json.loads((tmp_path / "a" / "result.json").read_text())
    assert record["tau_option"] == {"r2_target": "auto"} and record["auto"]["criterion"] == "relative_eigengap"
    assert record["scores"]["accuracy"] >= 0.95
    res = run_cli(
        "cluster", z, "--k", 4, "--r2", "AUTO", "--auto-criterion", "stability", "--json", "--out", tmp_path / "b"
    )
    assert res.code == 0, res.err
    assert json.loads(res.out)["auto"]["criterion"] == "stability"


@pytest.mark.parametrize(
    "value, fragment",
    [
        ("abc", "--r2 must be a number in (0, 1), 'auto' or 'select'"),
        ("1.5", "--r2 must lie in (0, 1)"),
        ("nan", "--r2 must lie in (0, 1)"),
        ("0", "--r2 must lie in (0, 1)"),
    ],
)
def test_cli_bad_r2_is_one_line(run_cli, noisy_latents, tmp_path, value, fragment):
    z, _ = noisy_latents
    assert_user_error(run_cli("cluster", z, "--k", 4, "--r2", value, "--out", tmp_path / "o"), fragment)


def test_cli_auto_with_another_tau_option(run_cli, noisy_latents, tmp_path):
    z, _ = noisy_latents
    assert_user_error(
        run_cli("cluster", z, "--k", 4, "--r2", "auto", "--tau", "1", "--out", tmp_path / "o"), "at most one of"
    )
