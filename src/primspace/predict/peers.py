"""The peers that primspace's motion prediction is measured against.

Each is a :class:`~primspace.predict.base.Predictor` (the one surface of every predictor):
fitted on motor arrays ``(n, T, J)`` (already scaled by the caller, e.g. to [-1, 1]) with
optional ``lengths`` (steps at and after a sample's length are padding: absent) and
integer ``labels`` (its primitive), it returns the whole predicted sequence
``(n_test, T, J)``, the observed part included. A peer's ``predict`` reads the observed
steps of ``motor`` only: the unobserved ones are set to zero before anything looks at them
(they may even be NaN). Frames are not read.

* :class:`ProMPPeer`: a Probabilistic Movement Primitive (the maintained
  ``movement-primitives`` package, extra ``predict``), one per primitive (``per_label``:
  it is given the test sample's true label) or one for all; its weight distribution is
  conditioned on every observed step.
* :class:`NearestPeer`: the fitted demonstration nearest on the observed steps, whole.
* :class:`MeanMotionPeer`: the mean motion of the sample's primitive (or of all).
* :func:`best_noise`: the ProMP's observation noise chosen *on the answer*.
* :class:`LabelledPeer`: what the peers share (the checks, label groups; the scene peers of
  :mod:`primspace.act.scene_peers` derive from it too), and :func:`phase`.

The error of a prediction is :func:`primspace.predict.metrics.unobserved_mse`, for the
peers and primspace's predictors alike.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from primspace.predict.base import MotionPredictor, observed_mask
from primspace.predict.metrics import check_labels, check_lengths, check_motor, unobserved_mse, valid_mask
from primspace.utils.errors import UserError

__all__ = [
    "ProMPPeer",
    "NearestPeer",
    "MeanMotionPeer",
    "NoiseChoice",
    "best_noise",
    "LabelledPeer",
    "phase",
    "promp_class",
    "imitate_promp",
]

_PROMP_MISSING = "the ProMP peer needs the movement-primitives package: pip install 'primspace[predict]'"


def promp_class():
    """The package's ``ProMP`` class, imported on first use."""
    try:
        from movement_primitives.promp import ProMP
    except ImportError as exc:
        raise UserError(_PROMP_MISSING) from exc
    return ProMP


def phase(length: int) -> np.ndarray:
    """Phase in [0, 1] over ``length`` valid steps (a fresh array: the package divides in place)."""
    return np.linspace(0.0, 1.0, int(length))


#: The temporal-difference factor of the ProMP's EM (``gamma`` of ``ProMP.imitate``).
_EM_GAMMA = 0.7


def imitate_promp(n_dims: int, n_basis: int, demos: Sequence[np.ndarray], n_iter: int = 1000, min_delta: float = 1e-5):
    """The package's ``ProMP`` learned from ``demos`` (each ``(steps, n_dims)`` over phase [0, 1])
    by the EM of ``ProMP.imitate`` (movement-primitives 0.9: Lazaric & Ghavamzadeh 2010, Sec. 3.2,
    with its variance update and stopping rule), computed once per demonstration length.

    ``imitate`` takes three pseudo-inverses of a ``(n_dims·n_basis)²`` matrix per demonstration
    and iteration; but a demonstration's E-step covariance depends only on its time grid, so
    demonstrations of one length share it. Here each iteration takes one pseudo-inverse per
    distinct length (plus one of the weight covariance) and the per-demonstration means in one
    product: the same updates (equal to ``imitate``'s up to rounding, pinned by a test), about
    ``3 x demonstrations / lengths`` times fewer factorisations (a K-fold over 343 paper
    demonstrations at 40 basis functions: hours to seconds). Returns the fitted ``ProMP``.
    """
    promp = promp_class()(int(n_dims), int(n_basis))
    lengths = np.array([len(y) for y in demos])
    order = np.argsort(lengths, kind="stable")
    demos = [np.asarray(demos[i], dtype=np.float64) for i in order]
    sizes = np.unique(lengths[order], return_counts=True)
    grams, rhs, energies = [], [], []
    start = 0
    for steps, count in zip(*sizes):
        diff = np.eye(steps) - _EM_GAMMA * np.eye(steps, k=1)  # H of imitate, per joint
        basis_diff = promp._rbfs_1d_sequence(phase(steps)) @ diff.T  # (n_basis, steps)
        grams.append(np.kron(np.eye(promp.n_dims), basis_diff @ basis_diff.T))
        for y in demos[start : start + count]:
            residual = diff @ y  # (steps, n_dims): R of imitate, step-major
            rhs.append((basis_diff @ residual).T.ravel())  # joint-major, as the weights
            energies.append(float(np.sum(residual**2)))
        start += count
    rhs, counts = np.asarray(rhs), sizes[1]
    bounds = np.concatenate([[0], np.cumsum(counts)])
    n_samples, total_energy = int(lengths.sum()), float(np.sum(energies))
    promp.variance = 1.0
    means = np.zeros((len(demos), promp.n_weights))
    for _ in range(int(n_iter)):
        previous = promp.weight_mean
        precision = np.linalg.pinv(promp.weight_cov)
        prior = precision @ promp.weight_mean
        covs = []
        for g, gram in enumerate(grams):
            cov = np.linalg.pinv(gram / promp.variance + precision)
            rows = slice(bounds[g], bounds[g + 1])
            means[rows] = (rhs[rows] / promp.variance + prior) @ cov.T
            covs.append(cov)
        promp.weight_mean = means.mean(axis=0)
        centered = means - promp.weight_mean
        spread = sum(c * cov for c, cov in zip(counts, covs))
        promp.weight_cov = (centered.T @ centered + spread) / len(demos)
        variance = total_energy - 2.0 * float(np.sum(rhs * means))
        for g, (gram, cov) in enumerate(zip(grams, covs)):
            block = means[bounds[g] : bounds[g + 1]]
            variance += counts[g] * np.trace(gram @ cov) + float(np.einsum("ij,jk,ik->", block, gram, block))
        promp.variance = variance / (np.linalg.norm(means) * len(demos) * promp.n_dims * n_samples + 2.0)
        if np.linalg.norm(promp.weight_mean - previous) < min_delta:
            break
    return promp


class LabelledPeer(MotionPredictor):
    """What the peers share: checking the fitted and the queried data, label groups.

    A subclass's ``fit`` checks its data with ``_fit_data`` and ends with ``_fitted``;
    its ``predict`` checks the query with ``_query``. ``per_label`` (a peer per primitive)
    makes the labels needed in both.

    Attributes
    ----------
    fitted_labels_ : list of int
        The labels of the fitted demonstrations (empty when none were given).
    """

    per_label: bool = True

    @property
    def needs_labels(self) -> bool:
        """A peer per primitive is given the test sample's label."""
        return self.per_label

    def _fit_data(self, motor, labels, lengths):
        motor = check_motor(motor)
        n, steps, joints = motor.shape
        lengths = check_lengths(lengths, n, steps)
        labels = check_labels(labels, n)
        if self.per_label and labels is None:
            raise UserError(f"{type(self).__name__}(per_label=True) needs the labels of the fitted demonstrations")
        if not np.all(np.isfinite(motor[valid_mask(lengths, steps)])):
            raise UserError("motor contains NaN or inf on valid steps")
        return motor, labels, lengths

    def _groups(self, labels, n: int) -> dict:
        """Fitted label (or None for all) -> the indices of its demonstrations."""
        if not self.per_label:
            return {None: np.arange(n)}
        return {int(lab): np.flatnonzero(labels == lab) for lab in np.unique(labels)}

    def _fitted(self, motor: np.ndarray, labels) -> None:
        """Mark the peer fitted (the last thing ``fit`` does)."""
        self.n_steps_, self.n_joints_ = motor.shape[1], motor.shape[2]
        self.fitted_labels_ = [] if labels is None else np.unique(labels).tolist()

    def _check_fitted(self) -> None:
        if not hasattr(self, "n_joints_"):
            raise UserError(f"{type(self).__name__}: call fit before predict")

    def _query_labels(self, labels, n: int):
        """The checked labels of ``n`` queried samples (needed when ``per_label``)."""
        labels = check_labels(labels, n)
        if self.per_label and labels is None:
            raise UserError(f"{type(self).__name__}(per_label=True) needs the test samples' labels")
        return labels

    def _query_shape(self, shape, observed, labels, lengths, same_steps: bool):
        """Checked ``observed``, labels and lengths of a query of ``shape`` ``(n, T, J)`` (peer fitted)."""
        n, steps, joints = shape
        if joints != self.n_joints_:
            raise UserError(f"motor has {joints} joints but the peer was fitted on {self.n_joints_}")
        if same_steps and steps != self.n_steps_:
            raise UserError(f"motor has T = {steps} steps but the peer was fitted on T = {self.n_steps_}")
        lengths = check_lengths(lengths, n, steps)
        observed = observed_mask(observed, lengths, (n, steps))
        labels = self._query_labels(labels, n)
        if self.per_label:
            unknown = sorted(set(labels.tolist()) - set(self.fitted_labels_))
            if unknown:
                raise UserError(f"label(s) {unknown} have no fitted demonstration")
        return observed, labels, lengths

    def _query(self, motor, observed, labels, lengths, same_steps: bool = True):
        """Checked query data; the unobserved steps of ``motor`` are zeroed (never read)."""
        self._check_fitted()
        motor = check_motor(motor)
        observed, labels, lengths = self._query_shape(motor.shape, observed, labels, lengths, same_steps)
        seen = np.where(observed[..., None], motor, 0.0)
        if not np.all(np.isfinite(seen)):
            raise UserError("motor contains NaN or inf on observed steps")
        return seen, observed, labels, lengths

    def _key(self, labels, i: int):
        return int(labels[i]) if self.per_label else None


class ProMPPeer(LabelledPeer):
    """ProMP conditioning (``movement-primitives``): one ProMP per primitive, or one for all.

    Fitting: the package's ``ProMP(J, n_basis)`` learned by its EM (``imitate``, computed per
    demonstration length by :func:`imitate_promp`) on each group's
    demonstrations, time as phase in [0, 1] over each demonstration's valid steps
    (``np.linspace(0, 1, T_i)``). With two demonstrations a group's spread is rank one,
    but the package's EM adds the per-demonstration posterior covariances, so the
    weight covariance it returns is full rank (smallest eigenvalues about 1e-7 on LASA):
    it is kept as it is. ``ridge`` (default 0: none) adds ``ridge * I`` to it.

    Prediction: the group's weight distribution (``per_label``: the test sample's true
    label, which it is given) conditioned on every observed step with the package's
    ``condition_position`` (one Gaussian update per step, ``y_cov = noise * I``, at the
    step's phase over the test sample's valid steps); the result is the conditioned mean
    over the valid steps, the last step held over the padding. This is the sequential
    form of conditioning on all observed steps at once; it takes a fraction of a second
    for LASA's 130 test samples, so no separate batch form is written.

    Parameters
    ----------
    n_basis : int
        Basis functions (weights) per joint.
    noise : float
        Observation noise variance of the conditioning (> 0); see :func:`best_noise`.
    per_label : bool
        One ProMP per label (labels needed in fit and predict) or one for all shapes.
    ridge : float
        Added to the diagonal of each fitted weight covariance.
    n_iter : int
        Most EM iterations of ``imitate``.
    """

    name = "promp"

    def __init__(
        self, n_basis: int = 15, noise: float = 1e-3, per_label: bool = True, ridge: float = 0.0, n_iter: int = 1000
    ) -> None:
        if int(n_basis) < 2:
            raise UserError(f"n_basis must be at least 2, got {n_basis}")
        _check_noise(noise)
        if ridge < 0:
            raise UserError(f"ridge must be >= 0, got {ridge}")
        self.n_basis, self.noise, self.per_label = int(n_basis), float(noise), bool(per_label)
        self.ridge, self.n_iter = float(ridge), int(n_iter)

    def fit(self, motor, labels=None, lengths=None, frames=None) -> ProMPPeer:
        """Fit one ProMP per label (or one for all) on the valid steps; returns self."""
        motor, labels, lengths = self._fit_data(motor, labels, lengths)
        if lengths.min() < 2:
            raise UserError("the ProMP peer needs at least 2 valid steps per demonstration")
        self.promps_ = {}
        for key, idx in self._groups(labels, len(motor)).items():
            promp = imitate_promp(motor.shape[2], self.n_basis, [motor[i, : lengths[i]] for i in idx], self.n_iter)
            if self.ridge:
                promp.weight_cov = promp.weight_cov + self.ridge * np.eye(promp.n_weights)
            self.promps_[key] = promp
        self._fitted(motor, labels)
        return self

    def conditioned(self, key, steps_y: np.ndarray, phases: np.ndarray, noise: float | None = None):
        """The package ProMP of group ``key`` conditioned on positions ``steps_y`` at ``phases``.

        Parameters
        ----------
        key : int or None
            The label (None when ``per_label`` is False).
        steps_y : ndarray, shape (m, J)
            The observed positions.
        phases : ndarray, shape (m,)
            Their phases in [0, 1].
        noise : float, optional
            Observation noise variance (default ``self.noise``).
        """
        noise = self.noise if noise is None else _check_noise(noise)
        promp = self.promps_[key]
        cov = noise * np.eye(self.n_joints_)
        for y, t in zip(steps_y, phases):
            promp = promp.condition_position(y, y_cov=cov, t=float(t), t_max=1.0)
        return promp

    def predict(
        self, motor, observed, labels=None, lengths=None, frames=None, noise: float | None = None
    ) -> np.ndarray:
        """Conditioned mean motion ``(n, T, J)`` given each sample's observed steps.

        Parameters
        ----------
        motor : array-like, shape (n, T, J)
            The test samples; only the observed steps are read.
        observed : array-like of bool, shape (n, T)
        labels : array-like of int, optional
            The test samples' true labels (needed when ``per_label``).
        lengths : array-like of int, optional
            Valid steps per test sample (the phase runs over these).
        noise : float, optional
            Overrides ``self.noise`` for this call.
        """
        seen, observed, labels, lengths = self._query(motor, observed, labels, lengths, same_steps=False)
        if lengths.min() < 2:
            raise UserError("the ProMP peer needs at least 2 valid steps per test sample")
        out = np.empty_like(seen)
        for i in range(len(seen)):
            phases = phase(lengths[i])
            steps = np.flatnonzero(observed[i])
            promp = self.conditioned(self._key(labels, i), seen[i, steps], phases[steps], noise)
            mean = promp.mean_trajectory(phase(lengths[i]))
            out[i, : lengths[i]] = mean
            out[i, lengths[i] :] = mean[-1]
        return out


def _check_noise(noise) -> float:
    try:
        value = float(noise)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise UserError(f"noise must be a positive number (a variance), got {noise!r}")
    return value


class NearestPeer(LabelledPeer):
    """The fitted demonstration nearest to the test sample on its observed steps, whole.

    Distance: the mean squared difference (over joints and the observed steps that are
    valid in the fitted demonstration too); a demonstration sharing no such step is never
    chosen; ties go to the first. The returned sequence is the demonstration's, all ``T``
    steps (its padding included), not the observed steps pasted in.

    Parameters
    ----------
    per_label : bool
        Search only the test sample's own label (labels needed), default all.
    """

    name = "nearest"

    def __init__(self, per_label: bool = False) -> None:
        self.per_label = bool(per_label)

    def fit(self, motor, labels=None, lengths=None, frames=None) -> NearestPeer:
        """Keep the demonstrations (valid steps and labels); returns self."""
        motor, labels, lengths = self._fit_data(motor, labels, lengths)
        self.motor_, self.labels_, self.lengths_ = motor.copy(), labels, lengths
        self._fitted(motor, labels)
        return self

    def neighbours(self, motor, observed, labels=None, lengths=None) -> np.ndarray:
        """Index (into the fitted demonstrations) of each test sample's nearest one."""
        seen, observed, labels, lengths = self._query(motor, observed, labels, lengths)
        valid_fit = valid_mask(self.lengths_, self.n_steps_)
        chosen = np.empty(len(seen), dtype=np.int64)
        for i in range(len(seen)):
            both = valid_fit & observed[i][None, :]
            sq = np.where(both, ((self.motor_ - seen[i][None]) ** 2).mean(axis=2), 0.0).sum(axis=1)
            count = both.sum(axis=1)
            dist = np.where(count > 0, sq / np.maximum(count, 1), np.inf)
            if self.per_label:
                dist[self.labels_ != labels[i]] = np.inf
            if not np.isfinite(dist).any():
                raise UserError(f"test sample {i} shares no observed step with any fitted demonstration")
            chosen[i] = int(np.argmin(dist))
        return chosen

    def predict(self, motor, observed, labels=None, lengths=None, frames=None) -> np.ndarray:
        """The nearest fitted demonstration of each test sample, ``(n, T, J)``."""
        return self.motor_[self.neighbours(motor, observed, labels, lengths)].copy()


class MeanMotionPeer(LabelledPeer):
    """The mean motion of the test sample's primitive (or of all), its observed steps ignored.

    The mean at a step is over the fitted demonstrations valid at that step; a step none
    covers holds the last covered mean.

    Parameters
    ----------
    per_label : bool
        The mean of the sample's own label (labels needed, default) or of all.
    """

    name = "mean_motion"

    def __init__(self, per_label: bool = True) -> None:
        self.per_label = bool(per_label)

    def fit(self, motor, labels=None, lengths=None, frames=None) -> MeanMotionPeer:
        """Compute the mean motion per label (or of all); returns self."""
        motor, labels, lengths = self._fit_data(motor, labels, lengths)
        steps = motor.shape[1]
        valid = valid_mask(lengths, steps)
        self.means_ = {}
        for key, idx in self._groups(labels, len(motor)).items():
            count = valid[idx].sum(axis=0)
            total = np.where(valid[idx][..., None], motor[idx], 0.0).sum(axis=0)
            mean = total / np.maximum(count, 1)[:, None]
            last = np.maximum.accumulate(np.where(count > 0, np.arange(steps), 0))
            self.means_[key] = mean[last]
        self._fitted(motor, labels)
        return self

    def predict(self, motor, observed, labels=None, lengths=None, frames=None) -> np.ndarray:
        """The mean motion of each test sample's label (or of all), ``(n, T, J)``."""
        _, _, labels, _ = self._query(motor, observed, labels, lengths)
        return np.stack(
            [self.means_[self._key(labels, i)] for i in range(len(labels if labels is not None else motor))]
        )


class NoiseChoice(NamedTuple):
    """The result of :func:`best_noise`.

    Attributes
    ----------
    noise : float
        The candidate with the lowest mean unobserved MSE (the first on a tie).
    predicted : ndarray, shape (n, T, J)
        The prediction with that noise.
    mse : ndarray, shape (n,)
        Its per-sample :func:`unobserved_mse`.
    scores : dict
        Candidate -> mean unobserved MSE over the samples (NaN ones left out).
    """

    noise: float
    predicted: np.ndarray
    mse: np.ndarray
    scores: dict


def best_noise(
    peer: ProMPPeer, motor, observed, labels=None, lengths=None, candidates: Sequence[float] = (1e-4, 1e-3, 1e-2)
) -> NoiseChoice:
    """The ProMP's observation noise chosen as the best of ``candidates`` *on the answer*.

    Each candidate predicts the test samples and is scored by the mean
    :func:`unobserved_mse` of the very steps it predicts: the choice sees the test set's
    unobserved steps, so the result **flatters the peer** (an upper bound on what it
    would do with the noise chosen on held-out data). ``peer.noise`` is left unchanged.

    Parameters
    ----------
    peer : ProMPPeer
        Fitted.
    motor : array-like, shape (n, T, J)
        The test samples, whole: the truth the candidates are scored on.
    observed, labels, lengths
        As for :meth:`ProMPPeer.predict`.
    candidates : sequence of float
        Noise variances to try.
    """
    if len(candidates) == 0:
        raise UserError("best_noise needs at least one candidate noise")
    best = None
    scores = {}
    for candidate in candidates:
        noise = _check_noise(candidate)
        predicted = peer.predict(motor, observed, labels=labels, lengths=lengths, noise=noise)
        mse = unobserved_mse(predicted, motor, observed, lengths)
        if np.all(np.isnan(mse)):
            raise UserError("best_noise: no test sample has an unobserved valid step to score")
        scores[noise] = float(np.nanmean(mse))
        if best is None or scores[noise] < scores[best.noise]:
            best = NoiseChoice(noise, predicted, mse, scores)
    return best
