"""What to generate: :class:`GenerationConfig`, the presets, and each sample's parameters.

The paper (section "Artificial Data") records 7 primitives x 245 block placements, 61
steps and 48 x 64 frames each; the ``paper`` preset makes the 245 as a 7 x 7 grid of
positions x 5 block sizes. Samples are ordered primitive-major: index ``((p * n_x + i_x) * n_y + i_y) * n_sizes +
i_size``. The seed only moves each block within its grid cell (uniform jitter of
``jitter`` times the grid spacing each way, per axis); sizes are exact.

``block_jitter`` says which samples share a jitter draw (:func:`sample_params`):

- ``"each"`` (every preset's default): sample ``i`` draws its own jitter from
  ``np.random.SeedSequence([seed, i])``, so the sizes of a grid cell sit at different
  positions.
- ``"shared"`` (the paper's layout: "each position corresponds to five samples differing
  in block size"): one draw per (primitive, grid cell), from
  ``np.random.SeedSequence([seed, SHARED_JITTER_KEY, label, i_x, i_y])`` with ``label``
  the primitive's registry index (:data:`~primspace.sim.primitives.PRIMITIVES`, so a
  subset of primitives keeps its positions) and ``SHARED_JITTER_KEY`` a constant that
  keeps these streams apart from the per-sample ones; every size of the cell uses it.

Either way a sample's parameters depend on the seed and its index alone, never on how
the samples are split into shards or on the number of workers.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from primspace.sim.primitives import PRIMITIVES, primitive_index
from primspace.utils.errors import UserError

__all__ = [
    "GenerationConfig",
    "PRESETS",
    "PARAM_NAMES",
    "MIN_LENGTH",
    "BLOCK_JITTERS",
    "SHARED_JITTER_KEY",
    "resolve_config",
    "sample_params",
]

#: Names of the generative factors stored in ``params``.
PARAM_NAMES = ("block_x", "block_y", "block_size")

#: The shortest motion whose phases (three side touches) every step rate resolves.
MIN_LENGTH = 31

#: The values of ``GenerationConfig.block_jitter``: one draw per sample, or per (primitive, grid cell).
BLOCK_JITTERS = ("each", "shared")

#: The second entry of a shared draw's seed (:func:`sample_params`), "SHAR" in ASCII. A
#: per-sample seed ``[seed, i]`` is two or three 32-bit words, a shared one five or six,
#: so no shared seed equals a per-sample one; the constant names the stream.
SHARED_JITTER_KEY = 0x53484152


def _grid(lo: float, hi: float, n: int) -> tuple[float, ...]:
    return tuple(round(float(v), 6) for v in np.linspace(lo, hi, n))


@dataclass(frozen=True)
class GenerationConfig:
    """What to generate: block grid, sizes, primitives, length, images.

    Parameters
    ----------
    block_x, block_y : tuple of float
        Grid of block centres on the table (m); every (x, y) pair is used.
    block_size : tuple of float
        Cube edges (m).
    primitives : tuple of str
        Which primitives (labels stay their index in :data:`PRIMITIVES`).
    length : int
        T, time steps per motion (the paper: 61, one per second of a one-minute motion).
    height, width : int
        Frame size (the paper: 48 x 64).
    images : bool
        Render camera frames (False: joints only, much faster).
    jitter : float
        Block positions move uniformly within +- ``jitter`` x grid spacing (per axis),
        drawn from the seed; 0 keeps the exact grid.
    block_jitter : {"each", "shared"}
        ``"each"`` (default): every sample draws its own jitter. ``"shared"``: one draw
        per (primitive, grid cell), shared by the cell's block sizes (the paper's layout);
        see the module docstring for the seeds.
    dt : float
        Seconds per step (the paper: a 61-step minute, dt = 1 s).
    ik_tolerance : float
        Largest allowed distance between the TCP and its scripted path (m).
    verify : bool
        Replay every generated motion through the success judge and refuse one that
        fails (a guard against silently writing a bad sample; costs ~6 ms a sample).
    scene_variation : str
        A level of :data:`primspace.sim.variation.VARIATIONS`: ``"none"`` (default) the
        standard scene; ``"varied"`` draws each sample's block and table colours, light,
        camera pose and a distractor from its own seed stream and records them in the
        file's ``scene`` array (the blocks and motions stay the same).
    """

    block_x: tuple[float, ...] = _grid(0.42, 0.60, 7)
    block_y: tuple[float, ...] = _grid(-0.15, 0.15, 7)
    block_size: tuple[float, ...] = _grid(0.035, 0.065, 5)
    primitives: tuple[str, ...] = PRIMITIVES
    length: int = 61
    height: int = 48
    width: int = 64
    images: bool = True
    jitter: float = 0.25
    dt: float = 1.0
    ik_tolerance: float = 0.002
    verify: bool = True
    block_jitter: str = "each"
    scene_variation: str = "none"

    def __post_init__(self) -> None:
        for name in ("block_x", "block_y", "block_size", "primitives"):
            object.__setattr__(self, name, tuple(getattr(self, name)))

    # --------------------------------------------------------------------- sizes
    @property
    def n_positions(self) -> int:
        return len(self.block_x) * len(self.block_y)

    @property
    def n_per_primitive(self) -> int:
        return self.n_positions * len(self.block_size)

    @property
    def n_samples(self) -> int:
        return len(self.primitives) * self.n_per_primitive

    @property
    def image_size(self) -> tuple[int, int] | None:
        return (self.height, self.width) if self.images else None

    def spacing(self, axis: str) -> float:
        """Grid spacing along ``block_x`` or ``block_y`` (0 for a single value)."""
        values = np.sort(np.asarray(getattr(self, axis), dtype=float))
        return float(np.min(np.diff(values))) if len(values) > 1 else 0.0

    # ---------------------------------------------------------------- validation
    def validate(self) -> GenerationConfig:
        """Check every field; raise :class:`UserError` naming the field. Returns self."""
        from primspace.sim.render import MAX_IMAGE_SIZE
        from primspace.sim.scene import TABLE

        for name in self.primitives:
            primitive_index(name)
        if not self.primitives:
            raise UserError("primitives: at least one primitive is needed")
        if len(set(self.primitives)) != len(self.primitives):
            raise UserError(f"primitives: repeated names in {list(self.primitives)}")
        for name, (lo, hi) in (
            ("block_x", TABLE.block_x),
            ("block_y", TABLE.block_y),
            ("block_size", TABLE.block_size),
        ):
            values = np.asarray(getattr(self, name), dtype=float)
            if values.size == 0:
                raise UserError(f"{name}: at least one value is needed")
            if not np.isfinite(values).all():
                raise UserError(f"{name}: values must be finite numbers")
            if len(np.unique(values)) != len(values):
                raise UserError(f"{name}: repeated values in {values.tolist()}")
            reach = self.jitter * self.spacing(name) if name != "block_size" else 0.0
            bad = values[(values - reach < lo - 1e-9) | (values + reach > hi + 1e-9)]
            if bad.size:
                what = "block size" if name == "block_size" else "block position"
                extra = f" (with jitter +-{reach:.4g})" if reach else ""
                raise UserError(f"{name} = {bad[0]:.4g} m{extra} is outside the table's {what} range [{lo}, {hi}] m")
        if not (0.0 <= self.jitter <= 0.5):
            raise UserError(f"jitter = {self.jitter}: must be in [0, 0.5] (a fraction of the grid spacing)")
        from primspace.sim.variation import resolve_variation

        resolve_variation(self.scene_variation)
        if self.block_jitter not in BLOCK_JITTERS:
            raise UserError(f"block_jitter = {self.block_jitter!r}: must be one of {', '.join(BLOCK_JITTERS)}")
        if not (MIN_LENGTH <= self.length <= 100_000):
            raise UserError(f"length (T) = {self.length}: must be at least {MIN_LENGTH} (the phases need it)")
        if not (1 <= self.height <= MAX_IMAGE_SIZE[0] and 1 <= self.width <= MAX_IMAGE_SIZE[1]):
            raise UserError(
                f"image size {self.height}x{self.width}: height must be 1..{MAX_IMAGE_SIZE[0]}, width 1..{MAX_IMAGE_SIZE[1]}"
            )
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise UserError(f"dt = {self.dt}: must be a positive number of seconds")
        if not (self.ik_tolerance > 0):
            raise UserError(f"ik_tolerance = {self.ik_tolerance}: must be positive")
        return self

    # ---------------------------------------------------------------------- json
    def to_dict(self) -> dict[str, Any]:
        """The settings as JSON values (``scene_variation`` only when it is not ``"none"``, so
        the standard scene's settings, manifests and files are those of earlier versions)."""
        d = asdict(self)
        if d["scene_variation"] == "none":
            del d["scene_variation"]
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any], base: GenerationConfig | None = None) -> GenerationConfig:
        """A configuration from JSON-like values (over ``base``'s, default: the defaults).

        Raises
        ------
        UserError
            For an unknown setting or a value of the wrong kind, naming the setting.
        """
        if not isinstance(d, dict):
            raise UserError(f"generation settings must be a JSON object, got {type(d).__name__}")
        kinds = {f.name: f.type for f in fields(cls)}
        unknown = sorted(set(d) - set(kinds))
        if unknown:
            raise UserError(f"unknown generation setting(s): {', '.join(unknown)}; known: {', '.join(kinds)}")
        values = {}
        for name, value in d.items():
            kind = kinds[name]
            try:
                if name == "primitives":
                    ok = isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)
                    values[name] = tuple(value) if ok else _bad()
                elif kind.startswith("tuple"):
                    ok = isinstance(value, (list, tuple)) and all(_is_number(v) for v in value)
                    values[name] = tuple(float(v) for v in value) if ok else _bad()
                elif kind == "bool":
                    values[name] = value if isinstance(value, bool) else _bad()
                elif kind == "str":
                    values[name] = value if isinstance(value, str) else _bad()
                elif kind == "int":
                    values[name] = int(value) if _is_number(value) and float(value).is_integer() else _bad()
                else:
                    values[name] = float(value) if _is_number(value) else _bad()
            except ValueError:
                raise UserError(f"generation setting {name}: {value!r} is not {_KIND_WORDS[kind]}") from None
        return replace(base if base is not None else cls(), **values)


_KIND_WORDS = {
    "tuple[float, ...]": "a list of numbers",
    "tuple[str, ...]": "a list of primitive names",
    "int": "an integer",
    "float": "a number",
    "bool": "true or false",
    "str": "a string",
}


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _bad():
    raise ValueError


#: Named configurations. ``paper``: 7 x 7 positions x 5 sizes x 7 primitives = 1715
#: motions of T = 61 steps with 48 x 64 frames, as in the paper. ``demo``: 3 x 3
#: positions x 2 sizes x 7 primitives = 126 motions, the same T and frames, for the CPU demo.
#: ``paper-varied``: the paper's layout in scenes that vary (:mod:`primspace.sim.variation`).
PRESETS: dict[str, GenerationConfig] = {
    "paper": GenerationConfig(),
    "demo": GenerationConfig(block_x=_grid(0.44, 0.58, 3), block_y=_grid(-0.12, 0.12, 3), block_size=(0.04, 0.06)),
    "paper-varied": GenerationConfig(scene_variation="varied"),
}


def resolve_config(config_or_preset) -> GenerationConfig:
    """A validated :class:`GenerationConfig` from a config, a preset name or a dict."""
    if isinstance(config_or_preset, GenerationConfig):
        config = config_or_preset
    elif isinstance(config_or_preset, str):
        if config_or_preset not in PRESETS:
            raise UserError(f"unknown preset {config_or_preset!r}; choose from {', '.join(PRESETS)}")
        config = PRESETS[config_or_preset]
    elif isinstance(config_or_preset, dict):
        config = GenerationConfig.from_dict(config_or_preset)
    else:
        raise UserError(f"expected a preset name or a GenerationConfig, got {type(config_or_preset).__name__}")
    return config.validate()


def sample_params(config: GenerationConfig, seed: int, index: int) -> tuple[int, float, float, float]:
    """``(label, block_x, block_y, block_size)`` of sample ``index`` (depends on seed and index only).

    The jitter's seed (see the module docstring): ``[seed, index]`` with ``block_jitter =
    "each"``; ``[seed, SHARED_JITTER_KEY, label, i_x, i_y]`` with ``"shared"``, the same
    for every size of the primitive's grid cell.
    """
    n_y, n_s = len(config.block_y), len(config.block_size)
    per = config.n_per_primitive
    p, rest = divmod(int(index), per)
    ix, rest = divmod(rest, n_y * n_s)
    iy, isz = divmod(rest, n_s)
    label = primitive_index(config.primitives[p])
    if config.block_jitter == "shared":
        key = [int(seed), SHARED_JITTER_KEY, label, ix, iy]
    else:
        key = [int(seed), int(index)]
    rng = np.random.default_rng(np.random.SeedSequence(key))
    jx, jy = rng.uniform(-1.0, 1.0, size=2) * config.jitter
    x = config.block_x[ix] + jx * config.spacing("block_x")
    y = config.block_y[iy] + jy * config.spacing("block_y")
    return label, float(x), float(y), float(config.block_size[isz])
