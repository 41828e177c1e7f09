"""Why a clustering of learned codes may score below the raw trajectories: one line for users.

Subspace clustering separates clusters whose (affine) subspaces are independent: the
low-rank representation is block-diagonal only then (Liu et al. 2013; Vidal & Favaro 2014).
``k`` affine subspaces of a ``q``-dimensional code space are independent only if their
dimensions plus one sum to at most ``q + 1``, so even ``k`` single points (dimension 0) need
``k <= q + 1``; with ``k > q + 1`` primitives the codes cannot hold them apart, however well
they were trained (LASA: 26 shapes in 8-dimensional codes cluster at 0.82-0.85 where the raw
trajectories of the same samples reach 0.97, docs/clustering.md). And with fewer samples per
primitive than ``q + 1``, a primitive's affine subspace in the codes is not determined by its
samples.
"""

from __future__ import annotations

__all__ = ["codes_note", "RAW_MARGIN"]

#: The raw trajectories must beat the codes by more than this accuracy to be reported.
RAW_MARGIN = 0.05


def codes_note(
    n_samples: int,
    n_dims: int,
    n_clusters: int,
    *,
    affine: bool = True,
    codes_accuracy: float | None = None,
    raw_accuracy: float | None = None,
) -> str | None:
    """One line saying why codes cluster worse than raw trajectories, or None.

    Said when the raw trajectories of the same samples score more than :data:`RAW_MARGIN`
    above the codes, or when the codes cannot hold the primitives apart (more primitives
    than ``q + 1``, or ``q`` without ``affine``) or have fewer samples per primitive than
    ``q + 1``; None otherwise.
    """
    room = n_dims + (1 if affine else 0)
    per = n_samples / max(n_clusters, 1)
    reasons = []
    if n_clusters > room:
        kind = "affine subspaces" if affine else "subspaces"
        reasons.append(
            f"{n_clusters} primitives in {n_dims}-dimensional codes cannot lie in independent {kind} "
            f"(at most {room} can), which the low-rank representation needs to separate them"
        )
    if per < n_dims + 1:
        reasons.append(
            f"{per:.3g} samples per primitive, fewer than the {n_dims + 1} that determine an affine subspace "
            f"of {n_dims} dimensions"
        )
    worse = codes_accuracy is not None and raw_accuracy is not None and raw_accuracy > codes_accuracy + RAW_MARGIN
    if not reasons and not worse:
        return None
    if not reasons:
        reasons.append("the codes are fitted to reconstruct the motions, not to separate primitives")
    head = (
        f"the codes cluster at accuracy {codes_accuracy:.2f}, the raw trajectories of the same {n_samples} samples "
        f"at {raw_accuracy:.2f} (same settings): "
        if worse
        else f"codes of {n_samples} samples in {n_dims} dimensions for {n_clusters} primitives: "
    )
    return "note: " + head + "; ".join(reasons) + "; cluster the data file itself for the raw trajectories"
