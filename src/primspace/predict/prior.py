"""A prior in code space per primitive, given the primitive (issue 39, its first piece).

The paper observes that codes of one primitive lie near a common affine subspace
(*Clustering*). :class:`GaussianCodePrior` makes that a distribution: for each primitive
(a label of the fitted demonstrations), a Gaussian over its fitted codes (their mean and
full covariance, shrunk towards a multiple of the identity so that a primitive with fewer
codes than dimensions still has one). ``n_samples`` codes are drawn from it once, in
:meth:`GaussianCodePrior.fit`, and decoded once; a new motion asked to be primitive ``k``
is predicted by that decoded ensemble conditioned on its observed entries
(:func:`~primspace.predict.candidates.condition_ensemble`, the ensemble Kalman update that
ProMP conditioning also is, with its own Gaussian over trajectories), then the continuity
correction. The code returned is the drawn code whose decoded motion is nearest the
prediction.

Unlike :class:`~primspace.predict.mixture.MixturePredictor` (candidates at and between the
fitted codes, all primitives, weighted by the prefix), the prior is continuous and is
given the primitive, as ProMP-with-labels is. Measuring it against ProMP-with-labels on the
paper preset, and the observation noise's choice, are issue 39's work still to do.
"""

from __future__ import annotations

import numpy as np

from primspace.errors import UserError
from primspace.predict.base import Forecast, Predictor, observed_mask
from primspace.predict.candidates import condition_ensemble, continuity_correction
from primspace.predict.metrics import check_labels, check_lengths, check_motor, valid_mask
from primspace.train.api import as_run, reconstruct

__all__ = ["GaussianCodePrior"]


class GaussianCodePrior(Predictor):
    """A Gaussian over each primitive's fitted codes, its draws decoded and conditioned (module docstring).

    Parameters
    ----------
    run : TrainedRun or path-like
        The trained run (θ frozen; not changed).
    n_samples : int
        Codes drawn per primitive (the ensemble's size).
    noise : float
        Observation noise ``r`` per observed entry (scaled units²) of the conditioning.
    shrinkage : float
        The covariance is ``(1 - s) C + s (tr C / d) I``: ``s`` in [0, 1].
    continuity : bool
        Apply the continuity correction after conditioning.
    random_state : int, optional
        Seed of the draws (default: the run's seed).
    """

    needs_labels = True

    def __init__(
        self,
        run,
        n_samples: int = 2000,
        noise: float = 1e-4,
        shrinkage: float = 0.05,
        continuity: bool = True,
        random_state: int | None = None,
    ):
        self.run = run
        self.n_samples = n_samples
        self.noise = noise
        self.shrinkage = shrinkage
        self.continuity = continuity
        self.random_state = random_state

    def fit(self, motor=None, labels=None, lengths=None, frames=None) -> "GaussianCodePrior":
        """Draw and decode ``n_samples`` codes per primitive of ``labels`` (the fitted
        demonstrations' labels, in the run's order; ``motor`` is not read)."""
        run = self.run_ = as_run(self.run)
        codes = np.asarray(run.latents, dtype=np.float64)
        labels = check_labels(labels, len(codes))
        if labels is None:
            raise UserError("a prior per primitive needs the labels of the run's fitted demonstrations")
        if not (isinstance(self.n_samples, (int, np.integer)) and self.n_samples >= 2):
            raise UserError(f"n_samples must be a whole number >= 2, got {self.n_samples!r}")
        if not (0.0 <= float(self.shrinkage) <= 1.0) or not float(self.noise) > 0:
            raise UserError(f"shrinkage must be in [0, 1] and noise > 0, got {self.shrinkage} and {self.noise}")
        seed = int(run.train_config.seed) if self.random_state is None else int(self.random_state)
        rng = np.random.default_rng([seed, 39])
        self.means_, self.codes_, self.decoded_ = {}, {}, {}
        for label in np.unique(labels[labels >= 0]):
            own = codes[labels == label]
            mean, cov = own.mean(axis=0), np.atleast_2d(np.cov(own, rowvar=False)) if len(own) > 1 else None
            if cov is None:
                cov = np.zeros((codes.shape[1], codes.shape[1]))
            s = float(self.shrinkage)
            cov = (1.0 - s) * cov + s * (np.trace(cov) / len(mean) + 1e-12) * np.eye(len(mean))
            drawn = rng.multivariate_normal(mean, cov, size=int(self.n_samples), method="eigh")
            decoded = run.scaler.transform(reconstruct(run, drawn.astype(np.float32), images=False, batch_size=1024)[0])
            self.means_[int(label)], self.codes_[int(label)], self.decoded_[int(label)] = mean, drawn, decoded
        return self

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None) -> Forecast:
        """Each motion as the primitive ``labels[i]`` asks for (scaled units), and its code."""
        motor = check_motor(motor)
        n, steps, joints = motor.shape
        labels = check_labels(labels, n)
        if labels is None:
            raise UserError("a prior per primitive is given each motion's primitive: pass labels")
        unknown = sorted(set(labels.tolist()) - set(self.decoded_))
        if unknown:
            raise UserError(f"label(s) {unknown} have no fitted demonstration")
        mask = observed_mask(observed, lengths, (n, steps))
        seen = np.where(mask[..., None], motor, 0.0)
        out, codes = np.empty_like(seen), np.empty((n, self.run_.latents.shape[1]), dtype=np.float32)
        for i, label in enumerate(labels.tolist()):
            decoded = self.decoded_[label].reshape(int(self.n_samples), -1)
            flat_mask = np.repeat(mask[i], joints)
            weights = np.ones(len(decoded))
            out[i] = condition_ensemble(decoded, weights, seen[i].reshape(-1), flat_mask, float(self.noise)).reshape(
                steps, joints
            )
            codes[i] = self.codes_[label][np.argmin(((decoded - out[i].reshape(-1)) ** 2).sum(axis=1))]
        if self.continuity:
            out = continuity_correction(out, seen, mask, valid_mask(check_lengths(lengths, n, steps), steps))
        return Forecast(out, codes, {"prior": {"n_samples": int(self.n_samples), "noise": float(self.noise)}})
