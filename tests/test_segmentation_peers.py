"""The segmentation peers (ruptures change points, a Gaussian HMM) and the upper bounds (issue 27,
items 4-5), on planted piecewise sequences: seconds."""

import sys

import numpy as np
import pytest

from primspace.segmentation import boundary_f1, step_labelling_accuracy
from primspace.segmentation.bounds import (
    clustered_bound,
    segment_features,
    supervised_bound,
    true_segments,
    window_code_features,
)
from primspace.segmentation.peers import (
    PEERS,
    ChangePointPeer,
    elbow,
    label_by_clustering,
    merge_short_runs,
    resample_segment,
    run_peers,
)
from primspace.utils.errors import UserError

CENTRES = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def planted(n=6, noise=0.05, seed=0):
    """``n`` sequences of three segments of 20-30 steps, each at its label's centre plus noise;
    their boundaries, step labels and step segments (-1 padded to the longest)."""
    rng = np.random.default_rng(seed)
    seqs, bounds, labels = [], [], []
    for i in range(n):
        chain = rng.permutation(3)
        durations = rng.integers(20, 31, size=3)
        lab = np.repeat(chain, durations)
        seqs.append(CENTRES[lab] + rng.normal(scale=noise, size=(len(lab), 3)))
        bounds.append(np.cumsum(durations)[:-1])
        labels.append(lab)
    T = max(len(s) for s in seqs)
    step_labels, step_segments = np.full((n, T), -1), np.full((n, T), -1)
    for i, (lab, b) in enumerate(zip(labels, bounds)):
        step_labels[i, : len(lab)] = lab
        step_segments[i, : len(lab)] = np.searchsorted(b, np.arange(len(lab)), side="right")
    return seqs, bounds, step_labels, step_segments


def _padded(labels, T):
    out = np.full((len(labels), T), -1)
    for i, row in enumerate(labels):
        out[i, : len(row)] = row
    return out


def test_resample_elbow_and_merge_runs():
    x = np.arange(11.0)[:, None] * np.array([[1.0, -2.0]])
    np.testing.assert_allclose(resample_segment(x, 3), [[0, 0], [5, -10], [10, -20]])
    assert resample_segment(x[:1], 4).shape == (4, 2)
    assert elbow([10.0, 2.0, 1.5, 1.2, 1.0]) == 1 and elbow([1.0, 1.0, 1.0]) == 0 and elbow([5.0, 1.0]) == 0
    np.testing.assert_array_equal(merge_short_runs([0, 0, 0, 1, 0, 0, 2, 2, 2], 3), [0] * 6 + [2] * 3)
    np.testing.assert_array_equal(merge_short_runs([1, 0, 0, 0, 0], 2), [0] * 5)  # a short first run joins the next
    np.testing.assert_array_equal(merge_short_runs([3, 3], 5), [3, 3])


def test_change_point_peer_rules_are_checked():
    with pytest.raises(UserError, match="rule"):
        ChangePointPeer("dynp", "l2", "bic")
    with pytest.raises(UserError, match="unknown"):
        ChangePointPeer("pelt", "cosine", "noise")
    with pytest.raises(UserError, match="true number"):
        ChangePointPeer("dynp", "l2", "count").boundaries([np.zeros((30, 2))], 8)


def test_clustering_labels_planted_segments():
    seqs, bounds, step_labels, _ = planted()
    labels, note = label_by_clustering(seqs, bounds, 3)
    assert note is None and step_labelling_accuracy(step_labels, _padded(labels, step_labels.shape[1])) == 1.0


@pytest.mark.parametrize("name", [n for n in PEERS if n != "hmm-full"])
def test_change_point_peers_find_planted_boundaries(name):
    pytest.importorskip("ruptures")
    seqs, bounds, step_labels, _ = planted()
    result = PEERS[name].run(seqs, 3, window=8, true_counts=[len(b) for b in bounds])
    assert boundary_f1(bounds, result.boundaries, 8)["f1"] >= 0.9, result.boundaries
    assert step_labelling_accuracy(step_labels, _padded(result.step_labels, step_labels.shape[1])) >= 0.9


def test_hmm_peer_finds_planted_boundaries_and_labels():
    pytest.importorskip("hmmlearn")
    seqs, bounds, step_labels, _ = planted()
    result = PEERS["hmm-full"].run(seqs, 3, window=8, random_state=0)
    assert boundary_f1(bounds, result.boundaries, 8)["f1"] >= 0.9
    assert step_labelling_accuracy(step_labels, _padded(result.step_labels, step_labels.shape[1])) >= 0.95
    again = PEERS["hmm-full"].run(seqs, 3, window=8, random_state=0)
    assert all(np.array_equal(a, b) for a, b in zip(result.step_labels, again.step_labels))  # seeded


def test_a_missing_package_is_reported_not_raised(monkeypatch):
    monkeypatch.setitem(sys.modules, "ruptures", None)  # import fails
    monkeypatch.setitem(sys.modules, "hmmlearn", None)
    monkeypatch.setitem(sys.modules, "hmmlearn.hmm", None)
    seqs, bounds, _, _ = planted(n=2)
    found, missing = run_peers(seqs, 3, 8, names=["pelt-l2-noise", "hmm-full", "dynp-l2-count"])
    assert not found and set(missing) == {"pelt-l2-noise", "hmm-full", "dynp-l2-count"}
    assert "primspace[eval]" in missing["pelt-l2-noise"] and "true number" in missing["dynp-l2-count"]


def test_true_segments_and_their_features():
    seqs, bounds, step_labels, step_segments = planted(n=3)
    lengths = np.array([len(s) for s in seqs])
    segs = true_segments(step_segments, step_labels, lengths)
    assert len(segs) == 9 and list(segs.position) == [0, 1, 2] * 3
    np.testing.assert_array_equal(segs.start[1:3], bounds[0])
    assert (segs.label == step_labels[segs.sample, segs.start]).all()
    raw, rel = segment_features(seqs, segs, "raw", 5), segment_features(seqs, segs, "relative", 5)
    assert raw.shape == (9, 15) and np.allclose(rel[:, :3], 0)
    codes = [np.repeat(s[::8][:, :2], 1, axis=0) for s in seqs]  # one "code" per window of 8 steps
    assert window_code_features(codes, segs, 8).shape == (9, 2)
    assert window_code_features(codes, segs, 8, n_windows=3).shape == (9, 6)
    with pytest.raises(UserError):
        segment_features(seqs, segs, "velocity")


def test_supervised_bound_separates_separable_segments_and_not_noise():
    seqs, _, step_labels, step_segments = planted(n=8)
    segs = true_segments(step_segments, step_labels, np.array([len(s) for s in seqs]))
    feats = segment_features(seqs, segs)
    bound = supervised_bound(feats, segs, 3, random_state=0)
    for name in ("logistic", "nearest"):
        assert bound[name]["accuracy"] == 1.0 and bound[name]["first"] == 1.0 and bound[name]["later"] == 1.0
        assert np.trace(bound[name]["confusion"]) == len(segs) and bound[name]["recall"] == [1.0, 1.0, 1.0]
    noise = np.random.default_rng(1).normal(size=feats.shape)
    assert supervised_bound(noise, segs, 3, random_state=0)["logistic"]["accuracy"] < 0.8
    assert clustered_bound(feats, segs, step_labels, 3) == 1.0
    one = true_segments(step_segments[:1], step_labels[:1], [len(seqs[0])])  # one segment per primitive: no split
    assert supervised_bound(feats[:3], one, 3) is None


def test_every_peer_is_described_for_the_tables():
    from primspace.results.composite import PEER_RULES

    assert list(PEER_RULES) == list(PEERS)
