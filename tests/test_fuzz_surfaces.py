"""Fuzz the surfaces of issue 38: predict's options, segment's bounds, npz numbering, names
from data reaching paths. Seeded draws (hypothesis, derandomised): every outcome is a result
or one UserError/DataError line; never a traceback, a hang, a wrong pairing or a path outside
the output folder."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from primspace.utils.errors import DataError, UserError

FUZZ = settings(max_examples=60, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck))


@pytest.mark.slow
@FUZZ
@given(st.text(max_size=12))
def test_an_observed_amount_is_a_number_a_word_or_one_line(text):
    """``--observe`` / ``--observe-frames``: whatever is typed parses or is one UserError."""
    from primspace.cli.observing import parse_amount
    from primspace.train.observe import Observation

    try:
        amount = parse_amount(text, "--observe", ("none",))
        Observation.build(amount, "first")
    except UserError as exc:
        assert "\n" not in str(exc).strip("\n") or "\n" in text
    else:
        assert amount == "none" or isinstance(amount, (int, float))


@FUZZ
@given(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.integers(min_value=-5, max_value=10**9),
)
def test_segment_bounds_are_a_setting_or_one_line(lo, hi, grid):
    """min_steps / max_steps / grid of any size give settings whose candidate lengths are bounded
    by the data (the cap of model_inputs) or one UserError; never a hang."""
    from primspace.segmentation.synthesis import SynthesisSettings, candidate_segments

    try:
        chosen = SynthesisSettings.for_model(30, lo, hi, grid)
    except (UserError, OverflowError, ValueError) as exc:
        assert isinstance(exc, UserError), exc
        return
    keys = candidate_segments(40, chosen.capped(40))  # model_inputs caps them at the data's T
    assert len(keys) <= 40 * 40 and all(0 <= s < e <= 40 for s, e in np.asarray(keys).reshape(-1, 2)[:, :2])


@FUZZ
@given(
    st.sets(st.integers(min_value=0, max_value=5), min_size=1, max_size=5),
    st.sets(st.integers(min_value=0, max_value=5), max_size=5),
)
def test_npz_numbering_never_pairs_joints_with_another_samples_frames(tmp_path_factory, joints, frames):
    """arr_N and images_N of any numbering: imported with sample i's joints beside sample i's
    frames, or refused in one line."""
    from primspace.data.importers.npz import import_npz

    path = tmp_path_factory.mktemp("npz") / "f.npz"
    arrays = {f"arr_{i}": np.full((5, 2), float(i)) for i in joints}
    arrays |= {f"images_{i}": np.full((5, 8, 8, 3), 10 * i, np.uint8) for i in frames}
    np.savez(path, **arrays)
    try:
        ds = import_npz(path, 5, image_size=(8, 8))
    except DataError as exc:
        assert "\n" not in str(exc)
        return
    assert sorted(joints) == list(range(len(joints)))  # imported only when numbered without a gap
    for i in range(len(ds)):
        assert np.allclose(ds.motor[i], i)
        if ds.has_images:
            assert int(np.median(ds.images[i])) == 10 * i  # its own frames


@FUZZ
@given(st.text(min_size=0, max_size=400))
def test_no_name_from_data_reaches_a_path(tmp_path_factory, name):
    """Any label or task name: its figure and animation lie in OUT/figures, under 255 bytes."""
    from primspace.results.layout import animation_file, figure_file

    out = tmp_path_factory.mktemp("exp")
    for path in (figure_file(out, f"reconstruction_{name}"), animation_file(out, name)):
        assert path.parent == out / "figures" and len(path.name.encode()) < 255
        assert path.resolve().parent == (out / "figures").resolve()
