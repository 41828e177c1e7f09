"""Padded demonstrations: arrays ``(N, Tmax, ...)`` whose samples end early.

Lab recordings of different lengths are often saved as one array ``(N, Tmax, J)``, each
sample padded to ``Tmax`` by repeating its last value (EIPL's data sets, many ``.npz``
and ``.npy`` files). Resampling a padded sample to ``T`` steps would stretch the real
motion over only part of the output and spend the rest on the hold (the issue that
brought this rule measured joints up to 1.8 units off for 15 real steps padded to 23).

The rule (:func:`padded_lengths`)
---------------------------------
Without given lengths, sample ``i``'s length is the smallest ``L`` such that every step
from ``L - 1`` to the end equals step ``L - 1`` **exactly** (all joints; frames do not
decide), but at least 2 steps (the fewest that can be resampled; a sample of one step
stays one step). So the trailing steps that repeat the last value are taken as padding,
and the first step of the hold is kept.

A demonstration that genuinely holds still at its end is trimmed the same way, to its
last moving step + 1: the rule cannot tell a hold from padding. Where the hold matters,
keep the padding (``keep_padding=True``, ``--keep-padding``: every sample is ``Tmax``
steps, as before) or give the lengths (``lengths``: :func:`checked_lengths`).
Values that differ in the last bit, or NaN, are never padding.
"""

from __future__ import annotations

import numpy as np

from primspace.utils.errors import DataError

__all__ = ["padded_lengths", "checked_lengths", "padding_note"]


def padded_lengths(values: np.ndarray) -> np.ndarray:
    """The length of each sample of ``values`` ``(N, Tmax, ...)`` without its padding (module docstring).

    Examples
    --------
    >>> x = np.array([[[0.0], [1.0], [2.0], [2.0], [2.0]], [[5.0], [5.0], [5.0], [5.0], [5.0]]])
    >>> padded_lengths(x).tolist()
    [3, 2]
    """
    n, t_max = values.shape[:2]
    width = int(np.prod(values.shape[2:], dtype=np.int64))
    out = np.empty(n, dtype=np.int64)
    for i in range(n):  # one sample at a time: ``values`` may be a memory map
        sample = np.asarray(values[i]).reshape(t_max, width)
        moved = np.flatnonzero((sample[1:] != sample[:-1]).any(axis=1))  # step k+1 differs from step k
        out[i] = moved[-1] + 2 if moved.size else 1
    return np.minimum(np.maximum(out, 2), t_max)


def checked_lengths(lengths, n: int, t_max: int, *, path=None, field: str = "lengths") -> np.ndarray:
    """Given valid lengths of ``n`` padded samples of ``t_max`` steps, as int64.

    Raises
    ------
    DataError
        Naming ``path``, ``field`` and the sample: not integers, not one per sample, or a
        length outside ``2 .. t_max`` (2: the fewest steps that can be resampled).
    """
    lengths = np.asarray(lengths)
    if lengths.dtype.kind not in "iu":
        raise DataError(f"must be integers, got {lengths.dtype}", path=path, field=field)
    if lengths.shape != (n,):
        raise DataError(f"must be one length per sample, shape ({n},), got {lengths.shape}", path=path, field=field)
    for i, t in enumerate(lengths.tolist()):
        if not 2 <= t <= t_max:
            raise DataError(
                f"length {t} is outside 2 .. {t_max} (the padded steps; at least 2 are needed to resample)",
                path=path,
                field=field,
                index=i,
            )
    return lengths.astype(np.int64)


def padding_note(lengths: np.ndarray, t_max: int) -> str:
    """For the data set's ``source`` text: ``; padding trimmed in 3 of 5 samples`` ('' if none was)."""
    trimmed = int(np.count_nonzero(np.asarray(lengths) < t_max))
    return f"; padding trimmed in {trimmed} of {len(lengths)} samples" if trimmed else ""
