"""The prior predictor online: each primitive's Gaussian filtered as the steps arrive.

:meth:`primspace.predict.prior.PriorPredictor.stream` prepares a :class:`PriorStream` (the gains
of :class:`~primspace.predict.code_prior.StepGains` before the first step); the loop is the one
of :func:`primspace.predict.stream.follow`.
"""

from __future__ import annotations

import numpy as np

from primspace.predict.candidates import continuity_correction
from primspace.predict.code_prior import SequentialGaussian, StepGains
from primspace.predict.metrics import valid_mask
from primspace.predict.stream import Stream

__all__ = ["PriorStream"]


class PriorStream(Stream):
    """Each primitive's Gaussian filtered as the steps arrive
    (:class:`~primspace.predict.code_prior.SequentialGaussian`, its gains computed before the
    first step), the posterior over primitives (or the one given), the mixture and the correction."""

    def __init__(self, predictor, truth, lengths, ids, r: float, weight: float, temperature, start: int):
        self.predictor, self.truth, self.lengths, self.ids, self.temperature = (
            predictor,
            truth,
            lengths,
            ids,
            temperature,
        )
        self.scaler, self.init = predictor.run_.scaler, predictor.name
        length, joints = truth.shape[1:]
        self.valid = valid_mask(lengths, length)
        self.count = predictor.primitives_.count
        wanted = sorted(set(ids.tolist())) if ids is not None else range(self.count)
        self.groups = {int(v): np.flatnonzero(lengths == v) for v in np.unique(lengths)}
        gains = {k: StepGains(predictor.blended(weight)[k], r, joints, length) for k in wanted}
        self.filters = {(v, k): SequentialGaussian(gains[k], len(g)) for v, g in self.groups.items() for k in wanted}
        self.size = predictor.ensembles_[0].mean.shape[0]
        for t in range(1, start):  # the steps before the first arrival
            self._observe(t)

    def _observe(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        """(n, P, D) conditioned means and (n, P) evidences after step ``t``."""
        n = len(self.truth)
        means, evidence = np.zeros((n, self.count, self.size)), np.full((n, self.count), -np.inf)
        for (v, k), f in self.filters.items():
            if t <= v:
                f.observe(t - 1, self.truth[self.groups[v], t - 1])
            means[self.groups[v], k], evidence[self.groups[v], k] = f.means, f.evidence
        return means, evidence

    def arrive(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        means, evidence = self._observe(t)
        p = self.predictor
        ids = self.ids
        weights = np.eye(self.count)[ids] if ids is not None else p.posterior_weights(evidence, self.temperature)
        out, codes = p.mix(means, weights, self.truth.shape)
        if p.continuity:
            mask = np.arange(self.truth.shape[1])[None, :] < np.minimum(self.lengths, t)[:, None]
            out = continuity_correction(out, np.where(mask[..., None], self.truth, 0.0), mask, self.valid)
        return out, codes
