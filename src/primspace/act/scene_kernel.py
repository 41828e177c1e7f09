"""The scene policy's own kind of map as its peer: a Gaussian process's mean from the first frame's
features to the whole motion, its settings chosen by K-fold on the fitted demonstrations.

:class:`~primspace.act.scene_policy.ScenePolicy` maps the block's colour moments to the motion by a
Gaussian process per primitive whose kernel (a length per feature, a scale, a noise) maximises the
marginal likelihood. :class:`KernelRidgePeer` is that map written and tuned independently: the
same features and targets, the posterior mean of a Gaussian process with an RBF kernel (kernel
ridge regression), its lengths and penalty chosen by K-fold prediction of the fitted
demonstrations (:func:`~primspace.predict.code_prior.fold_split`, the folds of the prior's choice)
and never on the evaluation set. A scene peer (:class:`~primspace.act.scene_peers.ScenePeer`): it
reads the first frame and the label, and no motor step of a query.
"""

from __future__ import annotations

import numpy as np

from primspace.act.frame_features import frame_features
from primspace.act.scene_peers import ScenePeer
from primspace.predict.code_prior import CV_FOLDS, fold_split
from primspace.predict.metrics import valid_mask
from primspace.utils.errors import UserError

__all__ = ["KernelRidgePeer", "LENGTH_GRID", "PENALTY_GRID", "SWEEPS"]

#: Length scales of the RBF kernel (on standardised features) the K-fold choice tries, per feature.
LENGTH_GRID = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 64.0)
#: Penalties (the noise variance against the kernel's 1, standardised targets) the K-fold choice tries.
PENALTY_GRID = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0)
#: Passes over the features of the per-feature length search (``length_scale="auto"``).
SWEEPS = 2


def _rbf(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The RBF kernel ``exp(-|a_i - b_j|² / 2)`` between the rows of ``a`` (n, d) and ``b`` (m, d),
    each already divided by its lengths."""
    return np.exp(-0.5 * ((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=-1))


def _standardised(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and scale of the columns of ``values`` (n, d) (scale 1 where a column is constant)."""
    scale = values.std(axis=0)
    return values.mean(axis=0), np.where(scale > 1e-12, scale, 1.0)


def _checked(value, name: str) -> float | None:
    """None for ``"auto"``, else ``value`` checked > 0 (one UserError)."""
    if isinstance(value, str) and value == "auto":
        return None
    if isinstance(value, (bool, str)) or not isinstance(value, (int, float, np.number)) or not value > 0:
        raise UserError(f"{name} must be 'auto' or a number > 0, got {value!r}")
    return float(value)


class KernelRidgePeer(ScenePeer):
    """A Gaussian process's mean from the first frame's features to the whole motion, its lengths and
    penalty chosen by K-fold prediction of the fitted demonstrations (module docstring).

    Per label (or once for all): the features of the demonstrations' first frames (the transformer
    fitted once on all of them), standardised by the group's mean and spread, and the targets, each
    demonstration's whole motion (scaled, all ``T`` steps flattened, as the scene policy's),
    standardised per entry. The prediction is the posterior mean of a Gaussian process with kernel
    ``exp(-Σ_d (x_d - x'_d)² / (2 ℓ_d²))`` and noise variance ``λ``, i.e. kernel ridge regression with
    penalty ``λ``: ``k(x)ᵀ (K + λ I)⁻¹ y``, back in scaled units; a test sample's padding beyond its
    valid steps holds its last valid step. The motion is returned as predicted (its first step is
    not replaced by the observed one).

    The choice, per group, on its fitted demonstrations alone: ``folds`` folds (seeded by
    ``random_state`` and the label), each predicted from the others, scored by the mean squared
    error over the held-out demonstrations' valid entries (scaled units). With
    ``length_scale="auto"`` the search starts from the best single length for every feature
    (:data:`LENGTH_GRID`), then :data:`SWEEPS` passes over the features try each length of the grid
    for one feature with the others kept; every length is tried with every penalty of
    :data:`PENALTY_GRID` (or the one given). A setting replaces the best only when strictly lower,
    so a tie keeps the earlier one. The scene policy's kernel maximises the marginal likelihood
    instead; nothing here reads the evaluation set.

    Parameters
    ----------
    features : str or object
        The first frame's features (default ``"blob"``, the scene policy's;
        :func:`~primspace.act.frame_features.frame_features`).
    length_scale : "auto" or float
        One length ``ℓ`` (> 0) for every standardised feature, or ``"auto"``: one per feature, by K-fold.
    penalty : "auto" or float
        ``λ`` (> 0), or ``"auto"``: by K-fold.
    per_label : bool
        One map per label (labels needed in fit and predict) or one for all.
    folds : int
        Folds of the choice (>= 2); a group with at most this many demonstrations leaves one out at a time.
    random_state : int
        Seed of the folds (>= 0).

    Attributes
    ----------
    features_ : object
        The fitted transformer of frames.
    choices_ : dict
        Label (None for all) -> ``{"length_scale": [one per feature], "penalty", "score"}``: the setting
        used and its K-fold MSE (``score`` None when both were given).
    """

    def __init__(
        self,
        features="blob",
        length_scale="auto",
        penalty="auto",
        per_label: bool = True,
        folds=CV_FOLDS,
        random_state=0,
    ) -> None:
        frame_features(features)  # a bad name fails here, not in fit
        _checked(length_scale, "length_scale")
        _checked(penalty, "penalty")
        if isinstance(folds, bool) or not isinstance(folds, (int, np.integer)) or folds < 2:
            raise UserError(f"folds must be a whole number >= 2, got {folds!r}")
        if isinstance(random_state, bool) or not isinstance(random_state, (int, np.integer)) or random_state < 0:
            raise UserError(f"random_state must be a whole number >= 0, got {random_state!r}")
        self.features, self.length_scale, self.penalty = features, length_scale, penalty
        self.per_label, self.folds, self.random_state = bool(per_label), int(folds), int(random_state)

    def fit(self, motor, labels=None, lengths=None, frames=None) -> KernelRidgePeer:
        """Fit the features, choose each group's setting by K-fold and fit its map (class docstring); returns self."""
        motor, labels, lengths, first = self._fit_data(motor, labels, lengths, frames)
        self.features_ = frame_features(self.features)
        rows = np.asarray(self.features_.fit_transform(first), dtype=np.float64)
        valid = np.repeat(valid_mask(lengths, motor.shape[1]), motor.shape[2], axis=1)  # (m, T·J), step-major
        self.maps_, self.choices_ = {}, {}
        for key, idx in self._groups(labels, len(motor)).items():
            if len(idx) < 2:
                raise UserError(f"{type(self).__name__}: label {key} has {len(idx)} demonstration: at least 2")
            x_mean, x_scale = _standardised(rows[idx])
            y_mean, y_scale = _standardised(motor[idx].reshape(len(idx), -1))
            x, z = (rows[idx] - x_mean) / x_scale, (motor[idx].reshape(len(idx), -1) - y_mean) / y_scale
            seed = [self.random_state, 50, 0 if key is None else int(key) + 1]
            ells, penalty, score = self._choose(x, z, y_scale, valid[idx], seed)
            coef = np.linalg.solve(_rbf(x / ells, x / ells) + penalty * np.eye(len(x)), z)
            self.maps_[key] = (x_mean, x_scale * ells, x / ells, coef, y_mean, y_scale)
            self.choices_[key] = {"length_scale": ells.tolist(), "penalty": penalty, "score": score}
        self._fitted(motor, labels)
        return self

    def _choose(self, x, z, y_scale, valid, seed) -> tuple[np.ndarray, float, float | None]:
        """The lengths (d,) and penalty with the lowest K-fold MSE of one group, and that MSE (class docstring)."""
        fixed_length, fixed_penalty = _checked(self.length_scale, "length_scale"), _checked(self.penalty, "penalty")
        penalties = PENALTY_GRID if fixed_penalty is None else (fixed_penalty,)
        starts = LENGTH_GRID if fixed_length is None else (fixed_length,)
        d = x.shape[1]
        if fixed_length is not None and fixed_penalty is not None:
            return np.full(d, fixed_length), fixed_penalty, None
        fold_of = fold_split([np.arange(len(x))], len(x), seed, self.folds)
        best: tuple = (np.inf, None, None)

        def consider(ells: np.ndarray) -> tuple:
            scores = self._fold_scores(x / ells, z, y_scale, valid, fold_of, penalties)
            i = int(np.argmin(scores))  # the first penalty on a tie
            return (float(scores[i]), ells, penalties[i]) if scores[i] < best[0] else best

        for ell in starts:
            best = consider(np.full(d, float(ell)))
        if fixed_length is None and d > 1:
            for _ in range(SWEEPS):
                for j in range(d):
                    for ell in LENGTH_GRID:
                        if ell != best[1][j]:
                            best = consider(np.where(np.arange(d) == j, float(ell), best[1]))
        return best[1], float(best[2]), best[0]

    @staticmethod
    def _fold_scores(x, z, y_scale, valid, fold_of, penalties) -> np.ndarray:
        """The K-fold MSE (scaled units, valid entries) of each penalty on features ``x`` already divided
        by their lengths: one eigendecomposition per fold serves every penalty."""
        errors, count = np.zeros(len(penalties)), 0
        for fold in np.unique(fold_of):
            test, train = fold_of == fold, fold_of != fold
            count += int(valid[test].sum())
            values, vectors = np.linalg.eigh(_rbf(x[train], x[train]))
            projected, cross = vectors.T @ z[train], _rbf(x[test], x[train]) @ vectors
            for i, penalty in enumerate(penalties):
                predicted = cross @ (projected / (values + penalty)[:, None])
                errors[i] += float(((((predicted - z[test]) * y_scale) ** 2)[valid[test]]).sum())
        return errors / max(count, 1)

    def predict(self, motor, observed, labels=None, lengths=None, frames=None) -> np.ndarray:
        """The predicted motion of each sample's first frame, ``(n, T, J)`` (class docstring).

        Parameters
        ----------
        motor : array-like, shape (n, T, J)
            The test samples: only their shape is read (T as fitted).
        observed : array-like of bool, shape (n, T), or an Observation rule
            Checked, not read: the scene alone predicts.
        labels : array-like of int, optional
            The test samples' primitives (needed when ``per_label``).
        lengths : array-like of int, optional
            Valid steps per test sample (the last valid step is held over the padding).
        frames : array-like, shape (n, T, H, W, 3) uint8
            Their frames; only the first of each is read.
        """
        (n, steps), labels, lengths, first = self._query(motor, observed, labels, lengths, frames, same_steps=True)
        rows = np.asarray(self.features_.transform(first), dtype=np.float64)
        keys = [self._key(labels, i) for i in range(n)]
        out = np.empty((n, steps * self.n_joints_))
        for key in dict.fromkeys(keys):
            which = np.flatnonzero([k == key for k in keys])
            x_mean, x_scale, x, coef, y_mean, y_scale = self.maps_[key]
            out[which] = _rbf((rows[which] - x_mean) / x_scale, x) @ coef * y_scale + y_mean
        out = out.reshape(n, steps, self.n_joints_)
        last = out[np.arange(n), lengths - 1]
        return np.where(valid_mask(lengths, steps)[..., None], out, last[:, None])
