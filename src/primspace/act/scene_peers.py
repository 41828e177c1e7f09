"""The peers of the scene mode: the whole motion from the first frame and the primitive.

primspace's :class:`~primspace.act.scene_policy.ScenePolicy` predicts a motion from its first
camera frame and the primitive to do; these two predictors (:class:`~primspace.predict.base.Predictor`)
are what it is measured against. Both read only the **first frame** of each sample
(``frames[:, 0]`` of ``(n, T, H, W, 3)`` uint8; frames ``(n, H, W, 3)`` are taken as the first
frames themselves) and the sample's label (``needs_labels``); the motor arrays are the
run's scaled ``(n, T, J)`` as for the other peers (:mod:`primspace.predict.peers`), and
``predict`` reads none of their steps (only their shape and ``lengths``): the caller scores
the steps after the first.

* :class:`ContextualProMPPeer`: per primitive, a ProMP (the ``movement-primitives``
  package's ``imitate``) and a ridge regression from the first frame's features
  (:mod:`primspace.act.frame_features`, standardised) to each demonstration's ProMP
  weights; the prediction is the trajectory of the predicted weights.
* :class:`NearestFramePeer`: the fitted demonstration of the same primitive whose first frame
  is nearest, replayed whole.

:class:`ScenePeer` is what they share (the first frames, no motor step read); the scene
policy's own kind of map as a peer, tuned by K-fold, is
:class:`~primspace.act.scene_kernel.KernelRidgePeer`.
"""

from __future__ import annotations

import numpy as np
from sklearn.linear_model import Ridge, RidgeCV
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from primspace.act.frame_features import frame_features
from primspace.predict.peers import LabelledPeer, imitate_promp, phase, promp_class
from primspace.utils.errors import UserError

__all__ = ["ScenePeer", "ContextualProMPPeer", "NearestFramePeer", "RIDGE_ALPHAS"]

#: The ridge penalties :class:`ContextualProMPPeer` chooses from (``alpha="auto"``, leave-one-out).
RIDGE_ALPHAS = np.logspace(-6, 3, 19)

#: The ridge of each demonstration's least-squares ProMP weights.
WEIGHT_RIDGE = 1e-8


def _first_frames(frames, n: int | None = None) -> np.ndarray:
    """The first frame of each sample, ``(n, H, W, 3)`` (one UserError when missing or not ``n``)."""
    if frames is None:
        raise UserError("the scene peers read each motion's first camera frame: pass frames (n, T, H, W, 3)")
    arr = frames if hasattr(frames, "ndim") else np.asarray(frames)
    if arr.ndim == 5:
        arr = arr[:, 0]
    arr = np.asarray(arr)
    if arr.ndim != 4 or (n is not None and len(arr) != n):
        like = "" if n is None else f" with n = {n} like motor"
        raise UserError(f"frames must be (n, T, H, W, 3){like}, got shape {np.shape(frames)}")
    return arr


class ScenePeer(LabelledPeer):
    """What the scene peers add to the peers' checks: the first frames, and no motor step read."""

    def _fit_data(self, motor, labels, lengths, frames):
        motor, labels, lengths = super()._fit_data(motor, labels, lengths)
        return motor, labels, lengths, _first_frames(frames, len(motor))

    def _query(self, motor, observed, labels, lengths, frames, same_steps: bool):
        """Checked query: ``(n, T)``, labels, lengths and first frames; no motor step is read."""
        self._check_fitted()
        shape = np.shape(motor)
        if len(shape) != 3 or 0 in shape:
            raise UserError(f"motor must be a non-empty (n, T, J) array, got shape {shape}")
        # observed is checked, not read: the scene alone predicts
        _, labels, lengths = self._query_shape(shape, observed, labels, lengths, same_steps)
        return shape[:2], labels, lengths, _first_frames(frames, shape[0])

    def _scenes(self, frames, labels) -> tuple[np.ndarray, np.ndarray | None, int]:
        """The first frames of the queried scenes, their checked labels and their number (peer fitted)."""
        self._check_fitted()
        first = _first_frames(frames)
        return first, self._query_labels(labels, len(first)), len(first)


def _standardiser(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and scale of ``features`` ``(n, d)`` (scale 1 where a feature is constant)."""
    mean = features.mean(axis=0)
    scale = features.std(axis=0)
    return mean, np.where(scale > 1e-12, scale, 1.0)


class ContextualProMPPeer(ScenePeer):
    """A ProMP per primitive whose weights are regressed on the first frame's features.

    Fitting, per label (or once for all): the package's ``ProMP(J, n_basis)`` learned by its EM
    (:func:`~primspace.predict.peers.imitate_promp`) on the
    group's demonstrations (time as phase in [0, 1] over each one's valid steps, as
    :class:`~primspace.predict.peers.ProMPPeer`); each demonstration's own weights by least
    squares on that ProMP's basis (the package's ``ProMP.weights``, ridge
    :data:`WEIGHT_RIDGE`), so they lie in the space of its ``weight_mean``; and a ridge
    regression (standardised features) from the features of the demonstrations' first frames
    to their weights' offsets from ``weight_mean``. The ridge has an intercept, so the
    prediction does not depend on the EM's ``weight_mean`` (it only centres the targets; a
    large penalty predicts the mean of the demonstrations' least-squares weights); the fitted
    ProMP is kept for its basis and weight distribution (``promps_``). The features'
    transformer is fitted once, on the first frames of all the fitted demonstrations.

    Prediction: the trajectory (``trajectory_from_weights``) of ``weight_mean`` plus the
    regressed offset, over the sample's valid steps (phase 0..1), the last step held over the
    padding. The motion is returned as predicted (its first step is not replaced by the
    observed one).

    Parameters
    ----------
    n_basis : int
        Basis functions (weights) per joint (>= 2).
    features : str or object
        The first frame's features: ``"pca"`` (principal components of the pixels), ``"blob"``
        (the red block's mass and centroid), ``"learned"`` (keypoints of an encoder fitted on the
        demonstrations' first frames alone), ``"pixels"``, or a transformer
        (:func:`~primspace.act.frame_features.frame_features`).
    alpha : "auto" or float
        The ridge penalty (> 0), or ``"auto"``: chosen per group by leave-one-out among
        :data:`RIDGE_ALPHAS` (scikit-learn's ``RidgeCV``).
    per_label : bool
        One ProMP and regression per label (labels needed in fit and predict) or one for all.
    n_iter : int
        Most EM iterations of ``imitate``.

    Attributes
    ----------
    features_ : object
        The fitted transformer of frames.
    promps_ : dict
        Label (None for all) -> the package's fitted ``ProMP``.
    regressions_ : dict
        Label -> the fitted scikit-learn pipeline (scaler, ridge) from features to weight offsets.
    alphas_ : dict
        Label -> the ridge penalty used.
    """

    def __init__(
        self, n_basis: int = 15, features="pca", alpha="auto", per_label: bool = True, n_iter: int = 1000
    ) -> None:
        if int(n_basis) < 2:
            raise UserError(f"n_basis must be at least 2, got {n_basis}")
        if not (isinstance(alpha, str) and alpha == "auto"):
            if isinstance(alpha, str) or not (np.isfinite(alpha) and alpha > 0):
                raise UserError(f"alpha must be 'auto' or a positive number, got {alpha!r}")
        frame_features(features)  # a bad name fails here, not in fit
        self.n_basis, self.features, self.alpha = int(n_basis), features, alpha
        self.per_label, self.n_iter = bool(per_label), int(n_iter)

    def fit(self, motor, labels=None, lengths=None, frames=None) -> ContextualProMPPeer:
        """Fit the ProMPs, the features and the regressions (class docstring); returns self."""
        promp_class()  # the package is there before any work
        motor, labels, lengths, first = self._fit_data(motor, labels, lengths, frames)
        if lengths.min() < 2:
            raise UserError("the contextual ProMP peer needs at least 2 valid steps per demonstration")
        self.features_ = frame_features(self.features)
        rows = np.asarray(self.features_.fit_transform(first), dtype=np.float64)
        self.promps_, self.regressions_, self.alphas_ = {}, {}, {}
        for key, idx in self._groups(labels, len(motor)).items():
            demos = [motor[i, : lengths[i]] for i in idx]
            promp = imitate_promp(motor.shape[2], self.n_basis, demos, self.n_iter)
            weights = np.stack([promp.weights(phase(len(y)), y, lmbda=WEIGHT_RIDGE) for y in demos])
            self.promps_[key] = promp
            self.regressions_[key], self.alphas_[key] = self._regression(rows[idx], weights - promp.weight_mean)
        self._fitted(motor, labels)
        return self

    def _regression(self, rows: np.ndarray, offsets: np.ndarray) -> tuple:
        """The fitted pipeline (standardise, ridge) from feature rows to weight offsets, and its penalty.

        ``alpha="auto"`` with a single demonstration has nothing to choose by: the largest
        penalty (its weights, whatever the scene).
        """
        if self.alpha == "auto" and len(rows) > 1:
            ridge = RidgeCV(alphas=RIDGE_ALPHAS)
        else:
            ridge = Ridge(alpha=float(RIDGE_ALPHAS[-1] if self.alpha == "auto" else self.alpha))
        pipeline = make_pipeline(StandardScaler(), ridge).fit(rows, offsets)
        return pipeline, float(ridge.alpha_ if isinstance(ridge, RidgeCV) else ridge.alpha)

    def weights(self, frames, labels=None) -> np.ndarray:
        """The predicted ProMP weights ``(n, J * n_basis)`` of scenes given by their first frames.

        Parameters
        ----------
        frames : array-like, shape (n, T, H, W, 3) or (n, H, W, 3), uint8
            The scenes; only the first frame of each is read.
        labels : array-like of int, optional
            Their primitives (needed when ``per_label``).
        """
        first, labels, n = self._scenes(frames, labels)
        rows = np.asarray(self.features_.transform(first), dtype=np.float64)
        out = np.empty((n, self.n_joints_ * self.n_basis))
        for i in range(n):
            key = self._key(labels, i)
            if key not in self.promps_:
                raise UserError(f"label(s) {[key]} have no fitted demonstration")
            out[i] = self.promps_[key].weight_mean + self.regressions_[key].predict(rows[i : i + 1])[0]
        return out

    def predict(self, motor, observed, labels=None, lengths=None, frames=None) -> np.ndarray:
        """The motion of each sample's predicted weights, ``(n, T, J)`` (class docstring).

        Parameters
        ----------
        motor : array-like, shape (n, T, J)
            The test samples: only their shape is read.
        observed : array-like of bool, shape (n, T), or an Observation rule
            Checked, not read: the scene alone predicts.
        labels : array-like of int, optional
            The test samples' primitives (needed when ``per_label``).
        lengths : array-like of int, optional
            Valid steps per test sample (the phase runs over these).
        frames : array-like, shape (n, T, H, W, 3) uint8
            Their frames; only the first of each is read.
        """
        (n, steps), labels, lengths, first = self._query(motor, observed, labels, lengths, frames, same_steps=False)
        if lengths.min() < 2:
            raise UserError("the contextual ProMP peer needs at least 2 valid steps per test sample")
        weights = self.weights(first, labels)
        out = np.empty((n, steps, self.n_joints_))
        for i in range(n):
            motion = self.promps_[self._key(labels, i)].trajectory_from_weights(phase(lengths[i]), weights[i])
            out[i, : lengths[i]] = motion
            out[i, lengths[i] :] = motion[-1]
        return out


class NearestFramePeer(ScenePeer):
    """The fitted demonstration of the same primitive whose first frame is nearest, whole.

    Distance: Euclidean between first frames, on the pixels scaled to [0, 1]
    (``features="pixels"``), or on the rows of another transformer of frames standardised
    by the fitted demonstrations' mean and spread (a constant feature is left unscaled).
    Ties go to the first demonstration. The returned sequence is the demonstration's, all
    ``T`` steps (its padding included).

    Parameters
    ----------
    features : str or object
        ``"pixels"``, ``"blob"``, ``"pca"`` or a transformer
        (:func:`~primspace.act.frame_features.frame_features`).
    per_label : bool
        Search only the test sample's own label (labels needed; default) or all.

    Attributes
    ----------
    features_ : object
        The fitted transformer of frames.
    rows_ : ndarray, shape (m, d)
        The fitted demonstrations' first frames as compared (standardised unless pixels).
    """

    def __init__(self, features="pixels", per_label: bool = True) -> None:
        frame_features(features)  # a bad name fails here, not in fit
        self.features, self.per_label = features, bool(per_label)

    def _rows(self, first: np.ndarray) -> np.ndarray:
        rows = np.asarray(self.features_.transform(first), dtype=np.float64)
        return (rows - self.mean_) / self.scale_

    def fit(self, motor, labels=None, lengths=None, frames=None) -> NearestFramePeer:
        """Keep the demonstrations and their first frames' features; returns self."""
        motor, labels, lengths, first = self._fit_data(motor, labels, lengths, frames)
        self.features_ = frame_features(self.features)
        rows = np.asarray(self.features_.fit_transform(first), dtype=np.float64)
        if isinstance(self.features, str) and self.features == "pixels":
            self.mean_, self.scale_ = np.zeros(rows.shape[1]), np.ones(rows.shape[1])
        else:
            self.mean_, self.scale_ = _standardiser(rows)
        self.rows_ = (rows - self.mean_) / self.scale_
        self.motor_, self.labels_, self.lengths_ = motor.copy(), labels, lengths
        self._fitted(motor, labels)
        return self

    def neighbours(self, frames, labels=None) -> np.ndarray:
        """Index (into the fitted demonstrations) of the nearest first frame of each scene.

        Parameters
        ----------
        frames, labels
            As for :meth:`ContextualProMPPeer.weights`: the scenes (only the first frame of each
            is read) and their primitives (needed when ``per_label``).
        """
        first, labels, n = self._scenes(frames, labels)
        rows = self._rows(first)
        chosen = np.empty(n, dtype=np.int64)
        for i in range(n):
            dist = np.sqrt(((self.rows_ - rows[i][None, :]) ** 2).sum(axis=1))
            if self.per_label:
                dist[self.labels_ != labels[i]] = np.inf
            if not np.isfinite(dist).any():
                raise UserError(f"label(s) {[int(labels[i])]} have no fitted demonstration")
            chosen[i] = int(np.argmin(dist))
        return chosen

    def predict(self, motor, observed, labels=None, lengths=None, frames=None) -> np.ndarray:
        """The demonstration of the nearest first frame, whole, ``(n, T, J)`` (class docstring).

        Parameters
        ----------
        motor : array-like, shape (n, T, J)
            The test samples: only their shape is read (T as fitted).
        observed : array-like of bool, shape (n, T), or an Observation rule
            Checked, not read.
        labels : array-like of int, optional
            The test samples' primitives (needed when ``per_label``).
        lengths : array-like of int, optional
            Valid steps per test sample (checked).
        frames : array-like, shape (n, T, H, W, 3) uint8
            Their frames; only the first of each is read.
        """
        _, labels, _, first = self._query(motor, observed, labels, lengths, frames, same_steps=True)
        return self.motor_[self.neighbours(first, labels)].copy()
