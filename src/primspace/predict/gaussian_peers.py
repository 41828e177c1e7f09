"""Peers that are Gaussians over whole trajectories, their settings chosen on the fitted demonstrations.

Each peer here is a Gaussian over a motion's flattened ``(T·J,)`` entries per primitive
(``per_label``: the test sample's own, which it is given) or one for all, conditioned on the
observed entries with noise ``r`` per entry (the standard Gaussian conditioning,
``μ + Σ_{·o} (Σ_oo + r I)⁻¹ (x_o - μ_o)``, computed by
:class:`~primspace.predict.code_prior.DecodedGaussian` as for the prior in code space); the
prediction is the conditioned mean. Neither reads a trained run.

* :class:`RawGaussianPeer`: the mean and covariance of the fitted demonstrations themselves
  (scaled, flattened over all ``T`` steps). ``r`` adds ``r I`` to ``Σ_oo``: for the conditioned
  mean this is the same as a ridge ``r I`` on the whole covariance.
* :class:`TunedProMPPeer`: a ProMP (``movement-primitives``'s ``imitate``, as
  :class:`~primspace.predict.peers.ProMPPeer`) with ``n_basis`` basis functions per joint and
  ``ridge`` added to its weight covariance, as the Gaussian over trajectories it implies
  (``mean_trajectory``, ``cov_trajectory`` over each test sample's valid steps in phase
  [0, 1]): the same as conditioning the weights on every observed step at once.

Their settings (``"auto"``, the default) are chosen per observation rule without the
answer, by the same K-fold prediction of the fitted demonstrations that chooses the prior's
(:func:`~primspace.predict.code_prior.fold_split`, :data:`~primspace.predict.code_prior.CV_FOLDS`
folds within each label): each fold is predicted by the Gaussians fitted without it, and the
setting with the lowest mean unobserved MSE of the held-out demonstrations is kept (the first
on a tie, and the first when nothing is left unobserved; a setting whose fit fails on a fold,
e.g. the ProMP's EM with more basis functions than the data carry, is not chosen, and when the
chosen one's fit on all the demonstrations fails the next best is used). A forecast's ``details`` record the
setting and ``model_share`` 0: the run's decoder takes no part.
"""

from __future__ import annotations

import itertools
from abc import abstractmethod

import numpy as np

from primspace.predict.base import Forecast, observation_rule
from primspace.predict.code_prior import CV_FOLDS, DecodedGaussian, condition_primitives, fold_split
from primspace.predict.metrics import unobserved_mse
from primspace.predict.peers import LabelledPeer, imitate_promp, phase, promp_class
from primspace.utils.errors import UserError

__all__ = ["GaussianPeer", "RawGaussianPeer", "TunedProMPPeer", "NOISE_GRID", "BASIS_GRID", "RIDGE_GRID"]

#: Observation noise ``r`` per entry (scaled units²) tried by the K-fold choice (the prior's grid).
NOISE_GRID = (1e-5, 1e-4, 1e-3, 1e-2)
#: Basis functions per joint of the tuned ProMP tried by the K-fold choice.
BASIS_GRID = (10, 15, 20, 30, 40)
#: Ridges added to the tuned ProMP's weight covariance tried by the K-fold choice.
RIDGE_GRID = (0.0, 1e-6, 1e-4, 1e-2)


def _grid(value, grid, name: str, low: float) -> list:
    """``[value]`` when fixed (checked ``>= low``), the grid when ``"auto"``, the values of a tuple or list
    (each checked) when one is given as the grid to try."""
    if isinstance(value, str) and value == "auto":
        return list(grid)
    if isinstance(value, (tuple, list)) and value:
        return [v for item in value for v in _grid(item, grid, name, low)]
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not value >= low:
        raise UserError(f"{name} must be 'auto' or a number >= {low:g}, got {value!r}")
    return [value]


class GaussianPeer(LabelledPeer):
    """What the Gaussian peers share: fitting per group, the K-fold choice of the settings, the
    conditioning (module docstring). A subclass gives :meth:`settings` (the candidates), the part
    of a setting that needs a refit (:meth:`fit_key`), :meth:`fit_group` and :meth:`gaussian`.

    Attributes
    ----------
    choices_ : dict
        Observation rule -> ``{"setting": ..., "ranked": [settings, best first], "scores": {setting text:
        K-fold MSE}}``.
    """

    #: A Gaussian over each test sample's valid steps (phase), else over all ``T`` steps.
    over_valid_steps = False

    @abstractmethod
    def settings(self) -> list[dict]:
        """The candidate settings (one when every setting is fixed)."""

    def fit_key(self, setting: dict):
        """The part of ``setting`` that the fitted groups depend on."""
        return None

    @abstractmethod
    def fit_group(self, motor: np.ndarray, lengths: np.ndarray, key):
        """What :meth:`gaussian` reads of one group's demonstrations (``key``: :meth:`fit_key`)."""

    @abstractmethod
    def gaussian(self, model, length: int, setting: dict) -> DecodedGaussian:
        """The Gaussian over ``length`` steps (step-major ``length · J`` entries) of a fitted group."""

    def fit(self, motor, labels=None, lengths=None, frames=None) -> GaussianPeer:
        """Keep the demonstrations; each group's Gaussians are fitted when a setting first needs them."""
        motor, labels, lengths = self._fit_data(motor, labels, lengths)
        self.settings()  # settings checked before anything is fitted
        self.motor_, self.labels_, self.lengths_ = motor, labels, lengths
        self.groups_ = self._groups(labels, len(motor))
        strata = [np.arange(len(motor))] if labels is None else [np.flatnonzero(labels == k) for k in np.unique(labels)]
        self.fold_of_ = fold_split(strata, len(motor), [int(self.random_state), 39, 2], CV_FOLDS)
        self.models_, self.gaussians_, self.choices_ = {}, {}, {}
        self._fitted(motor, labels)
        return self

    def _models(self, fold, key) -> dict:
        """Group -> fitted model, on every demonstration (``fold`` None) or on those out of ``fold``."""
        if (fold, key) not in self.models_:
            out = {}
            try:
                for group, idx in self.groups_.items():
                    kept = idx if fold is None else idx[self.fold_of_[idx] != fold]
                    kept = idx if len(kept) == 0 else kept
                    out[group] = self.fit_group(self.motor_[kept], self.lengths_[kept], key)
            except np.linalg.LinAlgError as exc:  # kept: the same fit fails again
                out = exc
            self.models_[fold, key] = out
        if isinstance(self.models_[fold, key], Exception):
            raise self.models_[fold, key]
        return self.models_[fold, key]

    def _gaussian(self, fold, setting: dict, group, length: int) -> DecodedGaussian:
        shape = sorted((k, v) for k, v in setting.items() if k != "noise")  # the noise only conditions
        key = (fold, repr(shape), group, length)
        if key not in self.gaussians_:
            self.gaussians_[key] = self.gaussian(self._models(fold, self.fit_key(setting))[group], length, setting)
        return self.gaussians_[key]

    def _conditioned(self, fold, setting: dict, seen, observed, labels, lengths) -> np.ndarray:
        """The conditioned means ``(n, T, J)`` of ``seen`` (unobserved steps zero) by the Gaussians of ``fold``."""
        n, steps, joints = seen.shape
        out = np.empty_like(seen)
        spans = lengths if self.over_valid_steps else np.full(n, steps)
        keys = [self._key(labels, i) for i in range(n)]
        for group, span in sorted(set(zip(keys, spans.tolist())), key=repr):
            idx = np.flatnonzero([k == group and s == span for k, s in zip(keys, spans)])
            g = self._gaussian(fold, setting, group, int(span))
            means, _ = condition_primitives(
                [g], seen[idx, :span], observed[idx, :span], [[0]] * len(idx), setting["noise"]
            )
            out[idx, :span] = means[:, 0].reshape(len(idx), span, joints)
            out[idx, span:] = out[idx, span - 1 : span]
        return out

    def choice(self, rule) -> dict:
        """The setting for observation ``rule`` (chosen by K-fold prediction on first use; module docstring)."""
        candidates = self.settings()
        if len(candidates) == 1:
            return candidates[0]
        if rule.key not in self.choices_:
            observed = rule.masks(self.lengths_, self.n_steps_)[0]
            seen = np.where(observed[..., None], self.motor_, 0.0)
            scores = {}
            for setting in candidates:
                predicted = np.full_like(self.motor_, np.nan)
                try:
                    for fold in np.unique(self.fold_of_[self.fold_of_ >= 0]):
                        held = self.fold_of_ == fold
                        labels = None if self.labels_ is None else self.labels_[held]
                        args = (seen[held], observed[held], labels, self.lengths_[held])
                        predicted[held] = self._conditioned(int(fold), setting, *args)
                except np.linalg.LinAlgError:  # a setting that cannot be fitted on a fold is not chosen
                    scores[repr(setting)] = np.nan
                    continue
                errors = unobserved_mse(predicted, self.motor_, observed, self.lengths_)
                errors = errors[np.isfinite(errors)]
                scores[repr(setting)] = float(errors.mean()) if errors.size else np.nan
            finite = [s for s in candidates if np.isfinite(scores[repr(s)])]
            ranked = sorted(finite, key=lambda s: scores[repr(s)]) + [s for s in candidates if s not in finite]
            self.choices_[rule.key] = {"setting": ranked[0], "ranked": ranked, "scores": scores}
        return self.choices_[rule.key]["setting"]

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None, **options) -> Forecast:
        """The conditioned mean motions ``(n, T, J)``; ``details``: the ``setting`` and ``model_share`` 0."""
        seen, mask, labels, lengths = self._query(
            motor, observed, labels, lengths, same_steps=not self.over_valid_steps
        )
        ranked = self.settings()
        if len(ranked) > 1:
            rule = observation_rule(observed, lengths, mask.shape)
            self.choice(rule)
            ranked = self.choices_[rule.key]["ranked"]
        for setting in ranked:  # the best the K-fold found whose fit on all the data succeeds
            try:
                out = self._conditioned(None, setting, seen, mask, labels, lengths)
            except np.linalg.LinAlgError as exc:
                failure = exc
                continue
            return Forecast(out, None, {"setting": dict(setting), "model_share": 0.0})
        raise UserError(f"{type(self).__name__}: no setting can be fitted ({failure})")

    def predict(self, motor, observed, labels=None, lengths=None, frames=None, **options) -> np.ndarray:
        """:meth:`forecast`'s motion."""
        return self.forecast(motor, observed, labels, lengths, frames).motor


class RawGaussianPeer(GaussianPeer):
    """The Gaussian of the fitted demonstrations' flattened trajectories, conditioned on the observed steps.

    Parameters
    ----------
    per_label : bool
        One Gaussian per label (labels needed in fit and predict, default) or one for all.
    noise : "auto" or float
        ``r`` per observed entry (a ridge on the covariance, for the conditioned mean); auto:
        chosen from :data:`NOISE_GRID` by K-fold prediction of the fitted demonstrations.
    random_state : int
        Seed of the folds.
    """

    name = "raw_gaussian"

    def __init__(self, per_label: bool = True, noise="auto", random_state: int = 0) -> None:
        self.per_label, self.noise, self.random_state = bool(per_label), noise, random_state

    def settings(self) -> list[dict]:
        return [{"noise": float(r)} for r in _grid(self.noise, NOISE_GRID, "noise", 1e-300)]

    def fit_group(self, motor: np.ndarray, lengths: np.ndarray, key):
        flat = motor.reshape(len(motor), -1)
        if len(flat) < 2:  # one demonstration: its trajectory, with no spread
            return DecodedGaussian.from_moments(flat[0], np.zeros((1, flat.shape[1])), flat.shape[1])
        return DecodedGaussian(flat, flat.shape[1])

    def gaussian(self, model, length: int, setting: dict) -> DecodedGaussian:
        return model


class TunedProMPPeer(GaussianPeer):
    """A ProMP whose basis count, weight-covariance ridge and observation noise are chosen by K-fold
    prediction of the fitted demonstrations, conditioned on every observed step at once.

    Parameters
    ----------
    per_label : bool
        One ProMP per label (labels needed in fit and predict, default) or one for all.
    n_basis : "auto", int or tuple of int
        Basis functions per joint (auto: :data:`BASIS_GRID`; a tuple: the grid tried).
    ridge : "auto" or float
        Added to the diagonal of each fitted weight covariance (auto: :data:`RIDGE_GRID`).
    noise : "auto" or float
        Observation noise variance per entry (auto: :data:`NOISE_GRID`).
    n_iter : int
        Most EM iterations of ``imitate``.
    random_state : int
        Seed of the folds.
    """

    name = "promp_tuned"
    over_valid_steps = True

    def __init__(
        self,
        per_label: bool = True,
        n_basis="auto",
        ridge="auto",
        noise="auto",
        n_iter: int = 1000,
        random_state: int = 0,
    ) -> None:
        self.per_label, self.n_basis, self.ridge, self.noise = bool(per_label), n_basis, ridge, noise
        self.n_iter, self.random_state = int(n_iter), random_state

    def settings(self) -> list[dict]:
        grids = (
            [int(b) for b in _grid(self.n_basis, BASIS_GRID, "n_basis", 2)],
            [float(v) for v in _grid(self.ridge, RIDGE_GRID, "ridge", 0.0)],
            [float(v) for v in _grid(self.noise, NOISE_GRID, "noise", 1e-300)],
        )
        return [{"n_basis": b, "ridge": g, "noise": r} for b, g, r in itertools.product(*grids)]

    def fit_key(self, setting: dict):
        return setting["n_basis"]

    def fit_group(self, motor: np.ndarray, lengths: np.ndarray, key):
        if lengths.min() < 2:
            raise UserError("the ProMP peer needs at least 2 valid steps per demonstration")
        with np.errstate(all="ignore"):
            promp = imitate_promp(motor.shape[2], int(key), [m[:n] for m, n in zip(motor, lengths)], self.n_iter)
        if not (np.isfinite(promp.weight_mean).all() and np.isfinite(promp.weight_cov).all()):
            raise np.linalg.LinAlgError(f"the ProMP's EM did not converge with {key} basis functions")
        return promp

    def gaussian(self, model, length: int, setting: dict) -> DecodedGaussian:
        if length < 2:
            raise UserError("the ProMP peer needs at least 2 valid steps per test sample")
        joints = model.n_dims
        promp = promp_class()(joints, model.n_weights_per_dim)
        promp.from_weight_distribution(model.weight_mean, model.weight_cov + setting["ridge"] * np.eye(model.n_weights))
        times = phase(length)
        cov = promp.cov_trajectory(times)  # joint-major: entry j * length + t
        order = (np.arange(joints)[None, :] * length + np.arange(length)[:, None]).ravel()  # step-major
        values, vectors = np.linalg.eigh(cov[np.ix_(order, order)])
        kept = values > 1e-12 * max(values.max(), 1e-300)  # its rank: at most the number of weights
        deviations = (vectors[:, kept] * np.sqrt(values[kept])).T
        return DecodedGaussian.from_moments(promp.mean_trajectory(times).ravel(), deviations, length * joints)
