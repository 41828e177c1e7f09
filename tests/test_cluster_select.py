"""Tau by held-out evidence: ``r2_target="select"``, the default of the estimator and the command."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from primspace.cluster import (
    DEFAULT_R2_TARGET,
    DEFAULT_TAU_CHOICE,
    SELECT_FIXED_TARGETS,
    ClusteringResult,
    LowRankSubspaceClustering,
    cluster_points,
    clustering_scores,
)
from primspace.cluster.advice import codes_note
from primspace.cluster.estimator import tau_option_from
from primspace.cluster.select import heldout_splits, heldout_stability, select_r2_target
from primspace.utils.errors import UserError


def planted(noise, seed=0, k=4, n_per=40, dim=2, ambient=40, offset_scale=0.3):
    """``k`` random affine ``dim``-subspaces of R^ambient, ``n_per`` noisy points on each."""
    rng = np.random.default_rng(seed)
    xs = []
    for _ in range(k):
        basis = np.linalg.qr(rng.standard_normal((ambient, dim)))[0]
        xs.append(offset_scale * rng.standard_normal(ambient) + rng.standard_normal((n_per, dim)) @ basis.T)
    return np.vstack(xs) + noise * rng.standard_normal((k * n_per, ambient)), np.repeat(np.arange(k), n_per)


def accuracy(y, labels):
    return clustering_scores(y, labels)["accuracy"]


def test_select_is_the_default_in_python_and_on_the_command_line():
    from primspace.cli.cluster import cluster_command

    assert DEFAULT_TAU_CHOICE == "select" and SELECT_FIXED_TARGETS[0] == DEFAULT_R2_TARGET == 0.99
    assert LowRankSubspaceClustering(3).get_params()["r2_target"] is None
    assert tau_option_from(None, None, None) == ("r2_target", "select")
    assert inspect.signature(cluster_command).parameters["r2"].default.default is None  # the estimator's default
    X, _ = planted(0.05)
    model = LowRankSubspaceClustering(4, random_state=0).fit(X)
    assert model.selection_ is not None and model.auto_choice_ is not None


def test_select_beats_the_fixed_target_where_it_fails_and_records_every_candidate():
    X, y = planted(0.5)  # the fixed 0.99 keeps noise directions here (test_cluster_auto)
    model = LowRankSubspaceClustering(4, random_state=0).fit(X)
    fixed = accuracy(y, LowRankSubspaceClustering(4, r2_target=0.99, random_state=0).fit(X).labels_)
    auto = accuracy(y, LowRankSubspaceClustering(4, r2_target="auto", random_state=0).fit(X).labels_)
    got = accuracy(y, model.labels_)
    assert fixed < 0.8 and got >= max(fixed, auto) - 0.05, (got, fixed, auto)
    sel = model.selection_
    assert sel.r2_targets[: len(SELECT_FIXED_TARGETS)] == SELECT_FIXED_TARGETS
    assert sel.sources[0] == ("default",) and "auto" in sum(sel.sources, ())
    assert sel.index == int(np.nanargmax(sel.scores)) and all(r >= 4 for r in sel.ranks)
    assert sel.auto["r2_target"] == model.auto_choice_.r2_target
    # the fit at the chosen target is exactly the fit at that fixed target
    same = LowRankSubspaceClustering(4, r2_target=sel.r2_target, random_state=0).fit(X)
    np.testing.assert_array_equal(model.labels_, same.labels_)
    assert model.tau_ == same.tau_


def test_select_is_deterministic_and_follows_the_seed():
    X, _ = planted(0.3)
    a = LowRankSubspaceClustering(4, random_state=3).fit(X).selection_
    b = LowRankSubspaceClustering(4, random_state=3).fit(X).selection_
    np.testing.assert_array_equal(a.scores, b.scores)
    assert a.to_dict() == b.to_dict()


def test_too_few_points_keep_the_fixed_default_and_say_why():
    X, _ = planted(0.05, k=3, n_per=3)  # 9 points: halves of 6 points, 3 clusters -> scored
    assert select_r2_target(X, 3, {"r2_target": 0.9999}, lambda part, t: np.zeros(len(part), int)).note is None
    sel = select_r2_target(X[:5], 4, {"r2_target": 0.9999}, lambda part, t: np.zeros(len(part), int))
    assert sel.index == 0 and sel.r2_target == 0.99 and np.all(np.isnan(sel.scores))
    assert "too few" in sel.note and sel.to_dict()["candidates"][0]["score"] is None
    one = select_r2_target(X, 3, {"r2_target": 0.99}, lambda part, t: np.zeros(len(part), int), fixed=(0.99,))
    assert one.note == "one candidate" and one.sources == (("default", "auto"),)


def test_a_candidate_whose_rank_is_below_k_is_not_scored_while_another_is_eligible():
    X, _ = planted(0.05, k=3, n_per=10)
    calls = []

    def labels(part, target):
        calls.append(target)
        return np.arange(len(part)) % 3

    ranks = {0.99: 5, 0.7: 2, 0.9999: 9}
    sel = select_r2_target(X, 3, {"r2_target": 0.9999}, labels, rank_of=ranks.get, repeats=1)
    assert 0.7 not in calls and np.isnan(sel.scores[1]) and sel.ranks == (5, 2, 9)
    assert sel.to_dict()["candidates"][1] == {"r2_target": 0.7, "sources": ["fixed"], "rank": 2, "score": None}
    low = select_r2_target(X, 3, {"r2_target": 0.9999}, labels, rank_of=lambda t: 1, repeats=1)
    assert np.all(np.isfinite(low.scores))  # none eligible: all scored


def test_heldout_stability_rewards_agreement_and_discounts_degenerate_partitions():
    X, y = planted(0.05, k=3, n_per=30)
    splits = heldout_splits(len(X), repeats=2, rng=0)
    for first, second, shared in splits:
        assert set(shared) <= set(first) & set(second) and len(shared) == len(X) // 3
    truth = {tuple(row): label for row, label in zip(X, y)}
    perfect = heldout_stability(X, 3, lambda part: np.array([truth[tuple(r)] for r in part]), splits)
    assert 0.95 < perfect <= 1.0  # ARI 1; the halves' classes are nearly, not exactly, equal in size
    # one big cluster plus an outlier agrees perfectly between halves but is useless: scored near 0
    lumped = heldout_stability(X, 3, lambda part: (np.arange(len(part)) == 0).astype(int), splits)
    assert lumped < 0.1

    def failing(part):
        raise UserError("keeps no component")

    assert heldout_stability(X, 3, failing, splits) == 0.0


def test_the_result_records_the_selection_and_round_trips():
    X, y = planted(0.3, n_per=25)
    result = cluster_points(X, LowRankSubspaceClustering(4, random_state=0), labels_true=y)
    data = result.to_dict(include_arrays=True)
    assert data["tau_option"] == {"r2_target": "select"} and "auto" not in data
    sel = data["selection"]
    assert sel["score"] == "heldout_stability" and sel["auto"]["criterion"] == "relative_eigengap"
    assert [c["r2_target"] for c in sel["candidates"]][:2] == list(SELECT_FIXED_TARGETS)
    assert result.summary()["selected_r2_target"] == sel["r2_target"] == pytest.approx(result.r2, abs=1e-6)
    assert ClusteringResult.from_dict(data).selection == result.selection


def test_codes_note_says_why_codes_cluster_below_raw_trajectories():
    assert codes_note(1715, 40, 7, codes_accuracy=0.9, raw_accuracy=0.92) is None
    note = codes_note(156, 8, 26, codes_accuracy=0.85, raw_accuracy=0.97)
    assert note.startswith("note: the codes cluster at accuracy 0.85, the raw trajectories of the same 156")
    assert "26 primitives in 8-dimensional codes cannot lie in independent affine subspaces (at most 9" in note
    assert "6 samples per primitive, fewer than the 9" in note and "\n" not in note
    worse = codes_note(1715, 40, 7, codes_accuracy=0.5, raw_accuracy=0.9)
    assert "not to separate primitives" in worse
    few = codes_note(30, 16, 3)  # no labels: the reasons alone
    assert few.startswith("note: codes of 30 samples in 16 dimensions for 3 primitives: 10 samples per primitive")


def test_the_command_compares_a_runs_codes_with_their_raw_trajectories():
    from primspace.cli.cluster import _codes_note
    from primspace.cluster.inputs import ClusterPoints

    rng = np.random.default_rng(0)
    y = np.repeat(np.arange(5), 8)
    raw, _ = planted(0.01, k=5, n_per=8, ambient=20)
    codes = rng.standard_normal((40, 3))  # codes that lost the primitives
    points = ClusterPoints(
        X=codes, labels=y, label_names=None, path=None, description="", samples=np.arange(40), raw=raw
    )
    options = {"r2_target": 0.99, "random_state": 0}
    result = cluster_points(codes, LowRankSubspaceClustering(5, **options), labels_true=y)
    note = _codes_note("run", points, 5, {**options, "affine": True}, result)
    assert note.startswith(f"note: the codes cluster at accuracy {result.scores['accuracy']:.2f}, the raw")
    assert "5 primitives in 3-dimensional codes cannot lie in independent affine subspaces (at most 4" in note
    assert _codes_note("z.npy", ClusterPoints(codes, y, None, None, ""), 5, options, result) is None  # not a run
