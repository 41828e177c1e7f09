"""What every figure shares: writing it, and the colours of the latent initialisations."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from primspace.utils.files import atomic_path
from primspace.utils.outputs import png_metadata

__all__ = ["save_figure", "INIT_COLORS", "init_color", "label_colors"]

# One palette for the latent initialisations, so every figure colours them alike.
INIT_COLORS = {
    "zero": "tab:blue",
    "random": "tab:red",
    "projection-vision": "tab:olive",  # before "projection": labels are matched by their start
    "projection": "tab:green",
    "pca": "tab:purple",
    "calibrated": "tab:orange",
}


def save_figure(
    fig: Figure, path: str | os.PathLike, dpi: int = 120, *, writer: str | None = None, overwrite: bool = True
) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically (creating the folder) and close it.

    ``writer`` (a command's mark, ``"primspace show"``) is stored in a PNG text chunk
    (:func:`primspace.utils.outputs.png_metadata`); ``overwrite=False`` never replaces an
    existing ``path``, even one that appears while the figure is written
    (:func:`primspace.utils.files.atomic_path`).
    """
    path = Path(path)
    try:
        with atomic_path(path, overwrite) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png", bbox_inches="tight", metadata=png_metadata(writer))
    finally:
        plt.close(fig)
    return path


def init_color(label, colors: dict | None = None):
    """The colour of a curve labelled ``label``: from ``colors``, else :data:`INIT_COLORS`
    when the label starts with an init name, else None (matplotlib's cycle)."""
    return (colors or {}).get(label) or next(
        (c for name, c in INIT_COLORS.items() if str(label).startswith(name)), None
    )


def label_colors(n: int):
    """``n`` distinct colours for cluster / primitive labels."""
    cmap = plt.get_cmap("tab10" if n <= 10 else "tab20" if n <= 20 else "turbo")
    return [cmap(i if n <= 20 else i / max(n - 1, 1)) for i in range(n)]
