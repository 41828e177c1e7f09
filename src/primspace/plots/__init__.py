"""Every figure primspace draws (matplotlib, Agg backend, written atomically as PNG, or
as an animated GIF by :mod:`~primspace.plots.animation`).

Functions take arrays and results (never a model or a run directory) and return a
:class:`matplotlib.figure.Figure`; :func:`save_figure` writes it and closes it. Figures
name the paper's figure they reproduce in their docstring.

- :mod:`~primspace.plots.base`: :func:`save_figure`, the colours shared by every figure.
- :mod:`~primspace.plots.samples`: one motion (frames and joints), recorded against generated.
- :mod:`~primspace.plots.clustering`: affinity and predicted labels, τ sweeps, accuracy per R².
- :mod:`~primspace.plots.training`: loss curves, the convergence figures, the latent PCA.
- :mod:`~primspace.plots.prediction`: observed, predicted and recorded joints; errors per observed fraction.
- :mod:`~primspace.plots.posterior`: the prior's posterior over primitives per observed fraction.
- :mod:`~primspace.plots.animation`: one motion as an animated GIF (Pillow), size-bounded.
"""

import matplotlib

matplotlib.use("Agg")  # headless: never needs a display; before any pyplot import below

from primspace.plots.animation import animation_frames, draw_animation, save_gif  # noqa: E402
from primspace.plots.base import INIT_COLORS, save_figure  # noqa: E402
from primspace.plots.clustering import plot_accuracy_vs_r2, plot_clustering, plot_tau_sweep  # noqa: E402
from primspace.plots.posterior import plot_posterior  # noqa: E402
from primspace.plots.prediction import plot_prediction_errors, plot_predictions  # noqa: E402
from primspace.plots.samples import (  # noqa: E402
    plot_image_strips,
    plot_motion_sample,
    plot_reconstruction,
    plot_sim_sample,
    reconstruction_title,
)
from primspace.plots.training import plot_intra_losses, plot_latent_pca, plot_loss_curves  # noqa: E402

__all__ = [
    "INIT_COLORS",
    "save_figure",
    "plot_motion_sample",
    "plot_sim_sample",
    "plot_reconstruction",
    "plot_image_strips",
    "reconstruction_title",
    "plot_predictions",
    "plot_prediction_errors",
    "plot_posterior",
    "plot_clustering",
    "plot_tau_sweep",
    "plot_accuracy_vs_r2",
    "plot_loss_curves",
    "plot_intra_losses",
    "plot_latent_pca",
    "animation_frames",
    "save_gif",
    "draw_animation",
]
