"""What long demonstrations to generate: the settings, their presets and the chains allowed.

:class:`CompositeConfig` holds the settings of :mod:`primspace.sim.composite`'s generator,
:data:`COMPOSITE_PRESETS` names two of them and :func:`resolve_composite` validates one; a
chain of primitives is allowed where :data:`ALLOWED` says each may act on the block, which
push and pull move (:data:`MOVES_TO`; :func:`valid_chains`). The rules and presets:
docs/simulator.md, section "Long demonstrations (composite)".
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, fields
from functools import cache

from primspace.sim.config import MIN_LENGTH
from primspace.sim.primitives import PRIMITIVES, primitive_index
from primspace.sim.scene import TABLE
from primspace.utils.errors import UserError

__all__ = ["CompositeConfig", "COMPOSITE_PRESETS", "ALLOWED", "MOVES_TO", "resolve_composite", "valid_chains"]

#: Where push and pull leave the block: the zone it is in afterwards (others leave it in place).
MOVES_TO = {"push": "far", "pull": "near"}

#: The primitives that may act on the block in each zone. ``start``: where it started (every
#: primitive works on the whole start area); ``far``: pushed to x = 0.70 m (circles there pass
#: beyond the arm's reach for large blocks off the centre line; push has nothing to do);
#: ``near``: pulled to x = 0.32 m (push and circles would need the hand behind or around the
#: block within 25 cm of the robot's base: the IK misses by 1-13 cm; pull has nothing to do).
ALLOWED = {
    "start": PRIMITIVES,
    "far": ("touch", "grasp", "pull", "touch_right"),
    "near": ("touch", "grasp", "touch_right"),
}


@dataclass(frozen=True)
class CompositeConfig:
    """What long demonstrations to generate.

    Parameters
    ----------
    n_sequences : int
        N, the number of sequences.
    min_primitives, max_primitives : int
        Primitives per sequence, uniform in [min, max] (2..4).
    duration : (int, int)
        Steps of each primitive's script, uniform in [lo, hi] (lo >= ``MIN_LENGTH`` = 31).
    transition_steps : int
        Steps of the transition before each primitive after the first.
    primitives : tuple of str
        What chains are made of (labels stay their index in ``PRIMITIVES``).
    block_x, block_y, block_size : (float, float)
        Uniform ranges of the block's start (m); default: the ``paper`` grid's span.
    image_size : (int, int) or None
        Frame size (H, W); None: joints only.
    dt, ik_tolerance : float
        Seconds per step; the largest allowed TCP miss of the scripted path (m).
    verify : bool
        Judge each primitive's steps by its success criteria and each transition for
        entering the block; refuse a sequence that fails.
    """

    n_sequences: int = 600
    min_primitives: int = 2
    max_primitives: int = 4
    duration: tuple[int, int] = (40, 70)
    transition_steps: int = 12
    primitives: tuple[str, ...] = PRIMITIVES
    block_x: tuple[float, float] = (0.42, 0.60)
    block_y: tuple[float, float] = (-0.15, 0.15)
    block_size: tuple[float, float] = (0.035, 0.065)
    image_size: tuple[int, int] | None = None
    dt: float = 1.0
    ik_tolerance: float = 0.002
    verify: bool = True

    def __post_init__(self) -> None:
        for name in ("duration", "primitives", "block_x", "block_y", "block_size", "image_size"):
            value = getattr(self, name)
            object.__setattr__(self, name, None if value is None else tuple(value))

    @property
    def length(self) -> int:
        """T: the longest possible sequence (max primitives of the longest duration)."""
        return self.max_primitives * self.duration[1] + (self.max_primitives - 1) * self.transition_steps

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def validate(self) -> CompositeConfig:
        """Check every field; raise :class:`UserError` naming the field. Returns self."""
        from primspace.sim.render import MAX_IMAGE_SIZE

        for name in self.primitives:
            primitive_index(name)
        checks = [
            ("n_sequences", self.n_sequences >= 1, "at least 1"),
            ("min_primitives", 2 <= self.min_primitives <= self.max_primitives <= 4, "2 <= min <= max <= 4"),
            (
                "duration",
                len(self.duration) == 2 and MIN_LENGTH <= self.duration[0] <= self.duration[1],
                f"(lo, hi) with {MIN_LENGTH} <= lo <= hi",
            ),
            ("transition_steps", self.transition_steps >= 2, "at least 2"),
            ("primitives", len(set(self.primitives)) == len(self.primitives) >= 2, "at least 2 distinct names"),
            (
                "image_size",
                self.image_size is None
                or (
                    len(self.image_size) == 2
                    and 1 <= self.image_size[0] <= MAX_IMAGE_SIZE[0]
                    and 1 <= self.image_size[1] <= MAX_IMAGE_SIZE[1]
                ),
                "None or (H, W)",
            ),
            ("dt", math.isfinite(self.dt) and self.dt > 0, "positive"),
            ("ik_tolerance", self.ik_tolerance > 0, "positive"),
        ]
        for name, (lo, hi) in (
            ("block_x", TABLE.block_x),
            ("block_y", TABLE.block_y),
            ("block_size", TABLE.block_size),
        ):
            v = getattr(self, name)
            checks.append(
                (name, len(v) == 2 and lo - 1e-9 <= v[0] <= v[1] <= hi + 1e-9, f"(lo, hi) within [{lo}, {hi}]")
            )
        for name, ok, want in checks:
            if not ok:
                raise UserError(f"composite setting {name} = {getattr(self, name)!r}: must be {want}")
        for k in range(self.min_primitives, self.max_primitives + 1):
            if not valid_chains(self.primitives, k):
                raise UserError(
                    f"composite setting primitives = {list(self.primitives)}: no allowed chain of {k} "
                    "(see ALLOWED: push and pull restrict what may follow)"
                )
        return self


#: ``composite-demo``: 72 sequences of 2-3 primitives, 31-40 steps each, joints only (CPU demo).
#: ``composite``: 600 sequences of 2-4 primitives, 40-70 steps each, joints only.
COMPOSITE_PRESETS: dict[str, CompositeConfig] = {
    "composite-demo": CompositeConfig(n_sequences=72, max_primitives=3, duration=(31, 40), transition_steps=8),
    "composite": CompositeConfig(),
}


def resolve_composite(config_or_preset) -> CompositeConfig:
    """A validated :class:`CompositeConfig` from a config, a preset name or a dict of fields."""
    if isinstance(config_or_preset, str):
        if config_or_preset not in COMPOSITE_PRESETS:
            raise UserError(
                f"unknown composite preset {config_or_preset!r}; choose from {', '.join(COMPOSITE_PRESETS)}"
            )
        config_or_preset = COMPOSITE_PRESETS[config_or_preset]
    elif isinstance(config_or_preset, dict):
        unknown = sorted(set(config_or_preset) - {f.name for f in fields(CompositeConfig)})
        if unknown:
            raise UserError(f"unknown composite setting(s): {', '.join(unknown)}")
        config_or_preset = CompositeConfig(**config_or_preset)
    if not isinstance(config_or_preset, CompositeConfig):
        raise UserError(f"expected a composite preset name or a CompositeConfig, got {type(config_or_preset).__name__}")
    try:
        return config_or_preset.validate()
    except (TypeError, ValueError) as exc:  # a value of the wrong kind (UserError passes through as it is)
        if isinstance(exc, UserError):
            raise
        raise UserError(f"composite settings: a value of the wrong kind ({exc})") from None


@cache
def valid_chains(primitives: tuple[str, ...], k: int) -> tuple[tuple[str, ...], ...]:
    """Every chain of ``k`` names from ``primitives`` with no immediate repeat that
    :data:`ALLOWED` permits (the block's zone follows :data:`MOVES_TO`), in a fixed order."""
    chains = []
    for chain in itertools.product(primitives, repeat=k):
        zone, ok = "start", True
        for prev, name in zip((None,) + chain, chain):
            ok = ok and name != prev and name in ALLOWED[zone]
            zone = MOVES_TO.get(name, zone)
        if ok:
            chains.append(chain)
    return tuple(chains)
