"""The primitive as an input (docs/predict.md): the prior's posterior over primitives
against the observed fraction of each motion (``posterior.png`` of ``primspace predict``).

The paper has no such figure: it names a primitive's cluster only after the whole
demonstration has been fitted.
"""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from primspace.plots.base import label_colors

__all__ = ["plot_posterior"]


def plot_posterior(
    fractions: Sequence[float],
    posterior: np.ndarray,
    names: Sequence[str],
    *,
    labels=None,
    label_names: Sequence[str] | None = None,
    title: str = "",
) -> Figure:
    """The posterior over primitives against the observed fraction of each motion.

    With ``labels``: one panel per true label (its name from ``label_names``), one line per
    primitive, the mean posterior of that primitive over the motions of that label. Without:
    one panel, one line per primitive, the mean posterior of each motion's top primitive (the
    most probable after the last fraction) over the motions whose top primitive it is.

    Parameters
    ----------
    fractions : sequence of float (F,)
        The observed fractions of the motions' valid steps.
    posterior : ndarray (F, n, P)
        The posterior over the P primitives of each of n motions after each fraction.
    names : sequence of str (P,)
        The primitives' names.
    labels : array-like (n,) int, optional
        Each motion's label (-1: none; motions without one are left out).
    """
    posterior = np.asarray(posterior, dtype=np.float64)
    colors = label_colors(len(names))
    panels = _panels(posterior, labels, label_names)
    cols = min(len(panels), 4)
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.6 * rows), squeeze=False, sharey=True)
    for ax, (heading, members, own) in zip(axes.ravel(), panels):
        for k, name in enumerate(names):
            chosen = members if own is None else members[own[members] == k]
            if chosen.size == 0 or (own is None and posterior[:, chosen, k].max() < 0.02):
                continue  # a primitive that never carries weight for these motions is left out
            mean = posterior[:, chosen, k].mean(axis=1)
            tag = name if own is None else f"{name} (n={chosen.size})"
            ax.plot(fractions, mean, marker="o", ms=3, lw=1.2, color=colors[k], label=tag)
        ax.set_title(heading, fontsize=8)
        ax.set_ylim(-0.02, 1.02)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, loc="best")
    for ax in axes.ravel()[len(panels) :]:
        ax.axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("observed fraction of the motion", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("posterior" if labels is not None else "posterior of the top primitive", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


def _panels(posterior: np.ndarray, labels, label_names) -> list:
    """``(heading, motions, top)`` per panel: one per label present, or one for every motion with
    ``top`` each motion's top primitive after the last fraction."""
    n = posterior.shape[1]
    if labels is None or not (np.asarray(labels) >= 0).any():
        return [("every motion, by its top primitive", np.arange(n), posterior[-1].argmax(axis=1))]
    labels = np.asarray(labels)
    panels = []
    for label in np.unique(labels[labels >= 0]):
        named = label_names is not None and 0 <= label < len(label_names)
        heading = f"label {label_names[label] if named else int(label)}"
        members = np.flatnonzero(labels == label)
        panels.append((f"{heading} (n={members.size})", members, None))
    return panels
