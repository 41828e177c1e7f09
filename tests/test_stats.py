"""The spread over seeds as the docs print it (issue 42): the sample std (ddof 1) and the
95 % Student-t interval of the mean, :mod:`primspace.utils.stats`."""

import math

import numpy as np
import pytest

from primspace.utils.stats import sample_std, spread_convention, t_factor, t_interval


def test_t_interval_of_one_two_three():
    # mean 2, sample std sqrt((1 + 0 + 1) / 2) = 1; half-width t(0.975, 2) / sqrt(3) = 4.303 / 1.732 = 2.484
    mean, half = t_interval([1.0, 2.0, 3.0])
    assert mean == 2.0 and sample_std([1.0, 2.0, 3.0]) == 1.0
    assert half == pytest.approx(4.302653 / math.sqrt(3), rel=1e-6) and round(half, 3) == 2.484


def test_t_interval_scales_with_the_sample_std_and_the_level():
    values = [0.8, 0.9, 1.0]  # std 0.1 (ddof 1; numpy's default ddof 0 gives 0.0816)
    assert sample_std(values) == pytest.approx(np.std(values, ddof=1)) and sample_std(values) == pytest.approx(0.1)
    assert t_interval(values)[1] == pytest.approx(0.2484, abs=1e-4)
    # two values: t(0.975, 1) = 12.706, / sqrt(2) = 8.985; five: t(0.975, 4) = 2.776, / sqrt(5) = 1.242
    assert t_factor(2) == pytest.approx(8.9846, abs=1e-4) and t_factor(5) == pytest.approx(1.2417, abs=1e-4)
    # 90 %: t(0.95, 2) = 2.920, / sqrt(3) = 1.686
    assert t_interval([1.0, 2.0, 3.0], level=0.9)[1] == pytest.approx(1.6859, abs=1e-4)
    # many values: the t quantile tends to the normal 1.96
    assert t_factor(10_000) * math.sqrt(10_000) == pytest.approx(1.96, abs=1e-3)


def test_one_value_has_no_spread_and_none_is_an_error():
    assert t_interval([0.5])[0] == 0.5 and math.isnan(t_interval([0.5])[1])
    assert math.isnan(sample_std([0.5])) and math.isnan(t_factor(1))
    with pytest.raises(ValueError, match="at least one"):
        t_interval([])
    with pytest.raises(ValueError, match="level"):
        t_interval([1.0, 2.0], level=1.0)


def test_the_convention_names_the_factors_it_uses():
    text = spread_convention((3, 5))
    assert "sample std, ddof 1" in text and "t(0.975, n-1) · std / sqrt(n)" in text
    assert "2.48 · std for 3 seeds, 1.24 · std for 5 seeds" in text
