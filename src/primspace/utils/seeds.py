"""The one check of a seed, for every layer that takes one (training, generation, experiments).

numpy's ``SeedSequence`` refuses a negative seed with a traceback and torch's
``manual_seed`` one of 2**64 or more; a seed is therefore a whole number in
``0 .. MAX_SEED``, checked where it enters, with one line naming the option.
"""

from __future__ import annotations

import numpy as np

from primspace.utils.errors import UserError

__all__ = ["MAX_SEED", "check_seed"]

#: The largest seed accepted.
MAX_SEED = 2**63 - 1


def check_seed(seed, name: str = "seed") -> int:
    """``seed`` as a whole number in 0 .. :data:`MAX_SEED`, or one UserError naming ``name``."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or not 0 <= seed <= MAX_SEED:
        raise UserError(f"{name} must be a whole number in 0..{MAX_SEED}, got {seed!r}")
    return int(seed)
