"""The tau sweep built on the estimator, the shared SVD, the one R^2 grid, and the pipeline."""

from __future__ import annotations

import inspect
import json

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.utils.validation import check_is_fitted

import primspace.cluster.estimator as estimator_module
from primspace.cluster import (
    DEFAULT_R2_GRID,
    R2_GRID,
    ClusteringResult,
    LowRankSubspaceClustering,
    cluster_points,
    clustering_figure,
    sweep,
    sweep_figure,
    tau_sweep,
)
from primspace.utils.errors import UserError
from test_cluster_pinned import planted


@pytest.fixture
def svd_calls(monkeypatch):
    """Count the SVDs of Z~ that fits and sweeps compute."""
    calls = []
    real = estimator_module.self_representation_svd

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(estimator_module, "self_representation_svd", counting)
    return calls


def test_one_r2_grid_is_the_commands_default():
    from primspace.cli.cluster import cluster_command

    assert DEFAULT_R2_GRID is R2_GRID and list(R2_GRID) == sorted(set(R2_GRID))
    assert all(0 < v < 1 for v in R2_GRID)
    help_text = inspect.signature(cluster_command).parameters["sweep_taus"].default.help
    assert f"R^2 targets {R2_GRID[0]:g} ... {R2_GRID[-1]:g}" in help_text


def test_a_sweep_computes_one_svd(svd_calls):
    X, y = planted()
    rows = sweep(X, 3, labels_true=y, random_state=0)
    assert len(rows) == len(R2_GRID) and len(svd_calls) == 1
    svd_calls.clear()
    fixed = LowRankSubspaceClustering(3, r2_target=0.99, random_state=0)
    result = cluster_points(X, fixed, labels_true=y, sweep_param="r2_target")
    assert len(result.sweep) == len(R2_GRID) and len(svd_calls) == 1  # the fit and the sweep share it


def test_tau_sweep_rows_are_fits_of_clones():
    X, y = planted()
    est = LowRankSubspaceClustering(3, tau=123.0, affinity="abs", ones_weight=2.0, n_init=5, random_state=7)
    rows = tau_sweep(est, X, param_name="tau_relative", param_range=[40.0, 800.0], labels_true=y, return_labels=True)
    assert est.get_params()["tau"] == 123.0 and not hasattr(est, "labels_")  # untouched
    for row in rows:
        model = clone(est).set_params(tau=None, tau_relative=row["value"]).fit(X)
        np.testing.assert_array_equal(row["labels"], model.labels_)
        assert (row["tau"], row["r2"], row["rank"]) == (model.tau_, model.r2_, model.rank_)
        assert row["grid"] == "tau_relative" and row["tau_relative"] == pytest.approx(row["value"], rel=1e-12)


def test_a_random_state_instance_runs_through_the_grid_as_before():
    X, _ = planted()
    a = sweep(X, 3, r2_targets=[0.9, 0.99], random_state=np.random.RandomState(4), return_labels=True)
    rng = np.random.RandomState(4)
    first = LowRankSubspaceClustering(3, r2_target=0.9, random_state=rng).fit(X)
    second = LowRankSubspaceClustering(3, r2_target=0.99, random_state=rng).fit(X)
    np.testing.assert_array_equal(a[0]["labels"], first.labels_)
    np.testing.assert_array_equal(a[1]["labels"], second.labels_)


def test_fit_with_a_shared_svd_is_the_same_fit():
    X, _ = planted()
    est = LowRankSubspaceClustering(3, r2_target=0.999, random_state=1)
    svd = est.decompose(X)
    with pytest.raises(NotFittedError):
        check_is_fitted(est)  # decompose validates but does not fit
    plain, shared = clone(est).fit(X), clone(est).fit(X, svd=svd)
    np.testing.assert_array_equal(plain.labels_, shared.labels_)
    assert (plain.tau_, plain.r2_, plain.rank_) == (shared.tau_, shared.r2_, shared.rank_)
    np.testing.assert_array_equal(plain.representation_factor_, shared.representation_factor_)


@pytest.mark.parametrize(
    "change, message",
    [({"affine": False}, "affine=True"), ({"ones_weight": 3.0}, "ones_weight=1.0"), ({"rows": 10}, "140 points")],
)
def test_an_svd_of_other_points_or_settings_is_refused(change, message):
    X, _ = planted()
    svd = LowRankSubspaceClustering(3).decompose(X)
    settings = {k: v for k, v in change.items() if k != "rows"}
    with pytest.raises(ValueError, match=message):
        LowRankSubspaceClustering(3, **settings).fit(X[change.get("rows", 0) :], svd=svd)
    with pytest.raises(ValueError, match="SelfRepresentationSVD"):
        LowRankSubspaceClustering(3).fit(X, svd="svd")


def test_sweep_refuses_bad_grids_before_any_work(svd_calls):
    X, _ = planted()
    est = LowRankSubspaceClustering(3)
    for kwargs, message in [
        ({"param_name": "n_init", "param_range": [1]}, "param_name must be one of"),
        ({"param_name": "tau", "param_range": []}, "grid is empty"),
        ({"param_name": "r2_target", "param_range": [0.9, 1.5]}, "r2_target must lie in"),
        ({"param_name": "tau", "param_range": [1.0, -1.0]}, "tau must be a positive number"),
    ]:
        with pytest.raises(UserError, match=message):
            tau_sweep(est, X, **kwargs)
    with pytest.raises(UserError, match="3 true labels for 150 points"):
        tau_sweep(est, X, labels_true=[0, 1, 2])
    with pytest.raises(UserError, match="needs sweep_values"):
        cluster_points(X, est, sweep_param="tau")
    assert svd_calls == []


def test_pipeline_result_is_the_estimators_and_round_trips_through_json():
    X, y = planted()
    est = LowRankSubspaceClustering(3, tau_relative=300.0, random_state=5)
    result = cluster_points(
        X, est, labels_true=y, label_names=["a", "b", "c"], sweep_param="tau", sweep_values=[0.1, 1.0]
    )
    model = clone(est).fit(X)
    np.testing.assert_array_equal(result.labels, model.labels_)
    assert (result.tau, result.r2, result.rank, result.tau_option) == (
        model.tau_,
        model.r2_,
        model.rank_,
        {"tau_relative": 300.0},
    )
    assert result.summary() == {
        "tau": model.tau_,
        "r2": model.r2_,
        "rank": model.rank_,
        "accuracy": 1.0,
        "nmi": 1.0,
        "ari": 1.0,
    }
    summary = result.to_dict()
    assert list(summary) == [
        "n_samples",
        "n_features",
        "n_clusters",
        "affine",
        "affinity",
        "ones_weight",
        "tau_option",
        "tau",
        "tau_relative",
        "r2",
        "rank",
        "spectral_method",
        "eigenvalues",
        "singular_values",
        "n_init",
        "seed",
        "seconds",
        "scores",
        "sweep",
    ]
    assert [r["value"] for r in summary["sweep"]] == [0.1, 1.0]
    full = json.loads(json.dumps(result.to_dict(include_arrays=True)))
    again = ClusteringResult.from_dict(full)
    assert again.to_dict() == summary
    np.testing.assert_array_equal(again.labels, result.labels)
    np.testing.assert_array_equal(again.figure_affinity(), result.figure_affinity())
    split = ClusteringResult.from_dict(summary, result.arrays())
    np.testing.assert_array_equal(split.figure_factor, result.figure_factor)


def test_figures_are_drawn_from_the_result_alone():
    import matplotlib.pyplot as plt

    from primspace.cluster import affinity_from_factor

    X, y = planted()
    est = LowRankSubspaceClustering(3, random_state=0)
    result = cluster_points(X, est, labels_true=y, sweep_param="r2_target", sweep_values=[0.9, 0.99])
    model = clone(est).fit(X)
    np.testing.assert_array_equal(
        result.figure_affinity(), affinity_from_factor(model.representation_factor_, rows=result.figure_indices)
    )
    for fig, title in ((clustering_figure(result, title="t"), "t"), (sweep_figure(result, title="s"), "s")):
        texts = [t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text"))]
        assert title in texts and len(fig.axes) >= 2
        plt.close(fig)
    with pytest.raises(ValueError, match="no sweep"):
        sweep_figure(cluster_points(X, est))
