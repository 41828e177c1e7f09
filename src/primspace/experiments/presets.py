"""Experiment presets: the paper's settings, and a demo that fits a CPU in minutes.

The ``paper`` preset follows *Experimental Results*: 1715 simulated samples (7 primitives
x 7 x 7 block positions x 5 sizes, T = 61, 48 x 64 images), a random 20% of them to fit
θ and Z for 800 epochs, the other 80% to infer Z with θ frozen for 600 epochs; zero,
random and projection initialisations (plus PCA, our data-dependent baseline); latent
clustering at q = 40 with τ chosen for R² = 0.9999; inter-primitive folds at q = 20 with
10% replay. Where the paper is silent (τ of the layers, learning rates, batch size, the
epochs of the inter-primitive phases, the latent sizes other than 20 and 40) the values
below are ours; docs/reproduce.md lists them beside the paper's.

A preset holds the decoder's :class:`~primspace.model.config.ModelConfig` and the optimiser's
:class:`~primspace.train.TrainConfig` as they are; each run derives its own from them
(:func:`primspace.experiments.runs.train_configs`: the run's q, seed and epochs).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

from primspace.model.config import ModelConfig
from primspace.train import TrainConfig
from primspace.utils.errors import UserError, config_from_dict

__all__ = [
    "ExperimentPreset",
    "PRESETS",
    "DEFAULT_PRESET",
    "LASA_DATA",
    "LASA_CHAINS",
    "REAL_PRESET",
    "COMPOSITE_PRESET_OF",
    "default_model",
    "default_train",
    "resolve_preset",
]

#: The preset ``primspace experiment`` runs without ``--preset``.
DEFAULT_PRESET = "demo"

#: The ``data_preset`` that imports the LASA handwriting set instead of simulating.
LASA_DATA = "lasa"
#: The ``data_preset`` of long demonstrations chained from LASA's real ones
#: (:func:`primspace.data.importers.chain_lasa`, this many sequences, seeded by ``--seed``).
LASA_CHAINS = "lasa-chains"
LASA_CHAIN_SEQUENCES = 120

# Fields of the presets written before they held a ModelConfig and a TrainConfig
# (experiment.json of older experiment directories): where each one lives now.
_FLAT_MODEL_FIELDS = ("layer_sizes", "taus")
_FLAT_TRAIN_FIELDS = ("batch_size", "lr", "latent_lr", "final_lr_fraction", "vision_weight")
_TUPLE_FIELDS = ("inits", "latent_dims", "seeds", "inter_inits", "inter_epochs")


def default_model() -> ModelConfig:
    """The decoder of every preset: the paper's two MTRNN layers, 32 fast and 12 slow units.

    ``latent_dim`` is set per run (the preset's ``latent_dims``); ``n_joints``,
    ``length`` and ``image_size`` come from the data.
    """
    return ModelConfig(layer_sizes=(32, 12), taus=(2.0, 8.0))


def default_train() -> TrainConfig:
    """The optimiser of every preset (``epochs`` and ``seed`` are set per run).

    Both learning rates decay along a cosine to 10% by the last epoch (ours; the paper
    does not say). ``threads=1``: the runs of a grid go in parallel across processes,
    and one thread each keeps every backend bit-identical.
    """
    return TrainConfig(final_lr_fraction=0.1, threads=1)


@dataclass(frozen=True)
class ExperimentPreset:
    """Everything an experiment needs besides its data.

    Parameters
    ----------
    name : str
    data_preset : str
        The simulator preset generated when no ``--data`` is given, or ``"lasa"``
        (:data:`LASA_DATA`): the LASA handwriting demonstrations imported (offline,
        resampled to ``lasa_length``).
    train_fraction : float
        Share of samples that fit θ and Z (the paper: 20%), drawn per primitive.
    inits : tuple of str
        Latent initialisations compared in the intra-primitive experiment; ``calibrated``
        infers with projection's fit (beyond the paper, :mod:`primspace.model.calibration`).
    latent_dims : tuple of int
        Latent sizes q compared.
    seeds : tuple of int
        Repetitions (each seed: its own split, weights, projection).
    fit_epochs, infer_epochs : int
        Epochs of the two phases (the paper: 800, 600).
    infer_batch_size : int
        Samples per step while inferring Z with θ frozen. Every code takes one Adam step
        per epoch on the gradient of its own sample's loss, whatever the batch (the
        table undoes the batch mean's 1/B), so with θ frozen a large batch computes the
        same updates (to float rounding), only faster.
    images : bool
        Train with the vision loss (when the data has images).
    model : ModelConfig
        The MTRNN decoder (layers fast first, their time constants); each run sets its
        ``latent_dim``.
    train : TrainConfig
        The optimiser while fitting θ and Z: batch size, Adam learning rates of θ and of
        the codes, their cosine decay, loss weights, threads; each run sets its
        ``epochs``, ``seed`` and ``checkpoint_every``.
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
    primitives : str or None
        Composite presets: the experiment preset whose single primitives (its data, its
        optimiser, q = its ``cluster_latent_dim``) make the model that segments the long
        demonstrations by synthesis and by surprise
        (:mod:`primspace.experiments.composite.primitives`); None: those methods do not run.
    segment_steps : (int, int) or None
        Their duration prior: the fewest and most steps of one primitive in the long
        demonstrations; None: 0.4 to 0.85 of the primitives' T.

    Notes
    -----
    ``model`` and ``train`` may also be given as dicts (as :meth:`to_dict` writes them).
    """

    name: str
    data_preset: str
    train_fraction: float = 0.2
    inits: tuple[str, ...] = ("zero", "random", "projection", "pca", "calibrated")
    latent_dims: tuple[int, ...] = (10, 20, 40)
    seeds: tuple[int, ...] = (0,)
    fit_epochs: int = 800
    infer_epochs: int = 600
    infer_batch_size: int = 256
    images: bool = True
    model: ModelConfig = field(default_factory=default_model)
    train: TrainConfig = field(default_factory=default_train)
    cluster_latent_dim: int = 40
    cluster_r2: float = 0.9999
    trajectory_r2: float = 0.9
    lasa_length: int = 100
    inter_latent_dim: int = 20
    inter_inits: tuple[str, ...] = ("zero", "projection", "calibrated")
    inter_epochs: tuple[int, int] = (400, 400)
    inter_replay: float = 0.1
    primitives: str | None = None
    segment_steps: tuple[int, int] | None = None
    extra: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.model, dict):
            object.__setattr__(self, "model", ModelConfig.from_dict(self.model))
        if isinstance(self.train, dict):
            object.__setattr__(self, "train", TrainConfig.from_dict(self.train))
        for key in _TUPLE_FIELDS:
            object.__setattr__(self, key, tuple(getattr(self, key)))
        if self.segment_steps is not None:
            object.__setattr__(self, "segment_steps", tuple(int(v) for v in self.segment_steps))

    def to_dict(self) -> dict:
        """JSON-ready: ``model`` and ``train`` nested as their own ``to_dict``."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["model"], out["train"] = self.model.to_dict(), self.train.to_dict()
        return {k: list(v) if isinstance(v, tuple) else v for k, v in out.items()} | {"extra": dict(self.extra)}

    @classmethod
    def from_dict(cls, d: dict) -> ExperimentPreset:
        """Read :meth:`to_dict`'s form, or the flat form of older experiment directories.

        The old form repeated the decoder's and the optimiser's fields at the top
        (``layer_sizes``, ``taus``; ``batch_size``, ``lr``, ``latent_lr``,
        ``final_lr_fraction``, ``vision_weight``); they are moved into ``model`` and
        ``train`` over the defaults (:func:`default_model`, :func:`default_train`),
        which give the very configurations the old version built from them.
        """
        d = dict(d)
        model = d.pop("model", None)
        train = d.pop("train", None)
        flat_model = {k: d.pop(k) for k in _FLAT_MODEL_FIELDS if k in d}
        flat_train = {k: d.pop(k) for k in _FLAT_TRAIN_FIELDS if k in d}
        if (flat_model and model is not None) or (flat_train and train is not None):
            both = sorted(flat_model if model is not None else flat_train)
            raise UserError(f"experiment preset: {', '.join(both)} given both flat and inside model/train")
        if model is None:
            model = default_model().to_dict() | flat_model
        if train is None:
            train = default_train().to_dict() | flat_train
        return config_from_dict(
            cls, d | {"model": ModelConfig.from_dict(model), "train": TrainConfig.from_dict(train)}, "experiment preset"
        )

    def with_overrides(self, **changes) -> ExperimentPreset:
        """A copy with some fields changed (``None`` values are ignored), checked.

        ``vision_frames``, ``loss_reduction``, ``device``, ``threads``, ``optimizer``, ``lr``,
        ``latent_lr`` and ``step`` are :class:`~primspace.train.TrainConfig` fields: they replace those of the
        preset's ``train``.

        Raises
        ------
        UserError
            An unknown initialisation, a latent size < 1, negative epochs, no seeds.
        """
        from primspace.model.latent import START_METHODS

        changes = {k: v for k, v in changes.items() if v is not None}
        for key in (
            "vision_frames",
            "loss_reduction",
            "device",
            "threads",
            "optimizer",
            "lr",
            "latent_lr",
            "step",
        ):  # training settings: they go into the preset's TrainConfig
            if key in changes:
                changes["train"] = replace(changes.get("train", self.train), **{key: changes.pop(key)})
                changes["train"].validate()
        unknown = list(
            dict.fromkeys(i for key in ("inits", "inter_inits") for i in changes.get(key, ()) if i not in START_METHODS)
        )
        if unknown:
            raise UserError(f"unknown initialisation(s) {', '.join(unknown)}; choose from {', '.join(START_METHODS)}")
        if any(q < 1 for q in changes.get("latent_dims", ())):
            raise UserError("latent sizes must be at least 1")
        if any(changes.get(k, 1) < 1 for k in ("fit_epochs", "infer_epochs")):
            raise UserError("--epochs: an experiment needs at least 1 fit and 1 infer epoch")
        for key in ("inits", "latent_dims", "seeds"):
            if key in changes and not changes[key]:
                raise UserError(f"--{key.replace('_', '-')} is empty")
        return replace(self, **changes)

    def settings(self) -> dict:
        """Every setting as one flat dict, nested ones dotted (``train.lr``): for comparing presets."""
        flat = {}
        for key, value in self.to_dict().items():
            if isinstance(value, dict) and key in ("model", "train"):
                flat |= {f"{key}.{k}": v for k, v in value.items()}
            else:
                flat[key] = value
        return flat


PRESETS: dict[str, ExperimentPreset] = {
    "paper": ExperimentPreset(name="paper", data_preset="paper"),
    # The paper's settings on its layout in scenes that vary (issue 52; docs/data.md, "Scenes that vary").
    "paper-varied": ExperimentPreset(name="paper-varied", data_preset="paper-varied"),
    # Sized by measurement to fit `make demo` in 5 minutes on 2 cores (docs/performance.md).
    "demo": ExperimentPreset(
        name="demo",
        data_preset="demo",
        latent_dims=(8, 40),
        images=False,
        fit_epochs=400,
        infer_epochs=250,
        train=replace(default_train(), batch_size=16, lr=3e-3, latent_lr=3e-2),
        inter_epochs=(100, 100),
    ),
    # The intra-primitive protocol on real demonstrations (issue 14): LASA's 26 shapes x 7
    # human demonstrations; 2 per shape fit θ and Z, the other 5 are inferred with θ frozen.
    # Motor only (LASA has no camera); the demo's optimiser (a small data set, like the demo's).
    "lasa": ExperimentPreset(
        name="lasa",
        data_preset=LASA_DATA,
        train_fraction=0.3,
        latent_dims=(8, 16),
        seeds=(0, 1, 2),
        images=False,
        fit_epochs=800,
        infer_epochs=600,
        train=replace(default_train(), batch_size=16, lr=3e-3, latent_lr=3e-2),
        cluster_latent_dim=16,
        lasa_length=61,
        inter_latent_dim=8,
        inter_epochs=(200, 200),
    ),
}

#: The preset of the intra protocol on real recordings (docs/real.md).
REAL_PRESET = "real"
# The intra-primitive protocol on real recordings (issue 50): any labelled data file from
# `primspace import` (--data; without it, LASA at 61 steps), 20 % of each class fitting θ
# and Z, the other 80 % inferred with θ frozen, q = 8, the demo's schedule and optimiser.
PRESETS[REAL_PRESET] = ExperimentPreset(
    name=REAL_PRESET,
    data_preset=LASA_DATA,
    train_fraction=0.2,
    inits=("zero", "random", "projection", "pca", "calibrated"),
    latent_dims=(8,),
    seeds=(0, 1, 2),
    images=False,
    fit_epochs=400,
    infer_epochs=250,
    train=replace(default_train(), batch_size=16, lr=3e-3, latent_lr=3e-2),
    cluster_latent_dim=8,
    lasa_length=61,
    inter_latent_dim=8,
    inter_epochs=(200, 200),
)

_DEMO_TRAIN = dict(batch_size=16, lr=3e-3, latent_lr=3e-2)
# Long demonstrations made of several primitives (issue 15; docs/sequences.md): one code of
# q per window of W steps, the simulator's composite presets (joints only), held-out
# demonstrations inferred with θ frozen and segmented. `experiment composite --preset demo`
# runs "composite-demo", `--preset paper` runs "composite" (COMPOSITE_PRESET_OF).
PRESETS["composite-demo"] = ExperimentPreset(
    name="composite-demo",
    data_preset="composite-demo",
    train_fraction=0.3,
    latent_dims=(8,),
    images=False,
    primitives="demo",
    fit_epochs=400,
    infer_epochs=250,
    model=replace(default_model(), code_window=8),
    train=replace(default_train(), **_DEMO_TRAIN),
)
PRESETS["composite"] = ExperimentPreset(
    name="composite",
    data_preset="composite",
    train_fraction=0.2,
    inits=("zero", "random", "projection"),
    primitives="paper",
    latent_dims=(8,),
    images=False,
    model=replace(default_model(), code_window=10),
    train=replace(default_train(), **_DEMO_TRAIN),
)

PRESETS["composite-lasa"] = ExperimentPreset(
    name="composite-lasa",
    data_preset=LASA_CHAINS,
    train_fraction=0.3,
    latent_dims=(8,),
    images=False,
    primitives="lasa",
    segment_steps=(30, 66),
    fit_epochs=400,
    infer_epochs=250,
    model=replace(default_model(), code_window=8),
    train=replace(default_train(), **_DEMO_TRAIN),
)

#: The experiment preset ``primspace experiment composite --preset NAME`` runs.
COMPOSITE_PRESET_OF = {"demo": "composite-demo", "paper": "composite", "lasa": "composite-lasa"}


def resolve_preset(name: str) -> ExperimentPreset:
    try:
        return PRESETS[name]
    except KeyError:
        raise UserError(f"unknown experiment preset {name!r}; choose from {', '.join(PRESETS)}") from None
