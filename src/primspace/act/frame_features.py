"""Features of camera frames for the predictors that read the scene.

A scene is its first camera frame, ``(H, W, 3)`` uint8 (48x64 in the simulated presets: a
Franka arm at its home pose over a table, and a small red block). The transformers here turn
frames ``(n, H, W, 3)`` into feature rows ``(n, d)`` float64, scikit-learn style
(``fit(frames)``, ``transform(frames)``, ``fit_transform(frames)``):

* :class:`PixelPCA`: the principal components of the flattened pixels (scaled to [0, 1]);
* :class:`ColourBlob`: the mass and centroid of the pixels of one colour (by default the block's);
* :class:`PixelVector`: the flattened pixels themselves, scaled to [0, 1];
* :class:`LearnedKeypoints`: K keypoints ``(x, y)`` and their presence, of a small CNN with a
  spatial softmax fitted as a spatial autoencoder on the given frames only (no colour, label or
  object given).

Why a colour blob: the block is 2-4 pixels wide in a 48x64 frame, and its position and size are
all that a motion given only the scene depends on (the arm starts at the same home pose and the
table is the same in every scene). The principal components of the pixels spend their variance
on the arm and the table's shading, and a block of a few pixels moves little of it; three
numbers (mass, column, row) say where the block is directly. It is told the block's colour, so
it is the ablation of :class:`LearnedKeypoints`, which is told nothing but the frames.

:func:`frame_features` resolves a name (``"pca"``, ``"blob"``, ``"pixels"``, ``"learned"``) or an object with
``fit`` and ``transform`` to a transformer.
"""

from __future__ import annotations

import copy

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.decomposition import PCA

from primspace.utils.errors import UserError

__all__ = [
    "BLOCK_COLOUR",
    "PixelPCA",
    "ColourBlob",
    "PixelVector",
    "LearnedKeypoints",
    "FEATURE_NAMES",
    "frame_features",
    "check_frames",
]

#: The block's colour, rgba 0.85 0.05 0.05 in 0-255.
BLOCK_COLOUR = (217, 13, 13)

#: The names :func:`frame_features` resolves.
FEATURE_NAMES = ("pca", "blob", "pixels", "learned")


def check_frames(frames, name: str = "frames") -> np.ndarray:
    """``frames`` as a non-empty uint8 ``(n, H, W, 3)`` array, or one UserError."""
    arr = np.asarray(frames)
    if arr.ndim != 4 or arr.shape[-1] != 3 or 0 in arr.shape:
        raise UserError(f"{name} must be a non-empty (n, H, W, 3) array of colour frames, got shape {arr.shape}")
    if arr.dtype != np.uint8:
        raise UserError(f"{name} must be uint8 (0-255), got dtype {arr.dtype}")
    return arr


class _FrameTransformer(BaseEstimator):
    """What the transformers share: the frame size seen in fit, ``fit_transform``."""

    def _remember(self, frames: np.ndarray) -> None:
        self.frame_shape_ = tuple(frames.shape[1:])

    def _checked(self, frames) -> np.ndarray:
        """Checked frames of the size seen in fit (one UserError before fit or on another size)."""
        if not hasattr(self, "frame_shape_"):
            raise UserError(f"{type(self).__name__}: call fit before transform")
        frames = check_frames(frames)
        if tuple(frames.shape[1:]) != self.frame_shape_:
            raise UserError(
                f"frames are {frames.shape[1:]} but {type(self).__name__} was fitted on {self.frame_shape_}"
            )
        return frames

    def fit_transform(self, frames, y=None) -> np.ndarray:
        """:meth:`fit` then :meth:`transform` on the same frames."""
        return self.fit(frames).transform(frames)


def _flat(frames: np.ndarray) -> np.ndarray:
    """``(n, H*W*3)`` float64 in [0, 1]."""
    return frames.reshape(len(frames), -1).astype(np.float64) / 255.0


class PixelVector(_FrameTransformer):
    """The flattened pixels scaled to [0, 1], ``(n, H*W*3)``; ``fit`` records the frame size."""

    def fit(self, frames, y=None) -> PixelVector:
        """Record the frame size; returns self."""
        self._remember(check_frames(frames))
        return self

    def transform(self, frames) -> np.ndarray:
        """The pixels of each frame, ``(n, H*W*3)`` float64 in [0, 1]."""
        return _flat(self._checked(frames))


class PixelPCA(_FrameTransformer):
    """The principal components of the flattened pixels (scaled to [0, 1]).

    Parameters
    ----------
    n_components : int
        Components kept, capped at ``n - 1`` for ``n`` fitted frames (and at the pixel count).
    random_state : int
        Seed of scikit-learn's ``PCA`` (its randomised solver), so the result is repeatable.

    Attributes
    ----------
    pca_ : sklearn.decomposition.PCA
        The fitted PCA.
    n_components_ : int
        The components kept.
    """

    def __init__(self, n_components: int = 20, random_state: int = 0) -> None:
        if not isinstance(n_components, (int, np.integer)) or n_components < 1:
            raise UserError(f"n_components must be a whole number >= 1, got {n_components!r}")
        self.n_components = n_components
        self.random_state = random_state

    def fit(self, frames, y=None) -> PixelPCA:
        """Fit the PCA on ``frames`` ``(n, H, W, 3)`` uint8 (n >= 2); returns self."""
        frames = check_frames(frames)
        if len(frames) < 2:
            raise UserError("PixelPCA needs at least 2 frames to fit")
        flat = _flat(frames)
        self.n_components_ = int(min(self.n_components, len(frames) - 1, flat.shape[1]))
        self.pca_ = PCA(n_components=self.n_components_, random_state=self.random_state).fit(flat)
        self._remember(frames)
        return self

    def transform(self, frames) -> np.ndarray:
        """The components of each frame, ``(n, n_components_)`` float64."""
        return np.asarray(self.pca_.transform(_flat(self._checked(frames))), dtype=np.float64)


def _check_colour(colour) -> np.ndarray:
    arr = np.asarray(colour, dtype=np.float64) if np.ndim(colour) == 1 else np.zeros(0)
    if arr.shape != (3,) or not np.all((arr >= 0) & (arr <= 255)):
        raise UserError(f"colour must be three numbers in 0-255 (r, g, b), got {colour!r}")
    if np.sum(arr == arr.max()) > 1:
        raise UserError(f"colour must have one dominant channel (e.g. red (217, 13, 13)), got {colour!r}")
    return arr


class ColourBlob(_FrameTransformer):
    """The mass and centroid of the pixels of one colour: ``[mass, u, v]`` per frame.

    A pixel's weight is ``w = clip((excess - threshold) / soft, 0, 1)``, where ``excess`` is
    how much the colour's dominant channel exceeds the pixel's other two channels (for the red
    block, ``R - max(G, B)``). The features are ``mass = sum w`` (pixels, about the block's
    area), and the weighted centroid ``u`` (column) and ``v`` (row), in pixel coordinates
    (the centre of pixel ``[row, col]`` is ``u = col, v = row``). A frame with mass 0 (no such
    pixel) gets the mean centroid of the fitted frames that had some (the frame's centre when
    none had).

    Parameters
    ----------
    colour : sequence of 3 numbers
        The colour in 0-255; it must have one dominant channel. Default :data:`BLOCK_COLOUR`.
    threshold : float
        The excess (0-255 units) below which a pixel weighs nothing; the table
        (0.72 0.60 0.45, an excess of about 31 on red) stays below the default.
    soft : float
        The excess above the threshold at which a pixel weighs 1 (> 0).

    Attributes
    ----------
    channel_ : int
        The colour's dominant channel.
    centroid_ : ndarray, shape (2,)
        The fit-time mean ``[u, v]``, given to frames with no such pixel.
    """

    def __init__(self, colour=BLOCK_COLOUR, threshold: float = 50.0, soft: float = 100.0) -> None:
        _check_colour(colour)
        if not np.isfinite(threshold):
            raise UserError(f"threshold must be a finite number, got {threshold!r}")
        if not (np.isfinite(soft) and soft > 0):
            raise UserError(f"soft must be a positive number, got {soft!r}")
        self.colour, self.threshold, self.soft = colour, threshold, soft

    def weights(self, frames) -> np.ndarray:
        """Each pixel's weight, ``(n, H, W)`` in [0, 1] (needs no fit)."""
        frames = check_frames(frames).astype(np.float64)
        channel = int(np.argmax(_check_colour(self.colour)))
        others = [c for c in range(3) if c != channel]
        excess = frames[..., channel] - np.maximum(frames[..., others[0]], frames[..., others[1]])
        return np.clip((excess - float(self.threshold)) / float(self.soft), 0.0, 1.0)

    def _moments(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mass ``(n,)`` and centroid ``(n, 2)`` (NaN where the mass is 0)."""
        w = self.weights(frames)
        rows, cols = np.indices(w.shape[1:], dtype=np.float64)
        mass = w.sum(axis=(1, 2))
        with np.errstate(invalid="ignore", divide="ignore"):
            u = (w * cols).sum(axis=(1, 2)) / mass
            v = (w * rows).sum(axis=(1, 2)) / mass
        centroid = np.where(mass[:, None] > 0, np.stack([u, v], axis=1), np.nan)
        return mass, centroid

    def fit(self, frames, y=None) -> ColourBlob:
        """Record the mean centroid of ``frames`` (for frames without the colour); returns self."""
        frames = check_frames(frames)
        self.channel_ = int(np.argmax(_check_colour(self.colour)))
        mass, centroid = self._moments(frames)
        if np.any(mass > 0):
            self.centroid_ = centroid[mass > 0].mean(axis=0)
        else:
            height, width = frames.shape[1:3]
            self.centroid_ = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        self._remember(frames)
        return self

    def transform(self, frames) -> np.ndarray:
        """``[mass, u, v]`` of each frame, ``(n, 3)`` float64."""
        mass, centroid = self._moments(self._checked(frames))
        centroid = np.where(np.isnan(centroid), self.centroid_[None, :], centroid)
        return np.column_stack([mass, centroid])


def _whole(value, name: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise UserError(f"{name} must be a whole number >= {low}, got {value!r}")
    return int(value)


class LearnedKeypoints(_FrameTransformer):
    """K keypoints ``(x, y)`` and their presence per frame, learned from the fitted frames alone.

    The encoder is the model's :class:`~primspace.model.keypoints.KeypointEncoder` (a small
    CNN and a spatial softmax), fitted as a deep spatial autoencoder (Finn et al. 2016) on the
    frames given to :meth:`fit` and nothing else: frames -> keypoints -> Gaussian heatmaps ->
    the frame in grey at half size (:func:`~primspace.train.vision_start.fit_keypoint_encoder`).
    What is the same in every frame is drawn by the decoder's learned background; what differs
    between the frames (in a scene's first frame: the object's place and size) has to pass
    through the keypoints. No colour, label or object is given.

    A frame is read through the encoder's K feature maps *relative to the fitted frames*: each
    map minus its mean over the fitted frames, in units of its spread over them (``r_k``), so
    that what is the same in every scene (the arm at its home pose, the table) reads as zero.
    Each map's weights are ``w_k = max(|r_k| - threshold, 0)``: the keypoint ``k`` is their
    centroid ``(x, y)`` and its presence their sum (how much of the frame differs there, about
    an object's area); a frame where a map has no weight gets that map's mean centroid over
    the fitted frames. On the paper preset's first frames the encoder's own spatial softmax
    moves by a tenth of a pixel; read this way the keypoints follow the block (docs/act.md).

    Parameters
    ----------
    keypoints : int
        K (>= 1); the features are ``(x_1, ..., x_K, y_1, ..., y_K, p_1, ..., p_K)``: the points in
        ``[-1, 1]`` (``x`` from the left edge to the right, ``y`` from the top row to the
        bottom), then the presences (>= 0).
    steps : int
        Adam steps of the autoencoder (batches of 64 frames; whole epochs, at least one).
    threshold : float
        Spreads of a map below which a cell weighs nothing (>= 0).
    random_state : int
        Seed of the weights and of the frames drawn: same seed, same features (one machine).

    Attributes
    ----------
    encoder_ : primspace.model.keypoints.KeypointEncoder
        The fitted encoder, frozen.
    mean_maps_, spread_ : torch.Tensor
        The maps' mean ``(K, h, w)`` over the fitted frames and their spread ``(K, 1, 1)``.
    centroid_ : ndarray, shape (2K,)
        The mean keypoints of the fitted frames, given to a map without weight.
    """

    def __init__(self, keypoints: int = 8, steps: int = 200, threshold: float = 1.0, random_state: int = 0) -> None:
        _whole(keypoints, "keypoints", 1)
        _whole(steps, "steps", 1)
        _whole(random_state, "random_state", 0)
        if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.number)) or not threshold >= 0:
            raise UserError(f"threshold must be a number >= 0, got {threshold!r}")
        self.keypoints, self.steps, self.threshold, self.random_state = keypoints, steps, threshold, random_state

    def fit(self, frames, y=None) -> LearnedKeypoints:
        """Fit the encoder and the maps' mean and spread on ``frames`` ``(n, H, W, 3)`` uint8 (n >= 2); returns self."""
        from primspace.train.vision_start import BATCH_FRAMES, FRAMES_PER_EPOCH, fit_keypoint_encoder

        frames = check_frames(frames)
        if len(frames) < 2:
            raise UserError("LearnedKeypoints needs at least 2 frames to fit")
        per_epoch = -(-min(len(frames), FRAMES_PER_EPOCH) // BATCH_FRAMES)
        epochs = max(1, -(-int(self.steps) // per_epoch))
        lengths = np.ones(len(frames), dtype=np.int64)
        self.encoder_ = fit_keypoint_encoder(
            frames[:, None], lengths, int(self.keypoints), int(self.random_state), epochs
        )
        maps = self._maps(frames)
        self.mean_maps_ = maps.mean(dim=0)
        self.spread_ = (maps - self.mean_maps_).flatten(2).std(dim=(0, 2)).view(-1, 1, 1).clamp_min(1e-9)
        points = self._read(maps)[:, : 2 * int(self.keypoints)]
        seen = np.isfinite(points)
        self.centroid_ = np.where(seen, points, 0.0).sum(axis=0) / np.maximum(seen.sum(axis=0), 1)
        self._remember(frames)
        return self

    def _maps(self, frames: np.ndarray):
        """The encoder's K feature maps ``(n, K, h, w)`` float64 of uint8 frames, 256 at a time."""
        import torch
        import torch.nn.functional as F

        out = []
        with torch.no_grad():
            for start in range(0, len(frames), 256):
                block = torch.from_numpy(np.ascontiguousarray(frames[start : start + 256]))
                x = block.float().div(255.0).permute(0, 3, 1, 2)
                out.append(self.encoder_.conv2(F.relu(self.encoder_.conv1(x))).double())
        return torch.cat(out)

    def _read(self, maps) -> np.ndarray:
        """``(n, 3K)``: each map's weighted centroid (NaN where it has no weight) and its weight."""
        import torch

        from primspace.model.keypoints import pixel_grid

        weights = torch.relu(((maps - self.mean_maps_) / self.spread_).abs() - float(self.threshold))
        xs, ys = pixel_grid(maps.shape[2], maps.shape[3], dtype=torch.float64)
        mass = weights.sum(dim=(2, 3))
        with np.errstate(invalid="ignore", divide="ignore"):
            x = ((weights.sum(dim=2) * xs).sum(dim=2) / mass).numpy()
            y = ((weights.sum(dim=3) * ys).sum(dim=2) / mass).numpy()
        return np.column_stack([x, y, mass.numpy()])

    def transform(self, frames) -> np.ndarray:
        """The keypoints and presences of each frame, ``(n, 3K)`` float64 (class docstring)."""
        out = self._read(self._maps(self._checked(frames)))
        points = out[:, : 2 * int(self.keypoints)]
        out[:, : 2 * int(self.keypoints)] = np.where(np.isfinite(points), points, self.centroid_[None, :])
        return out


def frame_features(features, random_state: int | None = None):
    """The transformer of frames named by ``features``.

    Parameters
    ----------
    features : str or object
        ``"pca"`` (:class:`PixelPCA`), ``"blob"`` (:class:`ColourBlob` of the block),
        ``"pixels"`` (:class:`PixelVector`) or ``"learned"`` (:class:`LearnedKeypoints`), or an object with ``fit(frames)`` and
        ``transform(frames)``: a copy of it is returned (scikit-learn's ``clone`` when it has
        ``get_params``), so fitting it leaves the caller's object as it was.
    random_state : int, optional
        The seed of ``"learned"`` (default 0); the other names draw nothing that it would seed.

    Returns
    -------
    object
        An unfitted transformer of frames ``(n, H, W, 3)`` uint8 into rows ``(n, d)``.
    """
    if isinstance(features, str):
        makers = {"pca": PixelPCA, "blob": ColourBlob, "pixels": PixelVector, "learned": LearnedKeypoints}
        if features not in makers:
            raise UserError(f"unknown frame features {features!r}: use one of {', '.join(FEATURE_NAMES)}")
        if features == "learned" and random_state is not None:
            return LearnedKeypoints(random_state=random_state)
        return makers[features]()
    if not (callable(getattr(features, "fit", None)) and callable(getattr(features, "transform", None))):
        raise UserError(
            f"frame features must be one of {', '.join(FEATURE_NAMES)} or an object with fit and transform, "
            f"got {features!r}"
        )
    if hasattr(features, "get_params"):
        from sklearn.base import clone

        return clone(features)
    return copy.deepcopy(features)
