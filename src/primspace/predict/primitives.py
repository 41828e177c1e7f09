"""The primitives of a run: which of its fitted codes make each one, and their names.

A primitive is either a label of the fitted demonstrations (when the user has labels) or a
cluster of the fitted codes found without labels, by the paper's affine low-rank subspace
clustering (:func:`cluster_codes`). :class:`Primitives`
keeps the assignment of every fitted code and a name per primitive, and turns what a user
asks for (a name such as ``"push"``, or an id) into a primitive, with one line naming
those available when it names none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from primspace.utils.errors import UserError
from primspace.utils.seeds import library_seed

__all__ = [
    "Primitives",
    "primitives_from_labels",
    "primitives_from_clusters",
    "cluster_codes",
    "PRIMITIVE_SOURCES",
    "top1_accuracy",
]

#: Where the primitives come from.
PRIMITIVE_SOURCES = ("labels", "clusters")


@dataclass
class Primitives:
    """The fitted codes grouped into primitives.

    Attributes
    ----------
    assignment : ndarray (m,) int
        The primitive of each fitted code (the run's order), ``0..P-1``; -1: none.
    names : list of str
        Each primitive's name (a label name, the label as text, or ``"cluster k"``).
    labels : list of int or None
        The label each primitive stands for (itself for labels; a cluster's majority label).
    source : str
        ``labels`` or ``clusters``.
    """

    assignment: np.ndarray
    names: list
    labels: list
    source: str

    @property
    def count(self) -> int:
        return len(self.names)

    def members(self, k: int) -> np.ndarray:
        """The fitted codes' indices of primitive ``k``."""
        return np.flatnonzero(self.assignment == k)

    def available(self) -> str:
        """The primitives a user may name, for an error line."""
        return ", ".join(f"{k} ({name})" for k, name in enumerate(self.names))

    def resolve(self, primitive) -> int:
        """``primitive`` (a name, or an id as int or digits) as an id, or one UserError listing them."""
        if isinstance(primitive, str):
            named = [k for k, name in enumerate(self.names) if name == primitive]
            if len(named) > 1:
                ids = ", ".join(str(k) for k in named[:-1]) + f" and {named[-1]}"
                raise UserError(
                    f"{primitive!r} names primitives {ids}: give the id of the one meant ({self.available()})"
                )
            if named:
                return named[0]
            if primitive.strip().isdigit():
                primitive = int(primitive)
            else:
                raise UserError(f"unknown primitive {primitive!r}: the run's primitives are {self.available()}")
        if isinstance(primitive, (bool, np.bool_)) or not isinstance(primitive, (int, np.integer)):
            raise UserError(f"a primitive is a name or an id, got {primitive!r}: {self.available()}")
        if not 0 <= int(primitive) < self.count:
            raise UserError(f"primitive {int(primitive)} is out of range: the run's primitives are {self.available()}")
        return int(primitive)

    def for_labels(self, labels) -> np.ndarray:
        """The primitive that stands for each of ``labels`` (n,) (for clusters: the largest cluster
        whose majority label it is), or one UserError naming a label that none stands for."""
        labels = np.asarray(labels, dtype=np.int64)
        sizes = np.bincount(self.assignment[self.assignment >= 0], minlength=self.count)
        table = {}
        for k, label in enumerate(self.labels):
            if label is not None and (label not in table or sizes[k] > sizes[table[label]]):
                table[label] = k
        missing = sorted(set(labels.tolist()) - set(table))
        if missing:
            raise UserError(f"label(s) {missing} stand for no primitive of the run: {self.available()}")
        return np.array([table[int(v)] for v in labels], dtype=np.int64)

    def summary(self) -> dict:
        """What ``result.json`` records."""
        return {
            "source": self.source,
            "names": list(self.names),
            "labels": [None if v is None else int(v) for v in self.labels],
            "sizes": [int((self.assignment == k).sum()) for k in range(self.count)],
        }


def _name(label: int, label_names) -> str:
    return label_names[label] if label_names is not None and 0 <= label < len(label_names) else str(label)


def primitives_from_labels(labels, label_names=None) -> Primitives:
    """One primitive per label present (``labels`` (m,) int; -1: none), in label order."""
    if labels is None:
        raise UserError(
            "the fitted data has no labels: choose the primitives as clusters of the codes (primitives='clusters')"
        )
    labels = np.asarray(labels, dtype=np.int64)
    present = [int(v) for v in np.unique(labels[labels >= 0])]
    if not present:
        raise UserError("the fitted data's labels are all -1 (none): choose primitives='clusters'")
    ids = np.array([present.index(int(v)) if v >= 0 else -1 for v in labels], dtype=np.int64)
    return Primitives(ids, [_name(v, label_names) for v in present], present, "labels")


def primitives_from_clusters(codes, n_clusters: int, labels=None, label_names=None, random_state: int = 0):
    """The fitted ``codes`` clustered into ``n_clusters`` affine subspaces (labels, when given,
    only name them: a cluster is called by its members' majority label, ``"cluster k"`` without)."""
    assignment, majority, majority_names = cluster_codes(codes, n_clusters, labels, label_names, random_state)
    names = [f"cluster {k}" if n is None else str(n) for k, n in enumerate(majority_names)]
    seen: dict = {}
    for k, n in enumerate(names):  # two clusters of one majority label get distinct names
        seen[n] = seen.get(n, 0) + 1
        if seen[n] > 1:
            names[k] = f"{n} ({seen[n]})"
    return Primitives(assignment, names, majority, "clusters")


def cluster_codes(codes, n_clusters: int, labels=None, label_names=None, random_state: int = 0):
    """Cluster ``codes`` (N, K·q) with :class:`~primspace.cluster.LowRankSubspaceClustering`
    (affine): the cluster of each code (N,) int64, numbered by first member; per cluster, the
    majority label of its members and that label's name (None without labels), which only name it."""
    from primspace.cluster.estimator import DEFAULT_R2_TARGET, LowRankSubspaceClustering

    codes = np.asarray(codes, dtype=np.float64)
    if (
        isinstance(n_clusters, (bool, np.bool_))
        or not isinstance(n_clusters, (int, np.integer))
        or not 1 <= n_clusters <= len(codes)
    ):
        raise UserError(
            f"the number of clusters must be a whole number in 1..{len(codes)} (the fitted codes), got {n_clusters!r}"
        )
    seed = None if random_state is None else library_seed(random_state, "random_state")  # sklearn takes 0..2**32-1
    model = LowRankSubspaceClustering(int(n_clusters), affine=True, r2_target=DEFAULT_R2_TARGET, random_state=seed)
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
        names.append(None if top is None else _name(top, label_names))
    return ids, majority, names


def top1_accuracy(posterior, stands_for, labels) -> float | None:
    """Share of the labelled samples (``labels`` >= 0) whose most probable primitive (``posterior``
    (n, P)) stands for their label (``stands_for``: the label of each primitive, None for none);
    None without labels."""
    if labels is None:
        return None
    labels = np.asarray(labels)
    scored = labels >= 0
    if not scored.any():
        return None
    table = np.array([-2 if v is None else int(v) for v in stands_for])
    top = np.asarray(posterior).argmax(axis=1)
    return float(np.mean(table[top[scored]] == labels[scored]))
