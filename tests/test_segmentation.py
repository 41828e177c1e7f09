"""Segmenting and labelling sequences of window codes (primspace.segmentation): planted
piecewise-constant codes of primitives on affine subspaces give back their boundaries and
labels, noise alone gives no change point, the partition is the exact optimum, and the
scores (boundary F1 with one-to-one matching, Hungarian step accuracy) are right on
hand-computed cases; bad arguments fail in one line."""

import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from primspace.segmentation import (
    boundaries_from_segments,
    boundary_f1,
    change_points,
    noise_variances,
    segment_sequences,
    step_labelling_accuracy,
)
from primspace.utils.errors import UserError

W = 10


def _planted(n_seq=30, q=12, n_prim=3, dim=2, n_windows=30, noise=0.05, seed=0, aligned=True):
    """Sequences chaining 2-4 primitives; a segment's code is a point of its primitive's
    affine subspace (dim ``dim`` in R^q), a window's code the mean of its steps' codes plus
    noise (a window straddling a boundary mixes the two). Padding windows hold junk."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(scale=2.0, size=(n_prim, q))
    bases = rng.normal(size=(n_prim, q, dim))
    codes = rng.normal(scale=50.0, size=(n_seq, n_windows, q))
    T = n_windows * W
    labels, segments = np.full((n_seq, T), -1, np.int32), np.full((n_seq, T), -1, np.int32)
    lengths = np.zeros(n_seq, np.int32)
    for i in range(n_seq):
        prims, n_segments = [int(rng.integers(n_prim))], rng.integers(2, 5)
        while len(prims) < n_segments:
            p = int(rng.integers(n_prim))
            prims += [p] if p != prims[-1] else []
        if aligned:
            steps = rng.integers(3, 7, size=len(prims)) * W
            steps[-1] -= rng.integers(0, W)  # a partial last window
        else:
            steps = rng.integers(3 * W, 6 * W + 1, size=len(prims))
        lengths[i] = L = int(steps.sum())
        step_code, t = np.zeros((L, q)), 0
        for s, (p, m) in enumerate(zip(prims, steps)):
            step_code[t : t + m] = centres[p] + bases[p] @ rng.normal(size=dim)
            labels[i, t : t + m], segments[i, t : t + m], t = p, s, t + m
        for k in range(-(-L // W)):
            codes[i, k] = step_code[k * W : (k + 1) * W].mean(axis=0) + noise * rng.normal(size=q)
    return codes, lengths, labels, segments


@pytest.mark.parametrize("seed", [0, 1])
def test_planted_aligned_boundaries_are_recovered_exactly_and_labelled(seed):
    codes, lengths, labels, segments = _planted(seed=seed)
    truth = boundaries_from_segments(segments, lengths)
    res = segment_sequences(codes, W, lengths, 3)
    for found, true in zip(res.boundaries, truth):
        np.testing.assert_array_equal(found, true)
    assert boundary_f1(truth, res.boundaries, 0)["f1"] == 1.0
    assert step_labelling_accuracy(labels, res.step_labels) >= 0.95
    assert [len(s) for s in res.step_labels] == list(lengths)
    np.testing.assert_array_equal(res.padded_step_labels(labels.shape[1]) == -1, labels == -1)
    S = len(res.segment_labels)
    assert res.segment_codes.shape == (S, 12) and S == sum(len(b) + 1 for b in truth)
    for i in range(len(lengths)):  # the segments of a sequence tile its valid steps
        start, stop = res.segment_start[res.segment_sample == i], res.segment_stop[res.segment_sample == i]
        assert start[0] == 0 and stop[-1] == lengths[i] and np.all(start[1:] == stop[:-1])
    assert res.note is None and set(res.segment_labels) == {0, 1, 2}


def test_unaligned_boundaries_within_a_window_thanks_to_transition_windows():
    codes, lengths, labels, segments = _planted(seed=3, aligned=False, noise=0.2)
    truth = boundaries_from_segments(segments, lengths)
    res = segment_sequences(codes, W, lengths, 3)
    assert boundary_f1(truth, res.boundaries, W)["f1"] == 1.0
    assert boundary_f1(truth, res.boundaries, 1)["f1"] >= 0.95  # placed inside the window too
    assert step_labelling_accuracy(labels, res.step_labels) >= 0.95
    plain = segment_sequences(codes, W, lengths, 3, transitions=False)
    assert boundary_f1(truth, plain.boundaries, W)["fp"] > 5  # mixed windows become segments


def test_a_transition_window_places_the_boundary_by_its_mix():
    a, b = np.zeros(6), np.full(6, 10.0)
    codes = np.vstack([np.tile(a, (5, 1)), 0.3 * a + 0.7 * b, np.tile(b, (5, 1))])
    res = segment_sequences([codes], W, [11 * W], 2)
    assert res.change_points[0].tolist() == [5] and res.transitions[0].tolist() == [True]
    assert res.boundaries[0].tolist() == [5 * W + 3]  # 30 % of window 5 is still segment a
    assert res.step_labels[0].tolist() == [0] * 53 + [1] * 57
    np.testing.assert_allclose(res.segment_codes, [a, b])  # the transition is in neither


@pytest.mark.parametrize("q", [8, 20])
def test_noise_only_gives_no_change_point(q):
    rng = np.random.default_rng(q)
    for n in (20, 60, 150):
        for _ in range(4):
            z = rng.normal(size=(n, q)) * np.linspace(0.5, 1.5, q) + rng.normal(size=q)
            assert change_points(z).size == 0, (n, q)
    seqs = [rng.normal(size=(40, q)) for _ in range(6)]
    res = segment_sequences(seqs, W, [400] * 6, 2)
    assert all(b.size == 0 for b in res.boundaries)
    assert boundary_f1([[]] * 6, res.boundaries, W)["f1"] == 1.0


def test_change_points_finds_one_jump_counts_only_valid_windows_and_takes_a_float_penalty():
    rng = np.random.default_rng(5)
    z = 0.1 * rng.normal(size=(30, 4))
    z[12:] += 2.0
    assert change_points(z, transitions=False).tolist() == [12]
    # with transitions the window either side of the jump may be shed as a transition; the
    # boundary step lands on the jump all the same
    assert change_points(z).tolist() in ([11], [12])
    assert segment_sequences([z], W, [300], 1).boundaries[0].tolist() == [12 * W]
    assert change_points(z, n_valid=11).size == 0  # the jump lies in the padding
    assert change_points(z, penalty=1e6).size == 0
    assert len(change_points(z, penalty=0.0)) > 5  # no cost per segment: split the noise


def _brute_force(Z, beta, min_size, transitions):
    """Least penalised cost over all partitions, by enumeration."""
    n, best = len(Z), np.inf
    for r in range(n):
        for cps in itertools.combinations(range(1, n), r):
            edges = (0, *cps, n)
            if min(b - a for a, b in zip(edges[:-1], edges[1:])) < min_size:
                continue
            cost = beta * (len(edges) - 1)
            for j, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
                sse = np.sum((Z[a:b] - Z[a:b].mean(axis=0)) ** 2)
                if transitions and j > 0 and b - a > 1:
                    sse = min(sse, np.sum((Z[a + 1 : b] - Z[a + 1 : b].mean(axis=0)) ** 2))
                cost += sse
            best = min(best, cost)
    return best


@pytest.mark.parametrize("min_size,transitions", [(1, False), (2, False), (2, True), (1, True)])
def test_the_partition_is_the_exact_optimum(min_size, transitions):
    rng = np.random.default_rng(min_size + 2 * transitions)
    for _ in range(3):
        Z = rng.normal(size=(9, 2)) + np.repeat(rng.normal(scale=2, size=(3, 2)), 3, axis=0)
        beta = 1.5
        cps = change_points(Z, penalty=beta, min_size=min_size, transitions=transitions)
        edges = np.concatenate([[0], cps, [9]])
        cost = beta * (len(edges) - 1)
        for j, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
            sse = np.sum((Z[a:b] - Z[a:b].mean(axis=0)) ** 2)
            if transitions and j > 0 and b - a > 1:
                sse = min(sse, np.sum((Z[a + 1 : b] - Z[a + 1 : b].mean(axis=0)) ** 2))
            cost += sse
        assert cost == pytest.approx(_brute_force(Z, beta, min_size, transitions))


def test_noise_variances_ignore_the_jumps():
    rng = np.random.default_rng(2)
    z = rng.normal(scale=[0.5, 2.0], size=(400, 2)) + np.repeat(rng.normal(scale=20, size=(8, 2)), 50, axis=0)
    np.testing.assert_allclose(noise_variances(z), [0.25, 4.0], rtol=0.2)


def test_boundary_f1_matches_one_to_one():
    two_near_one = boundary_f1([[10]], [[8, 12]], 3)
    assert (two_near_one["tp"], two_near_one["fp"], two_near_one["fn"]) == (1, 1, 0)
    assert two_near_one["precision"] == 0.5 and two_near_one["recall"] == 1.0
    assert two_near_one["f1"] == pytest.approx(2 / 3)
    assert boundary_f1([[4, 8]], [[6, 10]], 2)["tp"] == 2  # 6 could take either; 10 only 8
    assert boundary_f1([[10]], [[14]], 3)["f1"] == 0.0 and boundary_f1([[10]], [[13]], 3)["f1"] == 1.0
    across = boundary_f1([[10], []], [[], [10]], 5)  # no matching across sequences
    assert (across["tp"], across["fp"], across["fn"]) == (0, 1, 1)
    assert boundary_f1([[], []], [[], []], 1) == {"precision": 1.0, "recall": 1.0, "f1": 1.0, "tp": 0, "fp": 0, "fn": 0}
    none_found = boundary_f1([[5]], [[]], 1)
    assert none_found["precision"] == 1.0 and none_found["recall"] == 0.0 and none_found["f1"] == 0.0
    assert boundary_f1([[]], [[5]], 1)["precision"] == 0.0


def test_boundary_f1_equals_a_maximum_matching():
    rng = np.random.default_rng(7)
    for _ in range(200):
        t = np.sort(rng.integers(0, 60, size=rng.integers(0, 7)))
        f = np.sort(rng.integers(0, 60, size=rng.integers(0, 7)))
        tol = int(rng.integers(0, 8))
        ok = (np.abs(t[:, None] - f[None, :]) <= tol).astype(int)
        best = int(ok[linear_sum_assignment(ok, maximize=True)].sum()) if ok.size else 0
        assert boundary_f1([t], [f], tol)["tp"] == best


def test_step_labelling_accuracy_ignores_padding_and_renames_ids():
    true = np.array([[0, 0, 1, 1, -1, -1], [2, 2, 2, 0, 0, -1]])
    found = np.array([[5, 5, 7, 7, 9, 9], [3, 3, 3, 5, 5, 9]])  # junk in the padding
    assert step_labelling_accuracy(true, found) == 1.0
    found[1, 3] = 7
    assert step_labelling_accuracy(true, found) == pytest.approx(8 / 9)
    lists = [np.array([5, 5, 7, 7]), np.array([3, 3, 3, 5, 5])]
    assert step_labelling_accuracy(true, lists) == 1.0  # per-sequence lists against padded rows
    assert step_labelling_accuracy(true, [np.array([5, 5, 7, -1]), lists[1]]) == pytest.approx(8 / 9)


def test_boundaries_from_segments_on_a_hand_written_array():
    seg = np.array([[0, 0, 1, 1, 1, 2, -1, -1], [0, 0, 0, -1, -1, -1, -1, -1], [3, 3, 5, 5, 5, 5, 5, 5]])
    assert [b.tolist() for b in boundaries_from_segments(seg)] == [[2, 5], [], [2]]
    assert [b.tolist() for b in boundaries_from_segments(seg, [4, 3, 8])] == [[2], [], [2]]
    assert [b.tolist() for b in boundaries_from_segments([np.array([1, 1, 0])])] == [[2]]


def test_too_few_segments_are_not_clustered_and_say_so():
    rng = np.random.default_rng(0)
    res = segment_sequences(rng.normal(size=(2, 8, 4)), W, [80, 75], 3)
    assert res.segment_labels.tolist() == [0, 1] and "only 2 segment(s) for 3 primitive(s)" in res.note


@pytest.mark.parametrize(
    "call,message",
    [
        (lambda z: segment_sequences(z, 0, [50, 50], 2), "window must be an integer >= 1"),
        (lambda z: segment_sequences(z, W, [50, 50, 50], 2), "lengths must be 2 integers"),
        (lambda z: segment_sequences(z, W, [50, 81], 2), "sequence 1: length 81 needs 9 windows"),
        (lambda z: segment_sequences(z, W, [50, 0], 2), "every length must be >= 1"),
        (lambda z: segment_sequences(z, W, [50, 50], 0), "n_primitives must be an integer >= 1"),
        (lambda z: segment_sequences(z[0], W, [50], 2), r"code sequences must be \(N, K, q\)"),
        (lambda z: segment_sequences(z, W, [50, 50], 2, penalty="bic"), "penalty must be 'auto' or"),
        (lambda z: change_points(z[0], penalty=-1.0), "penalty must be 'auto' or"),
        (lambda z: change_points(z[0], n_valid=9), "n_valid=9 is more than the 8 windows"),
        (lambda z: change_points(z[0], min_size=0), "min_size must be an integer >= 1"),
        (lambda z: boundary_f1([[1]], [[1]], -1), "tolerance must be a finite number >= 0"),
        (lambda z: boundary_f1([[1]], [[1], [2]], 1), "1 sequences of true boundaries but 2 found"),
        (lambda z: step_labelling_accuracy([np.array([0, 1])], [np.array([0, 1, 1])]), "beyond padding"),
        (lambda z: step_labelling_accuracy([np.array([-1, -1])], [np.array([0, 1])]), "no valid steps"),
        (lambda z: boundaries_from_segments(np.zeros((2, 5), int), [5]), "lengths must be 2 integers"),
    ],
)
def test_bad_arguments_raise_user_error(call, message):
    z = np.random.default_rng(0).normal(size=(2, 8, 3))
    with pytest.raises(UserError, match=message):
        call(z)


def test_non_finite_codes_are_refused_but_padding_may_hold_anything():
    z = np.random.default_rng(0).normal(size=(2, 8, 3))
    z[1, 7] = np.nan
    assert len(segment_sequences(z, W, [50, 70], 1).step_labels[1]) == 70  # window 7 is padding
    with pytest.raises(UserError, match="codes of sequence 1 are not finite"):
        segment_sequences(z, W, [50, 80], 1)


def test_identical_codes_get_one_label_and_a_note():
    from primspace.segmentation import segment_sequences

    result = segment_sequences(np.zeros((4, 6, 3)), 5, [30, 30, 25, 20], 3)
    assert all(len(b) == 0 for b in result.boundaries)
    assert all((labels == 0).all() for labels in result.step_labels)
    assert result.note is not None and "identical" in result.note


def test_a_boundary_anywhere_in_the_transition_matches_within_the_tolerance():
    from primspace.segmentation import boundary_f1

    truth = [np.array([20, 60])]
    found = [np.array([33, 55])]  # 13 steps into a 10-step transition (3 past its end); 5 before the next
    assert boundary_f1(truth, found, 4)["tp"] == 0 and boundary_f1(truth, found, 5)["tp"] == 1  # strict
    within = boundary_f1(truth, found, 4, extent=10)  # reaches [16, 34] and [56, 74]: 55 misses by one
    assert within["tp"] == 1 and boundary_f1(truth, found, 5, extent=10)["tp"] == 2
    assert boundary_f1(truth, [np.array([15])], 4, extent=10)["tp"] == 0  # before the transition's reach
    with pytest.raises(UserError, match="extent"):
        boundary_f1(truth, found, 4, extent=-1)


def test_the_composite_data_records_its_transition_steps(tmp_path):
    from primspace.data import MotionDataset
    from primspace.sim.composite import CompositeConfig, generate_composite, transition_steps

    data = generate_composite(
        CompositeConfig(n_sequences=2, max_primitives=2, duration=(31, 32), transition_steps=5),
        seed=0,
        out=tmp_path / "long.h5",
        progress=False,
    )
    assert (
        transition_steps(MotionDataset.load(data)) == 5 and transition_steps(MotionDataset.load(data).subset([1])) == 5
    )
    assert transition_steps(MotionDataset(np.zeros((1, 4, 2)))) == 0  # not made by the generator
