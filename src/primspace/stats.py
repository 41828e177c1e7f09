"""Small statistics helpers (no torch, no mujoco): imported by experiment and report code.

- :func:`wilson_interval`: the Wilson score interval of a binomial proportion (success
  rates of the simulator's judge, :mod:`primspace.experiments.success`).
"""

from __future__ import annotations

import math
from statistics import NormalDist

__all__ = ["wilson_interval", "normal_quantile"]


def normal_quantile(confidence: float) -> float:
    """The two-sided standard normal quantile ``z = Phi^-1(1 - (1 - confidence) / 2)``.

    Parameters
    ----------
    confidence : float
        In (0, 1); 0.95 gives z = 1.959964.

    Returns
    -------
    float
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    return NormalDist().inv_cdf(1.0 - (1.0 - confidence) / 2.0)


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval for a success rate of ``successes`` out of ``n`` trials.

    With ``p = successes / n`` and ``z`` the two-sided normal quantile of ``confidence``
    (1.959964 for 0.95, :func:`normal_quantile`)::

        centre = (p + z^2 / (2 n)) / (1 + z^2 / n)
        half   = z / (1 + z^2 / n) * sqrt(p (1 - p) / n + z^2 / (4 n^2))
        (low, high) = (centre - half, centre + half)

    (Wilson 1927; Brown, Cai & DasGupta 2001). Unlike the normal ("Wald") interval it
    stays inside [0, 1] and is not empty at 0 or n successes: 0 of n gives
    ``(0, z^2 / (n + z^2))``, n of n gives ``(n / (n + z^2), 1)``. The bounds are
    clipped to [0, 1] against rounding, and exactly 0 (1) at 0 (n) successes.

    Parameters
    ----------
    successes : int
        Number of successes, 0 <= successes <= n.
    n : int
        Number of trials, >= 0. With ``n = 0`` nothing is known: the interval is
        ``(0.0, 1.0)`` (every rate possible), not NaN, so it stays valid JSON.
    confidence : float, default 0.95
        Coverage, in (0, 1).

    Returns
    -------
    (float, float)
        ``(low, high)``.

    Raises
    ------
    ValueError
        For counts that are negative, not whole numbers or ``successes > n``, or a
        confidence outside (0, 1).

    Examples
    --------
    >>> [round(v, 4) for v in wilson_interval(5, 10)]
    [0.2366, 0.7634]
    """
    z = normal_quantile(confidence)
    if int(successes) != successes or int(n) != n:
        raise ValueError(f"counts must be whole numbers, got {successes} of {n}")
    successes, n = int(successes), int(n)
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    z2 = z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2.0 * n)) / denom
    half = z / denom * math.sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n))
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return low, high
