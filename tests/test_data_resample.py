"""Frequency-domain resampling (paper, Motion Capture Data), endpoint-corrected."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.signal import resample as plain_fourier_resample

from primspace.data import resample
from primspace.utils.errors import DataError

lengths = st.integers(min_value=2, max_value=120)
finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=60, deadline=None)
@given(t0=st.integers(9, 80), t=st.integers(9, 160), data=st.data())
def test_band_limited_signal_plus_trend_resamples_exactly(t0, t, data):
    # Period = the motion's duration, sampled at both ends (k / (T0 - 1)); bandwidth
    # below half of min(T0, T) - 1 so both grids resolve it.
    n_max = max(1, (min(t0, t) - 1) // 2 - 1)
    harmonics = data.draw(st.lists(st.integers(1, n_max), min_size=1, max_size=3))
    coefs = data.draw(st.lists(st.floats(-2, 2), min_size=2 * len(harmonics) + 2, max_size=2 * len(harmonics) + 2))

    def signal(time):
        out = coefs[0] + coefs[1] * time
        for i, h in enumerate(harmonics):
            out = (
                out + coefs[2 + 2 * i] * np.sin(2 * np.pi * h * time) + coefs[3 + 2 * i] * np.cos(2 * np.pi * h * time)
            )
        return out

    x = signal(np.linspace(0, 1, t0))
    np.testing.assert_allclose(resample(x, t), signal(np.linspace(0, 1, t)), atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(t0=st.integers(4, 60), t=st.integers(4, 120), data=st.data())
def test_periodic_mode_is_the_papers_formula_and_exact_on_band_limited_periods(t0, t, data):
    h = data.draw(st.integers(1, max(1, (min(t0, t) - 1) // 2)))
    a, b = data.draw(finite), data.draw(finite)
    sig = lambda k, n: a * np.sin(2 * np.pi * h * k / n) + b * np.cos(2 * np.pi * h * k / n)  # noqa: E731
    if 2 * h >= min(t0, t):  # the Nyquist bin of an even grid cannot hold a sine
        return
    np.testing.assert_allclose(
        resample(sig(np.arange(t0), t0), t, periodic=True), sig(np.arange(t), t), atol=1e-8 * (1 + abs(a) + abs(b))
    )


@settings(max_examples=80, deadline=None)
@given(x=arrays(np.float64, st.tuples(st.integers(2, 70), st.integers(1, 4)), elements=finite), t=lengths)
def test_any_sequence_keeps_its_first_and_last_values(x, t):
    y = resample(x, t)
    assert y.shape == (t, x.shape[1])
    scale = np.abs(x).max() + 1e-12
    np.testing.assert_allclose(y[0], x[0], atol=1e-6 * scale, rtol=0)
    np.testing.assert_allclose(y[-1], x[-1], atol=1e-6 * scale, rtol=0)


@pytest.mark.parametrize("t0,t", [(50, 61), (61, 20), (1000, 61), (7, 3)])
def test_a_ramp_is_kept_exactly_where_plain_fft_rings(t0, t):
    ramp = np.linspace(-1.0, 2.0, t0)
    np.testing.assert_allclose(resample(ramp, t), np.linspace(-1.0, 2.0, t), atol=1e-12)
    if t > t0:  # the literal formula rings at the wrap-around: the reason for the correction
        plain = plain_fourier_resample(ramp, t)
        assert abs(plain[-1] - 2.0) > 0.1


def test_downsampling_low_passes_and_keeps_ends():
    k = np.linspace(0, 1, 400)
    x = np.sin(2 * np.pi * k) + 0.3 * np.sin(2 * np.pi * 150 * k)  # a tone above the new band
    y = resample(x, 41)
    np.testing.assert_allclose(y, np.sin(2 * np.pi * np.linspace(0, 1, 41)), atol=1e-9)


def test_shapes_batch_list_and_single():
    rng = np.random.default_rng(0)
    assert resample(rng.normal(size=(3, 17, 2)), 9).shape == (3, 9, 2)
    assert resample(rng.normal(size=(17, 2)), 9).shape == (9, 2)
    out = resample([rng.normal(size=(5, 2)), rng.normal(size=(40, 2))], 12)
    assert out.shape == (2, 12, 2)
    np.testing.assert_allclose(resample(np.ones((1, 8, 1)) * 3.0, 5), 3.0)


def test_length_one_sequence_is_a_clear_error_naming_the_sample():
    with pytest.raises(DataError, match=r"sample 1: a sequence of length 1 cannot be resampled"):
        resample([np.zeros((4, 2)), np.zeros((1, 2))], 10)


def test_bad_inputs():
    with pytest.raises(DataError, match="sample 1.*has 3 joints"):
        resample([np.zeros((4, 2)), np.zeros((4, 3))], 10)
    with pytest.raises(DataError, match="NaN"):
        resample(np.array([0.0, np.nan, 1.0]), 10)
    with pytest.raises(DataError, match="target length"):
        resample(np.zeros(5), 1)
