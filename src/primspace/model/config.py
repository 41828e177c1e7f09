"""The decoder's sizes: :class:`ModelConfig` (saved as JSON in a run's ``config.json``).

Kept apart from :mod:`primspace.model.decoder` (the torch modules) so that reading or writing a
configuration, and the command line's defaults, do not import torch.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from primspace.utils.errors import UserError, config_from_dict

__all__ = ["ModelConfig", "check_image_size"]


@dataclass
class ModelConfig:
    """Sizes of the decoder (saved as JSON in a run's ``config.json``).

    Parameters
    ----------
    latent_dim : int
        q, the size of each latent code ``z``.
    layer_sizes : tuple of int
        Units per MTRNN layer, fastest first (paper: 32 fast, 12 slow).
    taus : tuple of float
        Time constant τ per layer, fastest first (each ≥ 1; the paper gives no values).
    top_input_size : int, optional
        Size of ``u = p(z)`` fed to the top layer (default: the top layer's size).
    p_hidden : int
        Hidden width of the MLP ``p``.
    motor_hidden : int
        Hidden width of the motor head.
    image_size : (int, int) or None
        ``(H, W)`` of the predicted frames; None: no image head (motor only).
    image_channels : tuple of int
        Channels entering each deconvolution of the image head, widest first; the head
        doubles the resolution ``len(image_channels)`` times and ends in 3 channels.
    n_joints : int
        J, joint values per step (filled in from the data set).
    length : int
        T, steps per sequence (filled in from the data set).
    code_window : int or None
        None: one code per sequence (the paper). W: a sequence of codes ``z_1..z_K``,
        one per window of W steps (``K = ceil(T / W)``), for long demonstrations made of
        several primitives (the paper's *Summary and Discussion*; docs/sequences.md).
    learned_precision : bool
        The decoder holds one learned log-variance per modality
        (:class:`~primspace.model.precision.ModalityPrecision`), the weights of the loss
        ``TrainConfig.loss_reduction="precision"``; a fit sets it from its train config.
        False (default): no such parameters, the state of a run fitted without them.
    keypoints : int
        K > 0: attention in the image path (:mod:`primspace.model.keypoints`). The decoder
        also predicts K keypoints ``(x, y)`` per step, draws its frames through their
        heatmaps, and holds an encoder of real frames to K keypoints, the targets of the
        predicted ones; needs an image head. 0 (default): no keypoints.
    """

    latent_dim: int = 20
    layer_sizes: tuple[int, ...] = (32, 12)
    taus: tuple[float, ...] = (2.0, 8.0)
    top_input_size: int | None = None
    p_hidden: int = 64
    motor_hidden: int = 64
    image_size: tuple[int, int] | None = None
    image_channels: tuple[int, ...] = (64, 32, 16)
    n_joints: int = 0
    length: int = 0
    code_window: int | None = None
    learned_precision: bool = False
    keypoints: int = 0

    def __post_init__(self) -> None:
        self.layer_sizes = tuple(int(s) for s in self.layer_sizes)
        self.taus = tuple(float(t) for t in self.taus)
        self.image_channels = tuple(int(c) for c in self.image_channels)
        if self.image_size is not None:
            self.image_size = tuple(int(s) for s in self.image_size)

    @property
    def has_images(self) -> bool:
        return self.image_size is not None

    @property
    def u_size(self) -> int:
        """Size of ``p(z)``, the top layer's input."""
        return self.top_input_size if self.top_input_size is not None else self.layer_sizes[-1]

    @property
    def n_codes(self) -> int:
        """K, the codes per sequence: ``ceil(T / code_window)``, or 1."""
        return 1 if self.code_window is None else -(-self.length // self.code_window)

    @property
    def code_size(self) -> int:
        """The values of one sample's codes, ``K * q`` (a row of the code table)."""
        return self.n_codes * self.latent_dim

    def validate(self) -> ModelConfig:
        """Check every field; raise :class:`UserError` naming the field."""
        if not isinstance(self.latent_dim, int) or self.latent_dim < 1:
            raise UserError(f"latent size (latent_dim, --latent-dim) must be at least 1, got {self.latent_dim}")
        if len(self.layer_sizes) < 1 or any(s < 1 for s in self.layer_sizes):
            raise UserError(f"layer_sizes must be one or more positive sizes, got {list(self.layer_sizes)}")
        if len(self.taus) != len(self.layer_sizes):
            raise UserError(f"taus has {len(self.taus)} values for {len(self.layer_sizes)} layers")
        if any(not math.isfinite(t) or t < 1.0 for t in self.taus):
            raise UserError(f"every tau must be a finite number >= 1, got {list(self.taus)}")
        for name in ("p_hidden", "motor_hidden"):
            if getattr(self, name) < 1:
                raise UserError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.top_input_size is not None and self.top_input_size < 1:
            raise UserError(f"top_input_size must be at least 1, got {self.top_input_size}")
        if self.n_joints < 1:
            raise UserError(f"n_joints must be at least 1, got {self.n_joints}")
        if self.length < 1:
            raise UserError(f"length (T) must be at least 1, got {self.length}")
        if self.code_window is not None and (not isinstance(self.code_window, int) or self.code_window < 1):
            raise UserError(f"code window (code_window, --code-window) must be at least 1 step, got {self.code_window}")
        if not isinstance(self.learned_precision, bool):
            raise UserError(f"learned_precision must be true or false, got {self.learned_precision!r}")
        if not isinstance(self.keypoints, int) or isinstance(self.keypoints, bool) or self.keypoints < 0:
            raise UserError(f"keypoints (--keypoints) must be a whole number >= 0, got {self.keypoints!r}")
        if self.image_size is not None:
            check_image_size(self.image_size, self.image_channels)
        elif self.keypoints:
            raise UserError(
                "keypoints (--keypoints) are read from frames: the model needs an image head (not --no-images)"
            )
        return self

    # ------------------------------------------------------------------------- json
    def to_dict(self) -> dict:
        out = asdict(self)
        for k, v in out.items():
            if isinstance(v, tuple):
                out[k] = list(v)
        return out

    @classmethod
    def from_dict(cls, d: dict) -> ModelConfig:
        return config_from_dict(cls, d, "model config")

    @classmethod
    def for_dataset(cls, dataset, *, images: bool = True, **overrides) -> ModelConfig:
        """A config sized for ``dataset`` (J, T, and its image size unless ``images=False``)."""
        cfg = cls(**overrides)
        return cfg.fitted_to(dataset, images=images)

    def fitted_to(self, dataset, *, images: bool | None = None) -> ModelConfig:
        """A copy with ``n_joints``, ``length`` (and ``image_size``) taken from ``dataset``.

        ``images=None`` keeps this config's choice (image head or not; keypoints need one); ``True`` / ``False``
        force it. Raises :class:`UserError` if images are asked for and the data has none,
        or if a set ``image_size`` disagrees with the data.
        """
        want_images = (self.image_size is not None or self.keypoints > 0) if images is None else images
        d = self.to_dict()
        d["n_joints"] = int(dataset.n_joints)
        d["length"] = int(dataset.length)
        if want_images:
            if not dataset.has_images:
                raise UserError("the model has an image head but the data set has no images (use --no-images)")
            size = tuple(int(s) for s in dataset.image_size)
            if self.image_size is not None and tuple(self.image_size) != size:
                raise UserError(
                    f"the model predicts {self.image_size[0]}x{self.image_size[1]} images, "
                    f"the data set has {size[0]}x{size[1]}"
                )
            d["image_size"] = list(size)
        else:
            d["image_size"] = None
        return ModelConfig.from_dict(d).validate()


def check_image_size(size, channels) -> None:
    n_up = len(channels)
    factor = 2**n_up
    h, w = size
    if n_up < 1 or any(c < 1 for c in channels):
        raise UserError(f"image_channels must be one or more positive widths, got {list(channels)}")
    if h < factor or w < factor or h % factor or w % factor:
        raise UserError(
            f"image size {h}x{w} cannot be produced by the image head: its {n_up} deconvolutions "
            f"each double the resolution, so height and width must be multiples of {factor}"
        )
