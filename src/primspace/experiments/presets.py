"""Experiment presets: the paper's settings, and a demo that fits a CPU in minutes.

The ``paper`` preset follows *Experimental Results*: 1715 simulated samples (7 primitives
x 7 x 7 block positions x 5 sizes, T = 61, 48 x 64 images), a random 20% of them to fit
θ and Z for 800 epochs, the other 80% to infer Z with θ frozen for 600 epochs; zero,
random and projection initialisations (plus PCA, our data-dependent baseline); latent
clustering at q = 40 with τ chosen for R² = 0.9999; inter-primitive folds at q = 20 with
10% replay. Where the paper is silent (τ of the layers, learning rates, batch size, the
epochs of the inter-primitive phases, the latent sizes other than 20 and 40) the values
below are ours; docs/reproduce.md lists them beside the paper's.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

from primspace.errors import UserError, config_from_dict

__all__ = ["ExperimentPreset", "PRESETS", "resolve_preset"]


@dataclass(frozen=True)
class ExperimentPreset:
    """Everything an experiment needs besides its data.

    Parameters
    ----------
    name : str
    data_preset : str
        The simulator preset generated when no ``--data`` is given.
    train_fraction : float
        Share of samples that fit θ and Z (the paper: 20%), drawn per primitive.
    inits : tuple of str
        Latent initialisations compared in the intra-primitive experiment.
    latent_dims : tuple of int
        Latent sizes q compared.
    seeds : tuple of int
        Repetitions (each seed: its own split, weights, projection).
    fit_epochs, infer_epochs : int
        Epochs of the two phases (the paper: 800, 600).
    batch_size : int
        Samples per step while fitting θ and Z.
    infer_batch_size : int
        Samples per step while inferring Z with θ frozen. Every code takes one Adam step
        per epoch on the gradient of its own sample's loss, whatever the batch (the
        table undoes the batch mean's 1/B), so with θ frozen a large batch computes the
        same updates (to float rounding), only faster.
    lr, latent_lr : float
        Adam learning rates of θ and of the codes.
    final_lr_fraction : float
        Both rates decay along a cosine to this fraction by the last epoch (ours; the
        paper does not say).
    images : bool
        Train with the vision loss (when the data has images).
    vision_weight : float
    layer_sizes, taus : tuple
        The MTRNN layers (fast first) and their time constants.
    cluster_latent_dim : int
        q of the latents that are clustered (the paper: 40).
    cluster_r2 : float
        R² target that picks τ for latent clustering (the paper: 0.9999).
    trajectory_r2 : float
        R² target for clustering raw trajectories (the paper: 0.85–0.95 on motion capture).
    lasa_length : int
        Steps LASA demonstrations are resampled to for trajectory clustering.
    inter_latent_dim : int
        q of the inter-primitive experiment (the paper: 20).
    inter_inits : tuple of str
        Inits compared there (the paper: zero and projection).
    inter_epochs : (int, int)
        Epochs of phase 1 (six primitives) and phase 2 (the seventh + replay).
    inter_replay : float
        Share of phase-1 samples replayed in phase 2 (the paper: 10%).
    """

    name: str
    data_preset: str
    train_fraction: float = 0.2
    inits: tuple[str, ...] = ("zero", "random", "projection", "pca")
    latent_dims: tuple[int, ...] = (10, 20, 40)
    seeds: tuple[int, ...] = (0,)
    fit_epochs: int = 800
    infer_epochs: int = 600
    batch_size: int = 32
    infer_batch_size: int = 256
    lr: float = 1e-3
    latent_lr: float = 1e-2
    final_lr_fraction: float = 0.1
    images: bool = True
    vision_weight: float = 1.0
    layer_sizes: tuple[int, ...] = (32, 12)
    taus: tuple[float, ...] = (2.0, 8.0)
    cluster_latent_dim: int = 40
    cluster_r2: float = 0.9999
    trajectory_r2: float = 0.9
    lasa_length: int = 100
    inter_latent_dim: int = 20
    inter_inits: tuple[str, ...] = ("zero", "projection")
    inter_epochs: tuple[int, int] = (400, 400)
    inter_replay: float = 0.1
    extra: dict = field(default_factory=dict, compare=False)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ExperimentPreset":
        tuples = {"inits", "latent_dims", "seeds", "layer_sizes", "taus", "inter_inits", "inter_epochs"}
        return config_from_dict(cls, {k: tuple(v) if k in tuples else v for k, v in d.items()}, "experiment preset")

    def with_overrides(self, **changes) -> "ExperimentPreset":
        """A copy with some fields changed (``None`` values are ignored), checked.

        Raises
        ------
        UserError
            An unknown initialisation, a latent size < 1, negative epochs, no seeds.
        """
        from primspace.latent import INIT_METHODS

        changes = {k: v for k, v in changes.items() if v is not None}
        unknown = [i for i in changes.get("inits", ()) if i not in INIT_METHODS]
        if unknown:
            raise UserError(f"unknown initialisation(s) {', '.join(unknown)}; choose from {', '.join(INIT_METHODS)}")
        if any(q < 1 for q in changes.get("latent_dims", ())):
            raise UserError("latent sizes must be at least 1")
        if any(changes.get(k, 1) < 1 for k in ("fit_epochs", "infer_epochs")):
            raise UserError("--epochs: an experiment needs at least 1 fit and 1 infer epoch")
        for key in ("inits", "latent_dims", "seeds"):
            if key in changes and not changes[key]:
                raise UserError(f"--{key.replace('_', '-')} is empty")
        return replace(self, **changes)


PRESETS: dict[str, ExperimentPreset] = {
    "paper": ExperimentPreset(name="paper", data_preset="paper"),
    # Sized by measurement to fit `make demo` in 5 minutes on 2 cores (README, Performance).
    "demo": ExperimentPreset(
        name="demo",
        data_preset="demo",
        latent_dims=(8, 40),
        images=False,
        fit_epochs=400,
        infer_epochs=250,
        batch_size=16,
        lr=3e-3,
        latent_lr=3e-2,
        inter_epochs=(100, 100),
    ),
}


def resolve_preset(name: str) -> ExperimentPreset:
    try:
        return PRESETS[name]
    except KeyError:
        raise UserError(f"unknown experiment preset {name!r}; choose from {', '.join(PRESETS)}") from None
