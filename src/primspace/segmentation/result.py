"""What a segmentation of long demonstrations finds, whatever the method: its segments,
boundaries and labels (:class:`SegmentationResult`), and the labels given to segment codes by
the paper's tool, affine subspace clustering (:func:`label_segments`). The paper
(shared/paper.tex, Summary and Discussion, verbatim): "Moreover, these manifolds are close
enough to affine subspaces, which enables us to use subspace clustering algorithm for
labeling a collection of motion in unsupervised manner." (the manifolds: those of one
primitive's motions in trajectory space)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from primspace.cluster import LowRankSubspaceClustering
from primspace.utils.errors import UserError

__all__ = ["SEGMENT_R2_TARGET", "SegmentationResult", "label_segments"]

#: R^2 target of the affine subspace clustering of segment codes.
SEGMENT_R2_TARGET = "auto"


@dataclass
class SegmentationResult:
    """Segments of every sequence, their codes and labels. ``S`` segments in all, ordered by
    sequence then time.

    Attributes
    ----------
    boundaries : list of ndarray of int64
        Per sequence, the ascending steps where a segment starts (``k * window`` for a change
        point at window ``k``, inside window ``k`` after a transition window).
    step_labels : list of ndarray of int64
        Per sequence, the label of each of its ``lengths[i]`` valid steps.
    segment_codes : ndarray (S, q)
        Mean of each segment's fitted window codes.
    segment_sample, segment_start, segment_stop, segment_labels : ndarray (S,) of int64
        Sequence, steps ``[start, stop)`` and label (``0..n_primitives-1``) of each segment.
    change_points, transitions : list of ndarray
        Per sequence, the windows ``k >= 1`` where a segment starts, and whether window ``k``
        is a transition (left out of the segment's fit).
    penalties : ndarray (N,)
        Penalty used per sequence.
    window : int
    note : str or None
        Set when there were too few segments to cluster: each segment is then its own label.
    segment_templates : ndarray (S,) of int64 or None
        Synthesis and surprise: the template (decoded fitted code) nearest each segment,
        whose code ``segment_codes`` holds unless the codes were inferred.
    chosen : dict
        What the method chose without labels (synthesis and surprise: the ``offset`` model;
        surprise: its ``threshold``).
    """

    boundaries: list[np.ndarray]
    step_labels: list[np.ndarray]
    segment_codes: np.ndarray
    segment_sample: np.ndarray
    segment_start: np.ndarray
    segment_stop: np.ndarray
    segment_labels: np.ndarray
    change_points: list[np.ndarray] = field(default_factory=list)
    transitions: list[np.ndarray] = field(default_factory=list)
    penalties: np.ndarray = field(default_factory=lambda: np.zeros(0))
    window: int = 1
    note: str | None = None
    segment_templates: np.ndarray | None = None
    chosen: dict = field(default_factory=dict)

    def padded_step_labels(self, n_steps: int) -> np.ndarray:
        """Step labels as one (N, n_steps) int32 array with -1 at padding, like a data set's."""
        longest = max((len(s) for s in self.step_labels), default=0)
        if n_steps < longest:
            raise UserError(f"n_steps={n_steps} is shorter than the longest sequence ({longest} steps)")
        out = np.full((len(self.step_labels), n_steps), -1, dtype=np.int32)
        for i, labels in enumerate(self.step_labels):
            out[i, : len(labels)] = labels
        return out


def label_segments(codes, n_primitives: int, r2_target=SEGMENT_R2_TARGET, random_state=0):
    """Cluster labels of segment codes (affine LRSC), and a note when there is nothing to
    cluster (too few segments, or all codes identical; the note says which)."""
    n = len(codes)
    if n <= n_primitives:
        note = f"only {n} segment(s) for {n_primitives} primitive(s): not clustered, each segment is its own label"
        return np.arange(n, dtype=np.int64), note
    distinct = len(np.unique(np.round(codes, 12), axis=0))
    if distinct < 2:  # e.g. untrained zero codes: there is nothing to tell apart
        return np.zeros(n, dtype=np.int64), f"all {n} segment codes are identical: one label"
    model = LowRankSubspaceClustering(n_primitives, affine=True, r2_target=r2_target, random_state=random_state)
    return model.fit(codes).labels_.astype(np.int64), None
