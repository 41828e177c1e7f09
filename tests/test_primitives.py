"""The primitives of a run as clusters of its fitted codes (``primspace.predict.primitives``):
numbered by first member, named by their members' majority label."""

from __future__ import annotations

import numpy as np
import pytest

from primspace.predict.primitives import cluster_codes, primitives_from_clusters
from primspace.utils.errors import UserError


def _planted(seed: int = 0):
    """Three groups of 8 codes on three lines far apart (4-dimensional), in shuffled order, and their labels."""
    rng = np.random.default_rng(seed)
    groups = [c + np.outer(rng.normal(size=8), d) for c, d in zip(10 * np.eye(4)[:3], np.eye(4)[[1, 2, 3]])]
    codes, labels = np.concatenate(groups), np.repeat([2, 0, 1], 8)
    order = rng.permutation(len(codes))
    return codes[order], labels[order]


def test_clusters_are_numbered_by_first_member_and_named_by_majority_label():
    codes, labels = _planted()
    ids, majority, names = cluster_codes(codes, 3, labels, ("reach", "push", "wave"))
    assert ids.dtype == np.int64 and ids[0] == 0
    firsts = [int(np.flatnonzero(ids == k)[0]) for k in range(3)]
    assert firsts == sorted(firsts)
    for k in range(3):
        assert majority[k] == int(np.bincount(labels[ids == k]).argmax())
        assert names[k] == ("reach", "push", "wave")[majority[k]]
    assert cluster_codes(codes, 3)[1:] == ([None] * 3, [None] * 3)  # without labels: no names
    found = primitives_from_clusters(codes, 3, labels, ("reach", "push", "wave"))
    assert found.names == names and found.source == "clusters"
    with pytest.raises(UserError, match="whole number in 1..24"):
        cluster_codes(codes, 25)
