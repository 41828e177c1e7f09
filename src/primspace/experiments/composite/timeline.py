"""The composite experiment's timeline arrays: how many held-out demonstrations the figures
show, and their found boundaries as one array (written by
:mod:`~primspace.experiments.composite.experiment` and
:mod:`~primspace.experiments.composite.primitives`)."""

from __future__ import annotations

import numpy as np

__all__ = ["TIMELINE_SAMPLES", "padded_boundaries"]

#: Held-out demonstrations shown in the timeline figure.
TIMELINE_SAMPLES = 4


def padded_boundaries(boundaries: list[np.ndarray]) -> np.ndarray:
    """Ragged boundary lists as one (n, m) int array, -1 padded."""
    width = max((len(b) for b in boundaries), default=0)
    out = np.full((len(boundaries), max(width, 1)), -1, dtype=np.int64)
    for i, b in enumerate(boundaries):
        out[i, : len(b)] = b
    return out
