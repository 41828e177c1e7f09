import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from primspace.data import JointScaler
from primspace.utils.errors import DataError, UserError

values = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False, width=64)
shapes = st.tuples(st.integers(1, 6), st.integers(1, 12), st.integers(1, 5))


@settings(max_examples=80, deadline=None)
@given(x=arrays(np.float64, shapes, elements=values))
def test_scales_into_unit_box_and_inverts(x):
    scaler = JointScaler().fit(x)
    y = scaler.transform(x)
    assert y.shape == x.shape
    assert np.all(y >= -1 - 1e-9) and np.all(y <= 1 + 1e-9)
    # a joint moves when its half range is a positive float (5e-324 / 2 underflows to 0:
    # such a joint is still, as for the scaler)
    moving = (x.reshape(-1, x.shape[-1]).max(0) - x.reshape(-1, x.shape[-1]).min(0)) / 2 > 0
    # every moving joint reaches both ends of [-1, 1]
    flat = y.reshape(-1, y.shape[-1])
    np.testing.assert_allclose(flat.min(0)[moving], -1, atol=1e-9)
    np.testing.assert_allclose(flat.max(0)[moving], 1, atol=1e-9)
    np.testing.assert_allclose(scaler.inverse_transform(y), x, rtol=1e-12, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(x=arrays(np.float64, shapes, elements=values))
def test_serialises_exactly(x):
    scaler = JointScaler().fit(x)
    import json

    restored = JointScaler.from_dict(json.loads(json.dumps(scaler.to_dict())))
    np.testing.assert_array_equal(restored.transform(x), scaler.transform(x))


def test_constant_joint_does_not_divide_by_zero():
    x = np.stack([np.linspace(0, 1, 10), np.full(10, 3.5)], axis=-1)[None]
    scaler = JointScaler().fit(x)
    y = scaler.transform(x)
    assert np.isfinite(y).all()
    np.testing.assert_array_equal(y[..., 1], 0.0)
    np.testing.assert_allclose(scaler.inverse_transform(y), x)


def test_float32_in_float32_out_and_frames_work():
    x = np.random.default_rng(0).normal(size=(50, 3)).astype(np.float32)
    y = JointScaler().fit(x).transform(x)
    assert y.dtype == np.float32


def test_errors():
    with pytest.raises(UserError, match="not fitted"):
        JointScaler().transform(np.zeros((2, 2)))
    scaler = JointScaler().fit(np.zeros((3, 2)))
    with pytest.raises(DataError, match="3 joints.*fitted on 2"):
        scaler.transform(np.zeros((3, 3)))
    with pytest.raises(DataError, match="NaN"):
        JointScaler().fit(np.array([[np.nan, 1.0]]))
    with pytest.raises(UserError):
        JointScaler.from_dict({"data_min": [1.0], "data_max": [0.0]})


def test_restored_scaler_is_bit_identical_for_float32_data():
    x = np.random.default_rng(3).normal(size=(4, 7, 3)).astype(np.float32)
    scaler = JointScaler().fit(x)
    restored = JointScaler.from_dict(scaler.to_dict())
    np.testing.assert_array_equal(restored.transform(x), scaler.transform(x))
    assert scaler.data_min_.dtype == np.float64
