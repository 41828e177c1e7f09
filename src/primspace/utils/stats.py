"""Small statistics helpers (no torch, no mujoco): imported by experiment and report code.

- :func:`wilson_interval`: the Wilson score interval of a binomial proportion (success
  rates of the simulator's judge, :mod:`primspace.experiments.success`).
- the spread over seeds as the docs and the report print it: :func:`sample_std` (ddof 1),
  :func:`t_interval` (the mean and its two-sided Student-t half-width; :func:`t_factor`
  the half-width per std), and :func:`spread_convention`, the sentence that says so.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from statistics import NormalDist, fmean, stdev

__all__ = ["wilson_interval", "normal_quantile", "sample_std", "t_factor", "t_interval", "spread_convention"]


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


def sample_std(values: Iterable[float]) -> float:
    """The sample standard deviation (ddof 1, ``sqrt(sum (x - mean)^2 / (n - 1))``) of
    ``values``: the spread over seeds every table prints; NaN for fewer than two values
    (one seed has no spread).

    With three seeds the population std (ddof 0) is ``sqrt(2/3)`` of it: it understates
    the spread and makes "a gap beyond the spread" lenient.

    Examples
    --------
    >>> sample_std([1.0, 2.0, 3.0])
    1.0
    """
    v = [float(x) for x in values]
    return stdev(v) if len(v) > 1 else math.nan


def t_factor(n: int, level: float = 0.95) -> float:
    """``t(1 - (1 - level) / 2, n - 1) / sqrt(n)``: the two-sided Student-t interval's
    half-width of a mean of ``n`` values, in units of their sample std (NaN for n < 2).

    Examples
    --------
    >>> round(t_factor(3), 3)
    2.484
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if n < 2:
        return math.nan
    from scipy.stats import t  # scipy only where an interval is asked for

    return float(t.ppf(1.0 - (1.0 - level) / 2.0, n - 1)) / math.sqrt(n)


def t_interval(values: Iterable[float], level: float = 0.95) -> tuple[float, float]:
    """The mean of ``values`` and the half-width of its two-sided Student-t interval::

        half_width = t(1 - (1 - level) / 2, n - 1) * std / sqrt(n)      (std: ddof 1)

    The interval is ``mean ± half_width``: with 2-10 seeds the t quantile (12.7 for two,
    4.30 for three, 2.78 for five) is well above the normal 1.96.

    Parameters
    ----------
    values : iterable of float
        The per-seed values, at least one.
    level : float, default 0.95
        Coverage, in (0, 1).

    Returns
    -------
    (float, float)
        ``(mean, half_width)``; the half-width is NaN for a single value (no spread).

    Raises
    ------
    ValueError
        For no values, or a level outside (0, 1).

    Examples
    --------
    >>> mean, half = t_interval([1.0, 2.0, 3.0])
    >>> mean, round(half, 3)
    (2.0, 2.484)
    """
    v = [float(x) for x in values]
    if not v:
        raise ValueError("t_interval needs at least one value")
    return fmean(v), t_factor(len(v), level) * sample_std(v)


def spread_convention(seeds: Iterable[int] = (3, 5)) -> str:
    """The sentence that states, once per page, how a spread over seeds is printed: the
    sample std (ddof 1) and the 95 % t-interval half-width, with its factor for each
    number of ``seeds`` the page shows."""
    factors = ", ".join(f"{t_factor(n):.3g} · std for {n} seeds" for n in seeds)
    return (
        "Spreads: mean ± std over seeds (sample std, ddof 1); 95 % t-interval half-width = "
        f"t(0.975, n-1) · std / sqrt(n) ({factors})."
    )
