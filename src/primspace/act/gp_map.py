"""The scene policy's maps (:class:`~primspace.act.scene_policy.ScenePolicy`): a Gaussian process
from standardised features to standardised targets, with its exact leave-one-out residuals."""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["GaussianMap", "gaussian_process"]


def gaussian_process(seed: int):
    """A maker of scikit-learn Gaussian processes of ``n_features`` inputs: a constant times an RBF kernel
    with one length per feature, plus white noise; two restarts of the optimiser seeded by ``seed``."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    def make(n_features: int):
        kernel = ConstantKernel(1.0) * RBF(length_scale=np.ones(n_features)) + WhiteKernel(1e-2)
        return GaussianProcessRegressor(kernel, n_restarts_optimizer=2, random_state=seed)

    return make


class GaussianMap:
    """One Gaussian process from standardised features ``x`` (n, d) to standardised targets ``y`` (n, k),
    made by ``make`` (:func:`gaussian_process`); called on features, it predicts targets in their units."""

    def __init__(self, x: np.ndarray, y: np.ndarray, make):
        self.x_mean, self.x_std = x.mean(axis=0), x.std(axis=0) + 1e-9
        self.y_mean, self.y_std = y.mean(axis=0), y.std(axis=0) + 1e-6
        self.gp = make(x.shape[1])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # bounds reached by the optimiser: the fit is still used
            self.gp.fit((x - self.x_mean) / self.x_std, (y - self.y_mean) / self.y_std)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.gp.predict((np.atleast_2d(x) - self.x_mean) / self.x_std) * self.y_std + self.y_mean

    def held_out_residuals(self) -> np.ndarray:
        """(n, d) leave-one-out residuals of the fitted targets, original units: for a Gaussian
        process with kernel matrix ``K`` (noise included), ``[K⁻¹y]_i / [K⁻¹]_ii`` (exact, no refit)."""
        from scipy.linalg import solve_triangular

        inverse_l = solve_triangular(self.gp.L_, np.eye(len(self.gp.L_)), lower=True)
        diagonal = (inverse_l**2).sum(axis=0)  # diag of K⁻¹ = L⁻ᵀ L⁻¹
        alpha = self.gp.alpha_.reshape(len(diagonal), -1)
        return alpha / diagonal[:, None] * self.y_std
