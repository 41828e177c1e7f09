"""The vision-informed start ``projection-vision``: codes from a random projection of the motor
sequence together with the keypoint trajectories of its frames.

The paper leaves it as future work (*Summary and Discussion*): "visual perception information is
not used to initialize encodings. The problem here is only a small portion of each perceived image
is relevant to motion, the rest is a background noise which will clutter random projection. Some
attention mechanism will potentially alleviate the problem." The attention here is a keypoint
encoder (:class:`~primspace.model.keypoints.KeypointEncoder`, spatial softmax), fitted before
training as a *deep spatial autoencoder* (Finn et al. 2016):

* frames -> encoder -> K keypoints ``(x, y)`` in ``[-1, 1]`` -> Gaussian heatmaps
  (:func:`~primspace.model.keypoints.heatmaps`) -> a small convolutional decoder plus a learned
  background (started at the mean frame), reconstructing the frame downsampled to half its size
  in grey; :data:`VISION_EPOCHS` epochs of Adam on the valid frames of the fitted demonstrations
  only, seeded (same seed, same numbers on one machine);
* the encoder frozen, each sample's keypoint trajectory ``k_{1:T}`` (``T x 2K``) is scaled as the
  joints are, each coordinate's range over the fitted demonstrations' valid steps onto
  ``[-1, 1]`` (a :class:`~primspace.data.JointScaler`; the keypoints of a scene move over a small
  part of the image, so their raw range is narrow), zero after the sample's last valid step, and
  projected exactly as the motor is (:class:`~primspace.model.latent.LatentInitializer` ``projection``,
  ``P_jk ~ N(0, 1/q)``): ``z = P_m m_{1:T} + P_v k_{1:T}``, which is ``P [m; k]`` for the
  concatenated sequence with ``P = [P_m P_v]``. ``P_m`` is the motor-only start's matrix (the
  same seed), so with K = 0 the start is the motor-only projection, and frames that are the same
  in every sample move every code by one vector.

The encoder's weights, the keypoints' scaler, ``P_m`` and ``P_v`` are the run's initialiser (:class:`VisionProjection`),
saved in its checkpoint like ``P``: :func:`~primspace.train.infer` reads new samples' frames through
the same frozen encoder and matrices. Under an observation rule only the observed steps' joints
and frames count (the rest zero, as the motor projection does).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from primspace.data import JointScaler
from primspace.model.keypoints import KeypointEncoder, heatmaps
from primspace.model.latent import VISION_PROJECTION, LatentInitializer
from primspace.utils.errors import UserError

__all__ = [
    "VISION_PROJECTION",
    "VISION_KEYPOINTS",
    "VISION_EPOCHS",
    "SpatialAutoencoder",
    "fit_keypoint_encoder",
    "keypoint_trajectories",
    "valid_steps",
    "VisionProjection",
    "initializer_from_state",
]

#: K of the start's encoder when the model has no keypoints of its own (``ModelConfig.keypoints``).
VISION_KEYPOINTS = 4
#: Epochs of the spatial autoencoder.
VISION_EPOCHS = 10
#: Frames drawn per epoch (at most; every valid frame when fewer), per batch, and Adam's step size.
FRAMES_PER_EPOCH = 2048
BATCH_FRAMES = 32
LEARNING_RATE = 3e-3


class SpatialAutoencoder(nn.Module):
    """Frames -> K keypoints -> heatmaps -> a grey frame of ``size`` (Finn et al. 2016).

    The decoder is a learned background image plus two convolutions of the heatmaps, so
    what moves between frames has to pass through the keypoints.
    """

    def __init__(self, keypoints: int, size: tuple[int, int], hidden: int = 16) -> None:
        super().__init__()
        self.size = (int(size[0]), int(size[1]))
        self.encoder = KeypointEncoder(keypoints)
        self.background = nn.Parameter(torch.zeros(1, 1, *self.size))
        self.draw1 = nn.Conv2d(keypoints, hidden, kernel_size=3, padding=1)
        self.draw2 = nn.Conv2d(hidden, 1, kernel_size=3, padding=1)

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        """``(N, H, W, 3)`` uint8 frames -> ``(N, 1, h, w)`` grey reconstructions."""
        maps = heatmaps(self.encoder(frames), *self.size)
        return self.background + self.draw2(F.relu(self.draw1(maps)))


def grey_target(frames: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """``(N, H, W, 3)`` uint8 frames -> ``(N, 1, h, w)`` grey in [0, 1], area-downsampled to ``size``."""
    grey = frames.float().div(255.0).mean(dim=3, keepdim=True).permute(0, 3, 1, 2)
    return F.adaptive_avg_pool2d(grey, size)


def _valid_frames(images, lengths: np.ndarray) -> np.ndarray:
    """Every valid frame (N, H, W, 3) uint8 of ``images`` (n, T, H, W, 3)."""
    return np.concatenate([np.asarray(images[i])[: int(n)] for i, n in enumerate(lengths)])


def fit_keypoint_encoder(
    images, lengths: np.ndarray, keypoints: int, seed: int, epochs: int = VISION_EPOCHS
) -> KeypointEncoder:
    """A :class:`KeypointEncoder` fitted as a spatial autoencoder on the valid frames of ``images``.

    Parameters
    ----------
    images : array-like (n, T, H, W, 3) uint8
        The fitted demonstrations' frames.
    lengths : ndarray (n,)
        Their valid steps.
    keypoints : int
        K (> 0).
    seed : int
        Seeds the weights and the frames drawn; the fit runs on the CPU, in eval mode after.
    epochs : int
        Passes of at most :data:`FRAMES_PER_EPOCH` frames each.
    """
    frames = torch.from_numpy(_valid_frames(images, lengths))
    size = (max(1, frames.shape[1] // 2), max(1, frames.shape[2] // 2))
    rng = np.random.default_rng(seed)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = SpatialAutoencoder(keypoints, size)
    target = grey_target(frames, size)
    with torch.no_grad():
        model.background.copy_(target.mean(dim=0, keepdim=True))
    optimizer = torch.optim.Adam(model.parameters(), lr=LEARNING_RATE)
    for _ in range(int(epochs)):
        order = rng.permutation(len(frames))[:FRAMES_PER_EPOCH]
        for start in range(0, len(order), BATCH_FRAMES):
            batch = torch.from_numpy(order[start : start + BATCH_FRAMES])
            loss = F.mse_loss(model(frames[batch]), target[batch])
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    return model.encoder.eval().requires_grad_(False)


def valid_steps(lengths, steps: int) -> np.ndarray:
    """``(n, T)`` bool: the valid steps of samples of ``lengths``."""
    return np.arange(steps)[None, :] < np.asarray(lengths)[:, None]


def keypoint_trajectories(encoder: KeypointEncoder, images, lengths: np.ndarray) -> np.ndarray:
    """``(n, T, 2K)`` float64: each sample's keypoints ``(x_1, y_1, ..., x_K, y_K)`` per step in
    ``[-1, 1]``, zero after its valid steps. One sample per forward pass, so a sample's
    trajectory does not depend on the others."""
    out = []
    with torch.no_grad():
        for i, n in enumerate(lengths):
            frames = torch.from_numpy(np.ascontiguousarray(np.asarray(images[i])))
            points = encoder(frames).reshape(frames.shape[0], -1).double().numpy()
            points[int(n) :] = 0.0
            out.append(points)
    return np.stack(out)


class VisionProjection:
    """The ``projection-vision`` initialiser: ``z = P_m m + P_v k`` (module docstring).

    The same surface as :class:`~primspace.model.latent.LatentInitializer` (``method``,
    ``latent_dim``, ``window``, ``fit``, ``transform``, ``state_dict``), except that ``fit``
    and ``transform`` also read the samples' frames and valid lengths.

    Parameters
    ----------
    latent_dim : int
        q.
    keypoints : int
        K of the encoder; 0: no vision part (the motor-only projection).
    random_state : int
        Seed of ``P_m`` (as the motor-only start's), of ``P_v`` and of the encoder.
    window : int, optional
        One code per window of this many steps (:class:`LatentInitializer`).
    epochs : int
        Epochs of the spatial autoencoder.
    """

    method = VISION_PROJECTION

    def __init__(
        self,
        latent_dim: int = 20,
        keypoints: int = VISION_KEYPOINTS,
        random_state: int = 0,
        window: int | None = None,
        epochs: int = VISION_EPOCHS,
    ) -> None:
        if not isinstance(keypoints, int) or keypoints < 0:
            raise UserError(f"projection-vision: keypoints must be a whole number >= 0, got {keypoints!r}")
        self.latent_dim, self.keypoints, self.random_state = int(latent_dim), keypoints, int(random_state)
        self.window, self.epochs = window, int(epochs)
        self.motor = LatentInitializer("projection", self.latent_dim, self.random_state, window)
        self.vision = LatentInitializer("projection", self.latent_dim, self._seeds()[0], window)
        self.encoder: KeypointEncoder | None = None
        self.scaler: JointScaler | None = None

    def _seeds(self) -> tuple[int, int]:
        """The seeds of ``P_v`` and of the encoder, derived from ``random_state``."""
        a, b = np.random.SeedSequence([self.random_state, 1]).generate_state(2, dtype=np.uint32)
        return int(a), int(b)

    def fit(self, scaled_motor, images, lengths) -> VisionProjection:
        """Draw ``P_m``, fit the encoder on the valid frames of ``images`` and the keypoints' scaler
        on their valid steps, draw ``P_v``."""
        lengths = np.asarray(lengths)
        self.motor.fit(scaled_motor)
        if self.keypoints:
            _check_images(images)
            self.encoder = fit_keypoint_encoder(images, lengths, self.keypoints, self._seeds()[1], self.epochs)
            raw = keypoint_trajectories(self.encoder, images, lengths)
            self.scaler = JointScaler().fit(raw[valid_steps(lengths, raw.shape[1])])
            self.vision.fit(np.zeros((1, np.shape(scaled_motor)[1], 2 * self.keypoints)))
        return self

    def trajectories(self, images, lengths) -> np.ndarray:
        """The samples' keypoint trajectories ``(n, T, 2K)`` through the frozen encoder, scaled
        (zero after each sample's valid steps)."""
        self._check_fitted()
        raw = keypoint_trajectories(self.encoder, images, np.asarray(lengths))
        return self.scaler.transform(raw) * valid_steps(lengths, raw.shape[1])[..., None]

    def transform(
        self, scaled_motor, *, random_state: int | None = None, observed=None, images=None, lengths=None
    ) -> np.ndarray:
        """Initial codes ``(n, K·q)`` (float32) of the samples' motor ``(n, T, J)`` and frames
        ``images`` ``(n, T, H, W, 3)`` with ``lengths`` valid steps; ``observed`` (n, T): only
        those steps count. ``random_state`` is unused (the start draws nothing per sample)."""
        self.motor._check_fitted()
        codes = self.motor.transform(scaled_motor, observed=observed).astype(np.float64)
        if self.keypoints:
            if images is None:
                raise UserError(
                    "init 'projection-vision' reads the samples' frames, and none were given: "
                    "start by 'projection', 'zero' or 'random'"
                )
            _check_images(images)
            lengths = np.full(len(codes), np.shape(scaled_motor)[1]) if lengths is None else lengths
            codes += self.vision.transform(self.trajectories(images, lengths), observed=observed)
        return codes.astype(np.float32)

    def _check_fitted(self) -> None:
        if self.keypoints and self.encoder is None:
            raise UserError("VisionProjection is not fitted; call fit first")

    def state_dict(self) -> dict:
        """Everything needed to rebuild it: ``P_m``, ``P_v`` and the encoder's weights."""
        self._check_fitted()
        return {
            "method": self.method,
            "latent_dim": self.latent_dim,
            "keypoints": self.keypoints,
            "random_state": self.random_state,
            "window": self.window,
            "epochs": self.epochs,
            "motor": self.motor.state_dict(),
            "vision": self.vision.state_dict() if self.keypoints else None,
            "encoder": None if self.encoder is None else self.encoder.state_dict(),
            "scaler": None if self.scaler is None else self.scaler.to_dict(),
        }

    @classmethod
    def from_state_dict(cls, state: dict) -> VisionProjection:
        """The initialiser :meth:`state_dict` saved."""
        try:
            out = cls(
                int(state["latent_dim"]),
                int(state["keypoints"]),
                int(state["random_state"]),
                state["window"],
                int(state["epochs"]),
            )
            out.motor = LatentInitializer.from_state_dict(state["motor"])
            if out.keypoints:
                out.vision = LatentInitializer.from_state_dict(state["vision"])
                out.encoder = KeypointEncoder(out.keypoints)
                out.encoder.load_state_dict(state["encoder"])
                out.encoder.eval().requires_grad_(False)
                out.scaler = JointScaler.from_dict(state["scaler"])
        except (KeyError, TypeError, ValueError, RuntimeError) as exc:
            raise UserError(f"not a projection-vision state ({str(exc).splitlines()[0]})") from None
        return out


def _check_images(images) -> None:
    if images is None:
        raise UserError(
            "init 'projection-vision' reads the demonstrations' frames, and the data set has none: "
            "use data with frames (images), or start by 'projection'"
        )


def initializer_from_state(state: dict) -> LatentInitializer | VisionProjection:
    """The initialiser a checkpoint saved: a :class:`VisionProjection` or a :class:`LatentInitializer`."""
    if isinstance(state, dict) and state.get("method") == VISION_PROJECTION:
        return VisionProjection.from_state_dict(state)
    return LatentInitializer.from_state_dict(state)
