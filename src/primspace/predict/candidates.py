"""The fitted codes as a prior for prediction: a mixture over decoded candidates.

The maths of :class:`~primspace.predict.mixture.MixturePredictor` (the predictor that uses it).

Inferring a code from the beginning of a motion by gradient descent fits the observed
part and leaves the rest anywhere: nothing holds the code near the codes the decoder was
trained on (docs/predict.md, *What a first try shows*). ProMPs win that comparison by
their prior, a Gaussian over trajectories per primitive, given the labels. primspace has
its own prior without labels: the fitted codes themselves. :class:`CodeMixture` makes it a
mixture whose components are

* every fitted code ``z_i``, and
* points on the segments from each ``z_i`` towards its ``k`` nearest fitted codes (in code
  space, ``z_i + a (z_j - z_i)`` for ``a`` in :data:`SEGMENT_POINTS`, a little beyond
  both ends too): the paper's observation that codes of one primitive lie near a common
  affine subspace (*Clustering*), used without knowing which codes share a primitive,

each decoded once, ``d(θ, c)``. Given the observed entries ``x_obs`` of a new motion,
component ``c`` has the likelihood ``exp(-||x_obs - d(θ, c)_obs||² / (2σ²))`` (equal prior
weights); the prediction is the posterior mean of the decoded sequences, the optimum
for a squared error when the prefix leaves the primitive ambiguous, and the code
returned is the posterior mode.

**Ensemble conditioning** (``condition=r``, :meth:`CodeMixture.conditioned`): the
posterior-weighted candidates are also an ensemble with a mean ``μ`` and a covariance
``Σ = Σ_c w_c (d_c - μ)(d_c - μ)ᵀ``; conditioning that Gaussian on the observed entries
with an observation noise ``r`` per entry,
``μ + Σ_{·o} (Σ_oo + r I)⁻¹ (x_obs - μ_o)`` (the update of an ensemble Kalman filter, and
what ProMP conditioning does with its own Gaussian prior over trajectories), moves the
prediction *between* the candidates, along the directions in which nearby candidates
differ, instead of averaging them. It is computed in the ensemble's space (the
:data:`ENSEMBLE` candidates of largest weight): ``μ + Aᵀ (A_o A_oᵀ + r I)⁻¹ A_o (x_obs - μ_o)``
with ``A`` the weighted deviations, ``√w_c (d_c - μ)``.

``σ²`` and ``r`` (or no conditioning) are chosen without the answer: by leave-one-out
prediction of the fitted demonstrations themselves (:meth:`CodeMixture.choose_noise`).

:func:`continuity_correction` then removes the jump at the last observed step: the
residual there decays linearly to zero at the end of the motion (ProMP conditioning
passes through the observed points in the same way). It is ours, not the paper's.
"""

from __future__ import annotations

import numpy as np

from primspace.utils.errors import UserError

__all__ = [
    "condition_ensemble",
    "CodeMixture",
    "continuity_correction",
    "SEGMENT_POINTS",
    "NOISE_GRID",
    "CONDITION_GRID",
    "NEIGHBOURS",
    "ENSEMBLE",
]

#: Where the candidates sit on the segment from a fitted code to a neighbour (0: the code; 1: the neighbour).
SEGMENT_POINTS = (-0.25, 0.25, 0.5, 0.75, 1.25)
#: Nearest fitted codes each code is joined to.
NEIGHBOURS = 5
#: σ² tried by :meth:`CodeMixture.choose_noise` (scaled units, per observed entry summed).
NOISE_GRID = (1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2)
#: Observation noise ``r`` (per entry, scaled units²) of the ensemble conditioning tried by
#: :meth:`CodeMixture.choose_noise`; None: the posterior mean, not conditioned.
CONDITION_GRID = (None, 1e-4, 1e-3, 1e-2)
#: Candidates of largest posterior weight that make up a sample's conditioning ensemble.
ENSEMBLE = 256


def _sq_distances(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(n, c): Σ over the entries where ``mask`` (n, T) is set of (a_n - b_c)², for a (n, T, J), b (c, T, J)."""
    j = a.shape[2]
    m = np.repeat(mask.astype(np.float64), j, axis=1)
    af, bf = a.reshape(len(a), -1) * m, b.reshape(len(b), -1)
    return np.maximum((af**2).sum(1, keepdims=True) + m @ (bf**2).T - 2.0 * af @ bf.T, 0.0)


class CodeMixture:
    """Candidates built from a run's fitted codes and their decoded (scaled) motor sequences.

    Parameters
    ----------
    codes : ndarray (m, q)
        The fitted codes.
    decode : callable
        ``decode(Z) -> (len(Z), T, J)`` scaled motor (the run's decoder).
    neighbours : int
        Nearest fitted codes each code is joined to (capped at m - 1).
    points : sequence of float
        Positions on each segment.
    """

    def __init__(self, codes: np.ndarray, decode, neighbours: int = NEIGHBOURS, points=SEGMENT_POINTS):
        codes = np.asarray(codes, dtype=np.float64)
        if codes.ndim != 2 or len(codes) < 1:
            raise UserError(f"the mixture needs fitted codes (m, q), got shape {codes.shape}")
        k = min(int(neighbours), len(codes) - 1)
        rows, sources = [codes], [np.stack([np.arange(len(codes))] * 2, axis=1)]
        if k > 0:
            d2 = ((codes[:, None] - codes[None]) ** 2).sum(-1)
            np.fill_diagonal(d2, np.inf)
            near = np.argsort(d2, axis=1, kind="stable")[:, :k]
            for a in points:
                rows.append((codes[:, None] * (1.0 - a) + codes[near] * a).reshape(-1, codes.shape[1]))
                sources.append(np.stack([np.repeat(np.arange(len(codes)), k), near.reshape(-1)], axis=1))
        self.candidates = np.concatenate(rows)
        self.sources = np.concatenate(sources)  # (c, 2): the fitted codes each candidate is built from
        self.decoded = np.asarray(decode(self.candidates), dtype=np.float64)
        self.noise: float | None = None
        self.condition: float | None = None
        #: Choices of :meth:`choose_noise` kept by whoever asks (e.g. per observation rule), so
        #: that predictions of one rule share one leave-one-out search.
        self.choices: dict = {}

    def weights(self, scaled: np.ndarray, observed: np.ndarray, noise: float, exclude: np.ndarray | None = None):
        """(n, c) posterior weights of the candidates given the observed entries."""
        energy = _sq_distances(scaled, self.decoded, observed) / (2.0 * noise)
        if exclude is not None:
            energy = np.where(exclude, np.inf, energy)
        energy -= energy.min(axis=1, keepdims=True)
        w = np.exp(-energy)
        return w / w.sum(axis=1, keepdims=True)

    def predict(self, scaled: np.ndarray, observed: np.ndarray, noise: float | None = None, condition="chosen"):
        """Sequences (n, T, J, scaled) and posterior-mode codes (n, q): the posterior mean, or
        with ``condition=r`` the ensemble conditioned on the observed entries
        (:meth:`conditioned`). ``noise`` and ``condition`` default to the chosen ones."""
        noise = self.noise if noise is None else noise
        condition = self.condition if condition == "chosen" else condition
        if noise is None:
            raise UserError("the mixture's noise is not chosen: call choose_noise() or give noise=")
        w = self.weights(scaled, observed, noise)
        sequences = self.posterior_mean(w) if condition is None else self.conditioned(w, scaled, observed, condition)
        return sequences, self.candidates[np.argmax(w, axis=1)]

    def posterior_mean(self, w: np.ndarray) -> np.ndarray:
        """(n, T, J): the weighted mean of the decoded candidates, weights ``w`` (n, c)
        (one matrix product: ``einsum`` does not reach BLAS here)."""
        return (w @ self.decoded.reshape(len(self.decoded), -1)).reshape((len(w),) + self.decoded.shape[1:])

    def conditioned(self, w: np.ndarray, scaled: np.ndarray, observed: np.ndarray, r: float) -> np.ndarray:
        """(n, T, J): the ensemble of the :data:`ENSEMBLE` candidates of largest weight ``w``
        (n, c), conditioned on the entries of ``scaled`` (n, T, J) where ``observed`` (n, T),
        observation noise ``r`` per entry (module docstring)."""
        n, t, j = scaled.shape
        flat, x = self.decoded.reshape(len(self.decoded), -1), scaled.reshape(n, -1)
        masks = np.repeat(np.asarray(observed, dtype=bool), j, axis=1)
        k = min(ENSEMBLE, flat.shape[0])
        top = np.argpartition(-w, k - 1, axis=1)[:, :k] if k < flat.shape[0] else np.tile(np.arange(k), (n, 1))
        out = np.empty_like(x, dtype=np.float64)
        for i in range(n):
            out[i] = condition_ensemble(flat[top[i]], w[i, top[i]], x[i], masks[i], r)
        return out.reshape(n, t, j)

    def choose_noise(
        self,
        fitted_scaled: np.ndarray,
        observed: np.ndarray,
        valid: np.ndarray,
        grid=NOISE_GRID,
        conditions=CONDITION_GRID,
    ) -> dict:
        """The σ² of ``grid`` and the conditioning ``r`` of ``conditions`` (None: the posterior
        mean) whose leave-one-out prediction of the fitted demonstrations is best (each
        predicted from the candidates not built from it, then :func:`continuity_correction`);
        sets them and returns ``{"noise": σ², "condition": r, "loo": {"σ²/r": MSE}}``.

        ``fitted_scaled`` (m, T, J) are the demonstrations of the codes, ``observed`` (m, T)
        their observed steps under the rule being predicted, ``valid`` their valid steps.
        """
        m = len(fitted_scaled)
        own = np.arange(m)[:, None]
        exclude = (self.sources[None, :, 0] == own) | (self.sources[None, :, 1] == own)
        left = (valid & ~observed)[..., None]
        scores, settings = {}, {}
        for noise in grid:
            w = self.weights(fitted_scaled, observed, noise, exclude)
            for r in conditions:
                pred = self.posterior_mean(w) if r is None else self.conditioned(w, fitted_scaled, observed, r)
                pred = continuity_correction(pred, fitted_scaled, observed, valid)
                err = ((pred - fitted_scaled) ** 2 * left).sum((1, 2)) / np.maximum(left.sum((1, 2)) * pred.shape[2], 1)
                key = f"{noise:g}/{'none' if r is None else f'{r:g}'}"
                scores[key] = float(err[left.any((1, 2))].mean()) if left.any() else 0.0
                settings[key] = (float(noise), None if r is None else float(r))
        self.noise, self.condition = settings[min(scores, key=scores.get)]
        return {"noise": self.noise, "condition": self.condition, "loo": scores}


def condition_ensemble(members: np.ndarray, weights: np.ndarray, x: np.ndarray, mask: np.ndarray, r: float):
    """One sequence's ensemble ``members`` (k, D), weighted ``weights`` (k,), conditioned on the
    entries ``x[mask]`` with observation noise ``r`` per entry: ``μ + Aᵀ (A_o A_oᵀ + r I)⁻¹ A_o
    (x_o - μ_o)``, ``A`` the weighted deviations ``√w (d - μ)`` (the ensemble Kalman update;
    module docstring). Returns (D,)."""
    w = weights / weights.sum()
    mu = w @ members
    a = np.sqrt(w)[:, None] * (members - mu)
    ao = a[:, mask]
    gram = ao @ ao.T + r * np.eye(len(members))
    return mu + a.T @ np.linalg.solve(gram, ao @ (x[mask] - mu[mask]))


def continuity_correction(
    predicted: np.ndarray, scaled: np.ndarray, observed: np.ndarray, valid: np.ndarray, horizon: int | None = None
):
    """Add the residual at each sample's last observed step, decaying linearly to zero at its
    last valid step (or ``horizon`` steps after the observed one), to the unobserved steps
    (scaled units; observed steps unchanged).

    ``predicted``, ``scaled`` (n, T, J); ``observed``, ``valid`` (n, T) bool (a prefix).
    """
    out = np.array(predicted, dtype=np.float64, copy=True)
    t = np.arange(out.shape[1])
    for i in range(len(out)):
        seen = np.flatnonzero(observed[i])
        end = np.flatnonzero(valid[i])
        if not seen.size or not end.size or seen[-1] >= end[-1]:
            continue
        s, e = seen[-1], end[-1]
        ramp = np.clip(1.0 - (t - s) / (e - s if horizon is None else float(horizon)), 0.0, 1.0)
        rest = (t > s) & valid[i]
        out[i, rest] += ramp[rest, None] * (scaled[i, s] - out[i, s])
    return out
