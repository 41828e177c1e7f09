"""The one check of a seed, for every layer that takes one (training, generation, experiments).

numpy's ``SeedSequence`` refuses a negative seed with a traceback and torch's
``manual_seed`` one of 2**64 or more; a seed is therefore a whole number in
``0 .. MAX_SEED``, checked where it enters, with one line naming the option.

scikit-learn takes seeds in ``0 .. 2**32-1`` only: what it gets is :func:`library_seed` of
ours, never a user's seed unchecked.
"""

from __future__ import annotations

import numpy as np

from primspace.utils.errors import UserError

__all__ = ["MAX_SEED", "LIBRARY_MAX_SEED", "check_seed", "library_seed"]

#: The largest seed accepted.
MAX_SEED = 2**63 - 1
#: The largest seed scikit-learn (numpy's legacy ``RandomState``) takes.
LIBRARY_MAX_SEED = 2**32 - 1


def check_seed(seed, name: str = "seed") -> int:
    """``seed`` as a whole number in 0 .. :data:`MAX_SEED`, or one UserError naming ``name``."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or not 0 <= seed <= MAX_SEED:
        raise UserError(f"{name} must be a whole number in 0..{MAX_SEED}, got {seed!r}")
    return int(seed)


def library_seed(seed, name: str = "seed") -> int:
    """A seed for a library that takes 0 .. :data:`LIBRARY_MAX_SEED` (scikit-learn), derived from
    ``seed`` (checked by :func:`check_seed`): the seed itself where it fits (so its numbers stay
    as they were), else the first 32-bit word of numpy's ``SeedSequence(seed)``."""
    seed = check_seed(seed, name)
    if seed <= LIBRARY_MAX_SEED:
        return seed
    return int(np.random.SeedSequence(seed).generate_state(1, np.uint32)[0])
