"""Affine low-rank subspace clustering: algebra, spectral routes, estimator, metrics, sweep."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.utils.estimator_checks import parametrize_with_checks

from primspace.cluster import (
    LowRankSubspaceClustering,
    NormalizedAffinityOperator,
    affinity_from_factor,
    clustering_accuracy,
    clustering_scores,
    degrees_from_factor,
    njw_labels,
    r2_from_singular_values,
    self_representation_svd,
    shrinkage,
    spectral_embedding,
    sweep,
    tau_for_r2,
)
from primspace.cluster import lrsc as lrsc_module
from primspace.cluster import spectral as spectral_module
from primspace.utils.errors import UserError


def union_of_subspaces(n_per, dims, ambient, *, affine=True, noise=0.0, seed=0, offset_scale=1.0):
    """Points on K random affine (or linear) subspaces; returns X (rows = points), labels."""
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for k, (n, dim) in enumerate(zip(n_per, dims)):
        basis = np.linalg.qr(rng.standard_normal((ambient, dim)))[0]
        offset = offset_scale * rng.standard_normal(ambient) if affine else 0.0
        xs.append(offset + rng.standard_normal((n, dim)) @ basis.T)
        ys.append(np.full(n, k))
    x = np.vstack(xs)
    x += noise * rng.standard_normal(x.shape)
    perm = rng.permutation(x.shape[0])
    return x[perm], np.concatenate(ys)[perm]


def explicit_r2(X, q):
    """R^2 of Z ~ Z Q* computed from the n x n matrix (Z = X^T, centred denominator)."""
    z = X.T
    residual = z - z @ q
    centred = z - z.mean(axis=1, keepdims=True)
    return 1.0 - np.sum(residual**2) / np.sum(centred**2)


# ---------------------------------------------------------------------------- algebra


def test_shrinkage_is_the_papers_p():
    lam = np.array([10.0, 2.0, 1.0, 0.5, 0.0])
    tau = 1.0
    expected = [1 - 1 / 100, 1 - 1 / 4, 0.0, 0.0, 0.0]  # x = 1/sqrt(tau) is not kept
    np.testing.assert_allclose(shrinkage(lam, tau), expected)


@pytest.mark.parametrize("affine", [True, False])
def test_singular_value_r2_equals_explicit_r2(affine):
    X, _ = union_of_subspaces([30, 30, 30], [2, 3, 2], 12, affine=affine, noise=0.05, seed=1)
    X = X + 3.0  # a mean far from 0: the centred and uncentred definitions differ a lot
    svd = self_representation_svd(X, affine=affine, ones_weight=1.7)
    for tau_relative in (3.0, 30.0, 1e3, 1e6):
        tau = svd.tau_from_relative(tau_relative)
        q = svd.self_representation(tau)
        assert svd.r2(tau) == pytest.approx(explicit_r2(X, q), abs=1e-10)
    # the plain function on the matrix itself: R^2 relative to ||Z~||^2
    lam = svd.singular_values
    tau = svd.tau_from_relative(30.0)
    z = np.hstack([X, np.full((X.shape[0], 1), 1.7)]).T if affine else X.T
    q = svd.self_representation(tau)
    assert r2_from_singular_values(lam, tau) == pytest.approx(1 - np.sum((z - z @ q) ** 2) / np.sum(z**2), abs=1e-10)


def test_self_representation_is_the_closed_form_minimiser():
    """Q* = V P(Lambda) V^T minimises ||C||_* + (tau/2)||Z - ZC||_F^2 over symmetric C: the
    objective of Vidal & Favaro whose minimiser the paper's P(x) is (the paper's eq.
    relaxed_optim prints the weight as 1/tau, which would give P(x) = 1 - tau/(2 x^2))."""
    X, _ = union_of_subspaces([8, 8], [2, 2], 6, noise=0.1, seed=2)
    svd = self_representation_svd(X, affine=True)
    tau = svd.tau_from_relative(50.0)
    z = np.hstack([X, np.ones((X.shape[0], 1))]).T
    q = svd.self_representation(tau)

    def objective(c):
        return np.linalg.norm(c, "nuc") + tau / 2 * np.sum((z - z @ c) ** 2)

    best = objective(q)
    rng = np.random.default_rng(0)
    for _ in range(20):
        e = rng.standard_normal(q.shape) * 1e-3
        assert objective(q + (e + e.T) / 2) > best


def test_tau_for_r2_is_the_smallest_tau_reaching_the_target():
    X, _ = union_of_subspaces([40, 40, 40], [3, 3, 3], 15, noise=0.05, seed=3)
    svd = self_representation_svd(X)
    for target in (0.5, 0.9, 0.99, 0.999):
        tau = svd.tau_for_r2(target)
        assert svd.r2(tau) >= target
        assert svd.r2(tau * (1 - 1e-6)) < target
    taus = np.geomspace(1e-4, 1e4, 200) / svd.top_singular_value**2
    r2 = [svd.r2(t) for t in taus]
    assert np.all(np.diff(r2) >= -1e-12)  # non-decreasing in tau


def test_tau_for_r2_rejects_targets_it_cannot_serve():
    lam = np.array([3.0, 2.0, 1.0])
    with pytest.raises(UserError, match="no component kept"):
        tau_for_r2(lam, 0.1, total_sum_squares=100.0)  # Q* = 0 already gives R^2 = 0.86
    with pytest.raises(UserError, match=r"\(0, 1\)"):
        tau_for_r2(lam, 1.0)


def test_gram_route_svd_matches_lapack(monkeypatch):
    X, _ = union_of_subspaces([300, 300], [3, 2], 8, noise=0.01, seed=4)
    lapack = self_representation_svd(X)
    monkeypatch.setattr(lrsc_module, "_GRAM_SVD_MIN_ENTRIES", 0)
    gram = self_representation_svd(X)
    assert (lapack.method, gram.method) == ("lapack", "gram")
    np.testing.assert_allclose(gram.singular_values, lapack.singular_values, rtol=1e-9)
    np.testing.assert_allclose(gram.data_share, lapack.data_share, atol=1e-9)
    tau = lapack.tau_for_r2(0.99)
    np.testing.assert_allclose(gram.self_representation(tau), lapack.self_representation(tau), atol=1e-9)


# --------------------------------------------------------------------------- spectral


@pytest.fixture(scope="module")
def noisy_factor():
    X, y = union_of_subspaces([120, 100, 140, 90], [3, 2, 3, 2], 20, noise=0.03, seed=5)
    svd = self_representation_svd(X)
    return svd.factor(svd.tau_for_r2(0.999)), y


def test_operator_and_degrees_match_the_dense_matrices(noisy_factor):
    f, _ = noisy_factor
    w = affinity_from_factor(f, "squared")
    q = f @ f.T
    np.testing.assert_allclose(w, q * q)
    np.testing.assert_allclose(degrees_from_factor(f), w.sum(axis=1), rtol=1e-10)
    d = w.sum(axis=1)
    m = w / np.sqrt(np.outer(d, d))
    op = NormalizedAffinityOperator(f)
    x = np.random.default_rng(0).standard_normal((f.shape[0], 3))
    np.testing.assert_allclose(op.matmat(x), m @ x, atol=1e-12)
    np.testing.assert_allclose(op.matvec(x[:, 0]), m @ x[:, 0], atol=1e-12)


@pytest.mark.parametrize("method", ["gram", "lobpcg"])
def test_implicit_embeddings_span_the_dense_one(noisy_factor, method):
    f, y = noisy_factor
    dense = spectral_embedding(f, 4, method="dense")
    implicit = spectral_embedding(f, 4, method=method, random_state=0)
    np.testing.assert_allclose(implicit.eigenvalues, dense.eigenvalues, rtol=1e-7)
    # the same invariant subspace (eigenvectors are only defined up to rotation)
    overlap = np.linalg.svd(dense.vectors.T @ implicit.vectors, compute_uv=False)
    np.testing.assert_allclose(overlap, 1.0, atol=1e-6)
    dense_labels = njw_labels(dense.vectors, 4, random_state=0)
    np.testing.assert_array_equal(njw_labels(implicit.vectors, 4, random_state=0), dense_labels)
    assert clustering_accuracy(y, dense_labels) == 1.0


def test_dense_and_implicit_estimators_give_the_same_labels():
    X, y = union_of_subspaces([150, 150, 150, 150], [3, 3, 2, 3], 25, noise=0.05, seed=6)
    dense = LowRankSubspaceClustering(4, spectral="dense", random_state=0).fit(X)
    implicit = LowRankSubspaceClustering(4, spectral="implicit", random_state=0).fit(X)
    assert (dense.spectral_method_, implicit.spectral_method_) == ("dense", "gram")
    np.testing.assert_array_equal(dense.labels_, implicit.labels_)
    assert dense.self_representation_.shape == (600, 600) and implicit.self_representation_ is None
    assert clustering_accuracy(y, dense.labels_) == 1.0


def test_repeated_top_eigenvalue_is_resolved_by_every_route():
    """Noise-free, tau -> large: Q* -> V V^T is block diagonal, the top eigenvalue 1 repeats K
    times (ARPACK's single-vector Lanczos misses copies; gram and lobpcg must not)."""
    X, y = union_of_subspaces([60, 60, 60, 60, 60], [2, 2, 3, 2, 2], 30, seed=7)
    svd = self_representation_svd(X)
    f = svd.factor(svd.tau_from_relative(1e12))
    for method in ("dense", "gram", "lobpcg"):
        emb = spectral_embedding(f, 5, method=method, random_state=0)
        np.testing.assert_allclose(emb.eigenvalues, 1.0, atol=1e-6)
        assert clustering_accuracy(y, njw_labels(emb.vectors, 5, random_state=0)) == 1.0


def test_fewer_nonzero_eigenvalues_than_clusters_drop_the_null_space():
    X, _ = union_of_subspaces([50, 50], [1, 1], 5, seed=8)
    svd = self_representation_svd(X)
    f = svd.factor(svd.tau_from_relative(1e8))[:, :1]  # rank-1 Q*: W has one nonzero eigenvalue
    for method in ("dense", "gram"):
        emb = spectral_embedding(f, 3, method=method)
        assert emb.vectors.shape == (100, 1)


# -------------------------------------------------------------------------- estimator


@pytest.mark.parametrize("affine", [True, False])
def test_exact_recovery_of_noise_free_subspaces(affine):
    dims = [2, 3, 1, 2]
    X, y = union_of_subspaces([40, 50, 30, 45], dims, 16, affine=affine, seed=9)
    model = LowRankSubspaceClustering(4, affine=affine, tau_relative=1e10, spectral="dense", random_state=0).fit(X)
    assert clustering_accuracy(y, model.labels_) == 1.0
    assert model.rank_ == sum(d + 1 for d in dims) if affine else sum(dims)
    # subspace separation theorem: Q* has no weight between different subspaces
    q = model.self_representation_
    across = y[:, None] != y[None, :]
    assert np.abs(q[across]).max() < 1e-6 * np.abs(q).max()
    assert model.r2_ > 0.999999


def test_affine_finds_what_linear_cannot():
    """Parallel lines (same direction, different offsets) span one linear 2-D subspace each
    pair; only the affine model separates them."""
    rng = np.random.default_rng(10)
    direction = rng.standard_normal(6)
    offsets = [rng.standard_normal(6) for _ in range(3)]
    X = np.vstack([o + rng.standard_normal((40, 1)) * direction for o in offsets])
    y = np.repeat(np.arange(3), 40)
    affine = LowRankSubspaceClustering(3, tau_relative=1e8, random_state=0).fit(X)
    assert clustering_accuracy(y, affine.labels_) == 1.0
    assert affine.rank_ == 4  # the lines span a 3-D affine (4-D homogeneous) space together


def test_tau_options_agree():
    X, _ = union_of_subspaces([50, 50, 50], [2, 2, 2], 10, noise=0.02, seed=11)
    by_r2 = LowRankSubspaceClustering(3, r2_target=0.995, random_state=0).fit(X)
    by_tau = LowRankSubspaceClustering(3, tau=by_r2.tau_, random_state=0).fit(X)
    by_rel = LowRankSubspaceClustering(3, tau_relative=by_r2.tau_relative_, random_state=0).fit(X)
    assert by_r2.r2_ >= 0.995
    for other in (by_tau, by_rel):
        assert other.tau_ == pytest.approx(by_r2.tau_, rel=1e-12)
        assert other.rank_ == by_r2.rank_
        np.testing.assert_array_equal(other.labels_, by_r2.labels_)
    default = LowRankSubspaceClustering(3, random_state=0).fit(X)
    assert default.r2_ == pytest.approx(0.99, abs=1e-9)


def test_scale_invariance_with_tau_relative():
    X, _ = union_of_subspaces([60, 60, 60], [2, 3, 2], 12, noise=0.05, seed=12)
    c = 1234.5
    base = LowRankSubspaceClustering(3, affine=False, tau_relative=500.0, random_state=0).fit(X)
    scaled = LowRankSubspaceClustering(3, affine=False, tau_relative=500.0, random_state=0).fit(c * X)
    np.testing.assert_array_equal(base.labels_, scaled.labels_)
    assert (base.rank_, base.r2_) == pytest.approx((scaled.rank_, scaled.r2_))
    assert scaled.tau_ == pytest.approx(base.tau_ / c**2)
    # affine: scale-free when the ones row scales with the data
    base = LowRankSubspaceClustering(3, tau_relative=500.0, ones_weight=1.0, random_state=0).fit(X)
    scaled = LowRankSubspaceClustering(3, tau_relative=500.0, ones_weight=c, random_state=0).fit(c * X)
    np.testing.assert_array_equal(base.labels_, scaled.labels_)
    assert (base.rank_, base.r2_) == pytest.approx((scaled.rank_, scaled.r2_))


def test_same_seed_same_labels():
    X, _ = union_of_subspaces([80, 80, 80], [2, 2, 2], 10, noise=0.2, seed=13)
    a = LowRankSubspaceClustering(3, spectral="implicit", random_state=5).fit(X)
    b = LowRankSubspaceClustering(3, spectral="implicit", random_state=5).fit(X)
    np.testing.assert_array_equal(a.labels_, b.labels_)
    assert a.labels_.dtype == np.int64 and set(a.labels_) <= {0, 1, 2}


def test_abs_affinity_is_dense_only():
    X, y = union_of_subspaces([40, 40], [2, 2], 8, noise=0.01, seed=14)
    model = LowRankSubspaceClustering(2, affinity="abs", random_state=0).fit(X)
    assert model.spectral_method_ == "dense" and clustering_accuracy(y, model.labels_) == 1.0
    with pytest.raises(ValueError, match="affinity='squared'"):
        LowRankSubspaceClustering(2, affinity="abs", spectral="implicit").fit(X)


def test_dense_route_refuses_huge_n(monkeypatch):
    monkeypatch.setattr(spectral_module, "DENSE_MAX_SAMPLES", 50)
    X, _ = union_of_subspaces([40, 40], [2, 2], 8, seed=15)
    with pytest.raises(ValueError, match="limited to 50 points"):
        LowRankSubspaceClustering(2, spectral="dense").fit(X)


@pytest.mark.parametrize(
    "params, X, message",
    [
        ({}, np.array([[0.0, 1.0], [np.nan, 2.0], [1.0, 1.0]]), "NaN"),
        ({}, np.array([[0.0, 1.0], [np.inf, 2.0], [1.0, 1.0]]), "infinity"),
        ({"n_clusters": 4}, np.arange(6.0).reshape(3, 2), "n_samples=3 should be >= n_clusters=4"),
        ({"n_clusters": 0}, np.arange(6.0).reshape(3, 2), "n_clusters"),
        ({}, np.arange(6.0), "Expected 2D array"),
        ({"tau": 0.0}, np.arange(6.0).reshape(3, 2), "'tau' parameter"),
        ({"tau": -1.0}, np.arange(6.0).reshape(3, 2), "'tau' parameter"),
        ({"tau_relative": -2.0}, np.arange(6.0).reshape(3, 2), "'tau_relative' parameter"),
        ({"r2_target": 1.0}, np.arange(6.0).reshape(3, 2), "'r2_target' parameter"),
        ({"tau": 1.0, "r2_target": 0.9}, np.arange(6.0).reshape(3, 2), "at most one of tau, tau_relative, r2_target"),
        ({"tau": 1e-9}, np.arange(6.0).reshape(3, 2), "keeps no component"),
        ({}, np.ones((1, 3)), "1 sample"),
    ],
)
def test_bad_input_is_a_clear_value_error(params, X, message):
    params = {"n_clusters": 2, **params}
    n_clusters = params.pop("n_clusters")
    with pytest.raises(ValueError, match=message):
        LowRankSubspaceClustering(n_clusters, **params).fit(X)


@parametrize_with_checks([LowRankSubspaceClustering(3, n_init=2, random_state=0)])
def test_scikit_learn_estimator_checks(estimator, check):
    # Every check applies and passes (scikit-learn 1.9); check_array_api_input skips itself
    # unless SCIPY_ARRAY_API is set, and this estimator takes NumPy input only.
    check(estimator)


def test_lasa_26_shapes_cluster_with_accuracy_at_least_0_9():
    """The paper's trajectory-space clustering on real data: LASA's 26 single-pattern shapes x
    7 demos, T = 50, joints (x, y) scaled to [-1, 1], flattened; tau by the default held-out
    selection (no label used), which keeps the fixed 0.99 here: measured accuracy 0.973 (NMI 0.98)."""
    from primspace.data import JointScaler, import_lasa

    ds = import_lasa(length=50)
    X = JointScaler().fit_transform(ds.motor).reshape(len(ds), -1)
    model = LowRankSubspaceClustering(26, random_state=0).fit(X)
    scores = clustering_scores(ds.labels, model.labels_)
    assert scores["accuracy"] >= 0.9, scores
    assert model.r2_ == pytest.approx(0.99, abs=1e-9)


# ---------------------------------------------------------------------------- metrics


def test_accuracy_uses_the_best_matching():
    assert clustering_accuracy([0, 0, 1, 1, 2], [5, 5, 3, 3, 3]) == pytest.approx(0.8)
    assert clustering_accuracy([0, 0, 1, 1], [1, 1, 0, 0]) == 1.0
    assert clustering_accuracy([0, 0, 0, 0], [0, 1, 2, 3]) == 0.25  # extra clusters count as wrong


def test_scores_ignore_unknown_true_labels():
    scores = clustering_scores([0, 0, 1, 1, -1, -1], [1, 1, 0, 0, 0, 1])
    assert scores == {"accuracy": 1.0, "nmi": 1.0, "ari": 1.0, "n_scored": 4, "n_ignored": 2}
    assert clustering_scores([-1, -1], [0, 1])["accuracy"] is None
    with pytest.raises(ValueError, match="3 true labels for 2"):
        clustering_scores([0, 1, 1], [0, 1])


# ------------------------------------------------------------------------------ sweep


def test_sweep_rows_equal_estimator_fits():
    X, y = union_of_subspaces([50, 50, 50], [2, 3, 2], 12, noise=0.05, seed=16)
    rows = sweep(X, 3, r2_targets=[0.5, 0.9, 0.999], labels_true=y, random_state=3, return_labels=True)
    assert [r["value"] for r in rows] == [0.5, 0.9, 0.999]
    assert [r["r2"] for r in rows] == pytest.approx([0.5, 0.9, 0.999])
    for row in rows:
        model = LowRankSubspaceClustering(3, tau=row["tau"], random_state=3).fit(X)
        np.testing.assert_array_equal(row["labels"], model.labels_)
        assert (row["rank"], row["r2"]) == (model.rank_, pytest.approx(model.r2_))
        assert row["accuracy"] == clustering_accuracy(y, model.labels_)
    assert rows[2]["accuracy"] == 1.0
    taus = sweep(X, 3, taus=[rows[1]["tau"], 1e-9], random_state=3)
    assert taus[0]["rank"] == rows[1]["rank"] and "accuracy" not in taus[0]
    assert taus[1]["rank"] == 0 and "keeps no component" in taus[1]["note"]
    with pytest.raises(ValueError, match="at most one grid"):
        sweep(X, 3, taus=[1.0], r2_targets=[0.9])
