"""The primitives of a run as clusters of its fitted codes, and their affine subspaces (the scene mode's prior).

The paper: codes of one primitive lie near a common affine subspace (*Clustering*, affine
low-rank subspace clustering). :func:`cluster_codes` clusters a run's fitted codes with
:class:`~primspace.cluster.LowRankSubspaceClustering` (affine), numbers the clusters by
their first member and names each by the majority label of its members (display, and a
primitive asked for by name, :meth:`SceneClusters.check`); :func:`affine_subspace` gives a
cluster's mean and principal directions, where :mod:`primspace.predict.scene` searches a code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from primspace.cluster.estimator import LowRankSubspaceClustering
from primspace.utils.errors import UserError

__all__ = ["SCENE_VARIANCE", "SceneClusters", "cluster_codes", "affine_subspace"]

#: The share of a cluster's variance its subspace keeps when no rank is given.
SCENE_VARIANCE = 0.9


@dataclass
class SceneClusters:
    """The fitted codes clustered into primitives (:func:`cluster_codes`).

    Attributes
    ----------
    labels : ndarray (N,) int
        The cluster of each fitted code (the run's fitted order), numbered by first member.
    codes : ndarray (N, K·q) float64
        The fitted codes.
    majority : list of int or None
        Per cluster, the most frequent label of its members (None without labels).
    names : list of str or None
        The majority label's name (display only).
    r2 : float
        R² of the clustering's self-representation.
    """

    labels: np.ndarray
    codes: np.ndarray
    majority: list
    names: list
    r2: float

    @property
    def n_clusters(self) -> int:
        return len(self.majority)

    @property
    def sizes(self) -> list[int]:
        return np.bincount(self.labels, minlength=self.n_clusters).astype(int).tolist()

    def check(self, primitive) -> int:
        """``primitive`` as a cluster id, or one line naming the valid range. A label name (a str,
        e.g. ``"push"``) is the cluster whose members' majority label has that name (of several,
        the largest); a str of digits that names no cluster is a cluster id."""
        k = self.n_clusters
        if isinstance(primitive, str):
            if primitive in self.names or not primitive.strip().isdigit():
                return self.named(primitive)
            primitive = int(primitive)
        if (
            isinstance(primitive, (bool, np.bool_))
            or not isinstance(primitive, (int, np.integer))
            or not 0 <= primitive < k
        ):
            raise UserError(
                f"primitive {primitive!r} is out of range: the run's fitted codes form {k} clusters, choose 0..{k - 1}"
            )
        return int(primitive)

    def named(self, name: str) -> int:
        """The cluster of the primitive called ``name`` (majority label name; of several, the largest)."""
        hits = [k for k in range(self.n_clusters) if self.names[k] == name]
        if not hits:
            known = sorted({n for n in self.names if n is not None})
            raise UserError(
                f"no cluster of the fitted codes is mostly {name!r}: "
                + (
                    f"the clusters are mostly {', '.join(map(repr, known))}"
                    if known
                    else "the fitted data has no label names; give the cluster id"
                )
            )
        return max(hits, key=lambda k: self.sizes[k])

    def subspace(self, primitive: int, rank: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Cluster ``primitive``'s affine subspace: mean (K·q,) and basis (r, K·q) (:func:`affine_subspace`)."""
        k = self.check(primitive)
        return affine_subspace(self.codes[self.labels == k], rank, where=f"cluster {k}")

    def summary(self) -> dict:
        """What ``result.json`` records of the clusters."""
        return {
            "n_clusters": self.n_clusters,
            "cluster_sizes": self.sizes,
            "cluster_names": list(self.names),
            "first_members": [int(np.flatnonzero(self.labels == k)[0]) for k in range(self.n_clusters)],
            "r2": self.r2,
        }


def cluster_codes(
    codes, n_clusters: int, labels=None, label_names=None, *, r2_target=None, random_state: int = 0
) -> SceneClusters:
    """Cluster ``codes`` (N, K·q) with :class:`~primspace.cluster.LowRankSubspaceClustering`
    (affine); ``labels`` / ``label_names`` of the same samples only name the clusters."""
    codes = np.asarray(codes, dtype=np.float64)
    if (
        isinstance(n_clusters, (bool, np.bool_))
        or not isinstance(n_clusters, (int, np.integer))
        or not 1 <= n_clusters <= len(codes)
    ):
        raise UserError(
            f"the number of clusters must be a whole number in 1..{len(codes)} (the fitted codes), got {n_clusters!r}"
        )
    model = LowRankSubspaceClustering(int(n_clusters), affine=True, r2_target=r2_target, random_state=random_state)
    raw = model.fit(codes).labels_
    order = list(dict.fromkeys(raw.tolist()))  # by first member
    order += [c for c in range(int(n_clusters)) if c not in order]
    ids = np.array([order.index(c) for c in raw], dtype=np.int64)
    majority, names = [], []
    for k in range(int(n_clusters)):
        own = None if labels is None else np.asarray(labels)[ids == k]
        own = None if own is None else own[own >= 0]
        top = None if own is None or not own.size else int(np.bincount(own).argmax())
        majority.append(top)
        names.append(
            None
            if top is None
            else (label_names[top] if label_names is not None and top < len(label_names) else str(top))
        )
    return SceneClusters(ids, codes, majority, names, float(model.r2_))


def affine_subspace(
    codes, rank: int | None = None, variance: float = SCENE_VARIANCE, *, where: str = "the cluster"
) -> tuple[np.ndarray, np.ndarray]:
    """The mean (d,) and the top ``r`` principal directions (r, d) of ``codes`` (m, d).

    ``r``: ``rank`` (0 .. min(m − 1, d)), or the fewest directions that explain at least
    ``variance`` of the variance (0 when the codes are one point).
    """
    codes = np.asarray(codes, dtype=np.float64)
    mean = codes.mean(axis=0)
    _, s, vt = np.linalg.svd(codes - mean, full_matrices=False)
    most = min(len(codes) - 1, codes.shape[1])
    if rank is None:
        total = float(np.sum(s**2))
        share = np.cumsum(s**2) / total if total > 0 else np.ones(0)
        rank = 0 if total <= 0 else int(np.searchsorted(share, variance - 1e-12) + 1)
    elif isinstance(rank, (bool, np.bool_)) or not isinstance(rank, (int, np.integer)) or not 0 <= rank <= most:
        raise UserError(
            f"rank {rank!r}: {where} has {len(codes)} codes of size {codes.shape[1]}, "
            f"its subspace spans 0..{most} directions"
        )
    return mean, vt[: int(rank)]
