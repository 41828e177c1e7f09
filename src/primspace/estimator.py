"""The model in scikit-learn's words: :class:`AutoDecoder`.

The paper's system is an auto-decoder: no encoder, one latent code per demonstration
trained with the decoder's weights ("train"), and codes for new demonstrations found by
gradient descent with the weights frozen ("evaluation", paper *Main Results*). In
scikit-learn terms: ``fit_transform`` trains θ and the codes and returns the codes,
``transform`` infers codes for new data, ``inverse_transform`` decodes codes into motion.
It wraps :func:`~primspace.train.fit`, :func:`~primspace.train.infer`,
:func:`~primspace.train.reconstruct` and :func:`~primspace.predict.predict` (same seed, same
numbers) and, like them, works in memory unless given a checkpoint directory. It sits above
both :mod:`primspace.train` and :mod:`primspace.predict`: ``from primspace import AutoDecoder``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator

from primspace.data import MotionDataset
from primspace.model.config import ModelConfig
from primspace.predict import DEFAULT_PREDICT_EPOCHS, DEFAULT_PREDICTOR, predict
from primspace.train.api import evaluate, fit, infer, reconstruct
from primspace.train.config import TrainConfig
from primspace.train.run import TrainedRun
from primspace.train.rundir import load_run, write_run
from primspace.utils.errors import UserError, first_line

__all__ = ["AutoDecoder"]


class AutoDecoder(BaseEstimator):
    """An MTRNN decoder with one latent code per sample (Nikulin & Tani).

    Parameters
    ----------
    model_config : ModelConfig, optional
        Sizes of the decoder; J, T and the image size are taken from the data at ``fit``.
        Default: ``ModelConfig()``.
    train_config : TrainConfig, optional
        How to optimise (epochs, learning rates, seed ...). Default: ``TrainConfig()``.
    init : {"projection", "zero", "random", "pca"}
        How the codes start (paper: random linear projection ``P m``).
    images : bool, optional
        Train an image head on the data's frames (default: when the data has images).
    checkpoint_dir : path-like, optional
        Write the fit as a run directory there (checkpoints, metrics, codes; resumable
        with ``fit(..., resume=True)``). Default: in memory only.
    progress : bool, optional
        Progress bars (default: when stderr is a terminal).
    log_to : ("tensorboard", path-like), optional
        Also write the fit's per-epoch metrics (``history_``, ``metrics.jsonl``) as
        TensorBoard event files into that folder (:mod:`primspace.train.logger`; needs
        ``pip install 'primspace[tensorboard]'``). ``transform`` takes its own ``log_to``.

    Attributes
    ----------
    run_ : TrainedRun
        The fitted run: decoder, scaler, initialiser, codes, history.
    codes_ : ndarray (n_samples, latent_dim) float32
        The trained codes, in the order of the samples given to ``fit``.
    history_ : list of dict
        Per-epoch losses of the fit (epoch 0: the codes as initialised).
    inference_ : TrainedRun
        The last ``transform``'s run (its history holds the inference losses).

    Examples
    --------
    >>> model = AutoDecoder(ModelConfig(latent_dim=20), TrainConfig(epochs=800), init="projection")
    >>> Z = model.fit_transform(data)                 # doctest: +SKIP
    >>> Z_new = model.transform(new, epochs=600)      # doctest: +SKIP
    >>> motor, frames = model.inverse_transform(Z)    # doctest: +SKIP
    """

    def __init__(
        self,
        model_config: ModelConfig | None = None,
        train_config: TrainConfig | None = None,
        init: str = "projection",
        *,
        images: bool | None = None,
        checkpoint_dir: str | os.PathLike | None = None,
        progress: bool | None = None,
        log_to: tuple | None = None,
    ) -> None:
        self.model_config = model_config
        self.train_config = train_config
        self.init = init
        self.images = images
        self.checkpoint_dir = checkpoint_dir
        self.progress = progress
        self.log_to = log_to

    # ------------------------------------------------------------------ training
    def fit(self, X: MotionDataset, y=None, *, resume: bool = False, overwrite: bool = False) -> AutoDecoder:
        """Train θ and one code per sample of ``X`` (``y`` is ignored).

        ``resume`` / ``overwrite`` apply to ``checkpoint_dir`` (as in :func:`~primspace.train.fit`).
        """
        self.run_ = fit(
            X,
            self.checkpoint_dir,
            model_config=self.model_config,
            train_config=self.train_config,
            init=self.init,
            images=self.images,
            resume=resume,
            overwrite=overwrite,
            progress=self.progress,
            log_to=self.log_to,
        )
        self.codes_ = self.run_.latents
        self.history_ = self.run_.history
        self.fit_data_ = (
            X  # the fitted demonstrations, for the starts that read them (nearest, calibrated under observe)
        )
        return self

    def fit_transform(self, X: MotionDataset, y=None, **fit_params) -> np.ndarray:
        """Fit, then return the trained codes (n_samples, latent_dim), in ``X``'s order."""
        return self.fit(X, y, **fit_params).codes_

    def transform(
        self,
        X: MotionDataset,
        *,
        epochs: int | None = None,
        init: str | None = None,
        checkpoint_dir: str | os.PathLike | None = None,
        observe=None,
        observe_frames=None,
        log_to: tuple | None = None,
        **overrides,
    ) -> np.ndarray:
        """Codes for the samples of ``X`` with θ frozen (the paper's evaluation), in ``X``'s order.

        Parameters
        ----------
        epochs : int, optional
            Epochs of code optimisation (default: the fit's).
        init : str, optional
            How the new codes start (default: the fit's init, with its ``P``);
            ``"calibrated"``: ``P m`` mapped by the fit's ridge calibration onto where the
            fitted codes went (fits with ``projection`` or ``pca`` init); ``"nearest"``: the
            fitted code of the fitted sample whose (observed) motor is nearest.
        observe, observe_frames : optional
            Infer from a prefix of each motion: a fraction in (0, 1] of the valid steps, a
            number of steps, ``"none"``; frames also ``"first"`` (:func:`~primspace.train.infer`).
            The starts that read the fitted samples use those given to ``fit`` (after
            :meth:`load`: the run's data file).
        checkpoint_dir : path-like, optional
            Write the inference as a run directory (default: in memory).
        log_to : ("tensorboard", path-like), optional
            Also write the inference's per-epoch metrics as TensorBoard event files there
            (give it a folder of its own: not the fit's ``log_to``).
        **overrides
            Train-config fields for the inference, e.g. ``latent_lr=``, ``batch_size=``.
        """
        run = self._fitted()
        self.inference_ = infer(
            run,
            X,
            checkpoint_dir,
            epochs=run.train_config.epochs if epochs is None else epochs,
            init=init,
            progress=self.progress,
            observe=observe,
            observe_frames=observe_frames,
            fitted_data=getattr(self, "fit_data_", None),
            log_to=log_to,
            **overrides,
        )
        return self.inference_.latents

    def predict(
        self,
        X: MotionDataset,
        *,
        observe=0.25,
        observe_frames=None,
        init: str = DEFAULT_PREDICTOR,
        epochs: int | None = None,
        continuity: bool = True,
        fitted_data: MotionDataset | None = None,
        primitive=None,
        primitives: str = "labels",
        n_clusters: int | None = None,
        **overrides,
    ):
        """The rest of each motion of ``X`` from its observed beginning (docs/predict.md).

        The code is found from the observed entries only (``init``: ``"auto"``, the default, the
        predictor with the lowest K-fold error on the fitted demonstrations; ``"mixture"``, the
        posterior mean over the fitted codes; ``"prior"``; or a start followed by ``epochs`` of
        gradient inference, :func:`primspace.predict.predict`); the decoder's whole
        sequence is the prediction. ``continuity``: the residual at the last observed step
        decays to zero at the end. ``fitted_data``: the data set the model was fitted on
        (default: the one given to :meth:`fit`, else the run's data file). ``primitive``
        (a name such as ``"push"`` or an id), ``primitives`` (``"labels"`` or ``"clusters"``) and
        ``n_clusters``: the task of auto and the prior predictor (``init="prior"``), told the primitive
        of every motion or, without one, weighing its primitives by their posterior
        (:func:`primspace.predict.predict`; ``prediction_.details`` holds it).

        Returns
        -------
        (motor, frames)
            Joint values in physical units (n, T, J) float32 and frames (n, T, H, W, 3)
            uint8 (None without an image head). The :class:`~primspace.predict.Prediction`
            with the errors of the unobserved steps is kept as ``prediction_``.
        """
        fitted_data = getattr(self, "fit_data_", None) if fitted_data is None else fitted_data
        self.prediction_ = predict(
            self._fitted(),
            X,
            observe=observe,
            observe_frames=observe_frames,
            init=init,
            epochs=DEFAULT_PREDICT_EPOCHS if epochs is None else epochs,
            fitted_data=fitted_data,
            continuity=continuity,
            progress=self.progress,
            primitive=primitive,
            primitives=primitives,
            n_clusters=n_clusters,
            **overrides,
        )
        return self.prediction_.motor, self.prediction_.frames

    def inverse_transform(self, Z: np.ndarray, *, images: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Decode codes ``Z`` (n, latent_dim): joint values in physical units (n, T, J)
        float32, and frames (n, T, H, W, 3) uint8 (None without an image head or with
        ``images=False``).

        Raises
        ------
        UserError
            If ``Z`` is not a 2-D array of finite numbers with at least one row and one
            column per code value (one line saying which).
        """
        run = self._fitted()
        return reconstruct(run, _check_codes(Z, run.model_config.code_size), images=images)

    def score_samples(self, X: MotionDataset, Z: np.ndarray) -> dict:
        """The loss of codes ``Z`` on ``X`` (``loss``, ``motor``, ``vision``), as logged while training."""
        return evaluate(self._fitted(), X, Z)

    # ---------------------------------------------------------------- persistence
    def save(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write the fitted model as a run directory (what ``primspace train`` writes)."""
        return write_run(path, self._fitted(), overwrite=overwrite)

    @classmethod
    def load(cls, path: str | os.PathLike, *, progress: bool | None = None) -> AutoDecoder:
        """An AutoDecoder fitted from a run directory (written by :meth:`save`, ``fit`` or ``primspace train``)."""
        run = load_run(path)
        model = cls(
            run.model_config,
            run.train_config,
            run.init,
            images=run.config["data"]["images"],
            progress=progress,
        )
        model.run_, model.codes_, model.history_ = run, run.latents, run.history
        return model

    def _fitted(self) -> TrainedRun:
        run = getattr(self, "run_", None)
        if run is None:
            raise UserError("this AutoDecoder is not fitted yet: call fit (or AutoDecoder.load) first")
        return run

    def __sklearn_is_fitted__(self) -> bool:
        return getattr(self, "run_", None) is not None


def _check_codes(Z, q: int) -> np.ndarray:
    """``Z`` as a float32 array (n, q), n >= 1, finite; else one :class:`UserError` saying why."""
    try:
        z = np.asarray(Z)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise UserError(
            f"Z must be an array of numbers of shape (n, {q}), got {type(Z).__name__} ({first_line(exc)})"
        ) from None
    if z.dtype.kind not in "iuf":
        raise UserError(f"Z must hold numbers, got an array of dtype {z.dtype}")
    if z.ndim != 2 or z.shape[1] != q:
        raise UserError(f"Z must have shape (n, {q}): one row of {q} code values per sample, got {z.shape}")
    if z.shape[0] == 0:
        raise UserError(f"Z has no rows (shape {z.shape}): nothing to decode")
    bad = ~np.isfinite(z) | (np.abs(z) > np.finfo(np.float32).max)
    if bad.any():
        i, j = (int(v) for v in np.argwhere(bad)[0])
        raise UserError(f"Z[{i}, {j}] = {z[i, j]:g}: codes must be finite numbers within the float32 range")
    return z.astype(np.float32)
