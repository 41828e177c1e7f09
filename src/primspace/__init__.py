"""primspace: latent spaces of robot motion primitives.

Implements, and extends, Nikulin & Tani, *Initialization of Latent Space Coordinates
via Random Linear Projections for Learning Robotic Sensory-Motor Sequences*: an MTRNN
decoder generates joint-angle sequences and camera images from one latent code per
demonstration; codes initialised by a random linear projection of the motor sequence
keep the latent space structured, so affine low-rank subspace clustering finds the
motion primitives without labels.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("primspace")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__", "AutoDecoder"]


def __getattr__(name: str):
    """``primspace.AutoDecoder`` (:mod:`primspace.estimator`), loaded on first use: ``import
    primspace`` does not import torch."""
    if name == "AutoDecoder":
        from primspace.estimator import AutoDecoder

        return AutoDecoder
    raise AttributeError(f"module 'primspace' has no attribute {name!r}")
