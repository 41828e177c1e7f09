"""Long demonstrations (primspace.sim.composite): chains, per-step ground truth, smooth
transitions, padding, seeds, the HDF5 round trip and the chain rule."""

from __future__ import annotations

import numpy as np
import pytest

from primspace.data import MotionDataset
from primspace.sim.composite import (
    ALLOWED,
    COMPOSITE_PRESETS,
    MOVES_TO,
    CompositeConfig,
    SequencePlan,
    draw_plan,
    generate_composite,
    resolve_composite,
    simulate_sequence,
    transition_path,
    valid_chains,
)
from primspace.sim.primitives import PRIMITIVES, SCRIPT, get_primitive
from primspace.sim.scene import FINGERTIP_RADIUS
from primspace.utils.errors import DataError, UserError

TINY = CompositeConfig(n_sequences=6, min_primitives=2, max_primitives=3, duration=(31, 34), transition_steps=8)


@pytest.fixture(scope="module")
def tiny():
    return generate_composite(TINY, seed=0)


def _segments_of(plan: SequencePlan, transition: int) -> list[tuple[int, int]]:
    """(label, steps) of each segment the plan should produce."""
    return [
        (get_primitive(name).label, d + (transition if k else 0))
        for k, (name, d) in enumerate(zip(plan.chain, plan.durations))
    ]


def test_step_fields_follow_the_drawn_chains(tiny):
    assert tiny.motor.shape == (6, TINY.length, 9) and TINY.length == 3 * 34 + 2 * 8
    assert list(tiny.label_names) == list(PRIMITIVES) and (tiny.labels == -1).all()
    for i in range(len(tiny)):
        plan = draw_plan(TINY, 0, i)
        assert 2 <= len(plan.chain) <= 3 and all(a != b for a, b in zip(plan.chain, plan.chain[1:]))
        want_labels = np.concatenate([np.full(n, label) for label, n in _segments_of(plan, 8)])
        want_segments = np.concatenate([np.full(n, k) for k, (_, n) in enumerate(_segments_of(plan, 8))])
        n = int(tiny.lengths[i])
        assert n == len(want_labels) and 2 * 31 + 8 <= n <= TINY.length
        np.testing.assert_array_equal(tiny.step_labels[i, :n], want_labels)
        np.testing.assert_array_equal(tiny.step_segments[i, :n], want_segments)
        assert (tiny.step_labels[i, n:] == -1).all() and (tiny.step_segments[i, n:] == -1).all()
        np.testing.assert_allclose(tiny.params[i], plan.block, rtol=1e-6)


def test_padding_holds_the_last_valid_value(tiny):
    assert (tiny.lengths < TINY.length).any()
    for i, n in enumerate(tiny.lengths):
        assert (tiny.motor[i, n:] == tiny.motor[i, n - 1]).all()


def _steps_near_boundaries(ds, i: int, transition: int):
    """Per-step changes (arm: largest joint, rad; fingers: m) of sample ``i``, split into
    those within a script and the largest in each window around a segment boundary (the
    last 2 steps of a script, the transition, the first 2 of the next script)."""
    n = int(ds.lengths[i])
    steps = {
        "arm": np.abs(np.diff(ds.motor[i, :n, :7], axis=0)).max(axis=1),
        "fingers": np.abs(np.diff(ds.motor[i, :n, 7])),
    }
    seg = ds.step_segments[i, :n]
    starts = np.flatnonzero(np.diff(seg)) + 1  # first step of segments 1, 2, ...
    pos = np.arange(n) - np.searchsorted(seg, seg)  # step within its segment
    in_script = ((seg == 0) | (pos > transition))[1:]  # change t -> t + 1 inside one script
    within = {k: v[in_script] for k, v in steps.items()}
    near = {k: [v[b - 2 : b + transition + 2].max() for b in starts] for k, v in steps.items()}
    return within, near


def test_motion_is_smooth_across_segment_boundaries(tiny):
    """A jump at a boundary (the next script restarting from home, fingers snapping shut)
    would be a step several times larger than any within the single-primitive scripts."""
    parts = [_steps_near_boundaries(tiny, i, TINY.transition_steps) for i in range(len(tiny))]
    finger_typical = max(within["fingers"].max() for within, _ in parts)
    assert finger_typical > 0  # the data hold a grasp
    for i, (within, near) in enumerate(parts):
        assert max(near["arm"]) <= 1.5 * within["arm"].max(), (i, near["arm"], within["arm"].max())
        assert max(near["fingers"]) <= 2.0 * finger_typical, (i, near["fingers"], finger_typical)


def test_same_seed_same_arrays_other_seed_other_arrays(tiny):
    again = generate_composite(TINY, seed=0)
    for name in ("motor", "params", "lengths", "step_labels", "step_segments"):
        assert np.array_equal(getattr(again, name), getattr(tiny, name)), name
    other = generate_composite(TINY, seed=1)
    assert not np.array_equal(other.params, tiny.params)
    assert not np.array_equal(other.motor, tiny.motor)


def test_hdf5_round_trip_keeps_the_fields(tiny, tmp_path):
    path = generate_composite(TINY, seed=0, out=tmp_path / "c.h5")
    assert path == tmp_path / "c.h5"
    ds = MotionDataset.load(path)
    for name in ("motor", "labels", "params", "lengths", "step_labels", "step_segments"):
        np.testing.assert_array_equal(getattr(ds, name), getattr(tiny, name), err_msg=name)
    assert ds.label_names == list(PRIMITIVES) and "primspace.sim.composite" in ds.source
    with pytest.raises(UserError, match="exists"):
        generate_composite(TINY, seed=0, out=path)


def test_block_moves_with_push_and_pull_and_each_primitive_is_judged():
    from primspace.sim.generate import worker_scene

    plan = SequencePlan((0.5, 0.05, 0.05), ("push", "pull", "touch"), (31, 33, 32))
    seq = simulate_sequence(worker_scene(), TINY, plan, 0)  # verify: every script passes its judge
    seg = seq["step_segments"]
    assert seq["block"][0, 0] == pytest.approx(0.5)
    assert seq["block"][seg == 1][0, 0] == pytest.approx(
        SCRIPT.push_target_x, abs=2e-3
    )  # pull starts where push left it
    assert seq["block"][-1, 0] == pytest.approx(SCRIPT.pull_target_x, abs=2e-3)
    assert len(seq["motor"]) == 31 + 33 + 32 + 2 * 8


def test_ik_miss_is_an_error_naming_the_sample_and_writes_nothing(tmp_path):
    strict = CompositeConfig(n_sequences=4, max_primitives=2, duration=(31, 31), transition_steps=4, ik_tolerance=1e-12)
    with pytest.raises(DataError, match=r"x\.h5: field 'motor', sample 0: inverse kinematics misses .* mm"):
        generate_composite(strict, out=tmp_path / "x.h5")
    assert not (tmp_path / "x.h5").exists()


def test_transition_lifts_clear_of_the_block_then_goes_over_a_low_first_pose():
    size = 0.05
    z_safe = size + FINGERTIP_RADIUS + SCRIPT.hover
    start, low_key = np.array([0.45, 0.0, 0.02]), np.array([0.40, 0.1, 0.02])
    tcp, fingers, end = transition_path(start, 0.02, size, low_key, 10)
    assert len(tcp) == 10 and np.all(np.diff(tcp[:, 2]) >= -1e-12)
    assert end == pytest.approx([0.40, 0.1, z_safe])
    lifting = tcp[:, 2] < z_safe - 1e-9
    assert np.allclose(tcp[lifting, :2], start[:2])  # straight up first, no sideways sweep near the block
    assert fingers[0] > 0.02 and fingers[-1] < fingers[0]  # a grasp lets go as it lifts, then closes
    _, _, end = transition_path(start, 0.0, size, np.array([0.40, 0.1, z_safe]), 10)
    assert end == pytest.approx([0.45, 0.0, z_safe])  # a first pose at the safe height: just lift


def test_chain_rule():
    chains = valid_chains(PRIMITIVES, 3)
    assert {c[0] for c in chains} == set(PRIMITIVES)
    for chain in chains:
        zone = "start"
        for a, b in zip((None,) + chain, chain):
            assert a != b and b in ALLOWED[zone]
            zone = MOVES_TO.get(b, zone)
    assert ("push", "pull", "touch") in chains and ("pull", "touch", "grasp") in chains
    assert ("push", "touch", "circle_cw") not in chains and ("pull", "grasp", "push") not in chains
    assert valid_chains(("push", "pull"), 2) == (("push", "pull"),)  # a pulled block may not be pushed
    assert valid_chains(("push", "pull"), 3) == ()


def test_presets_and_settings_are_checked():
    demo, big = COMPOSITE_PRESETS["composite-demo"], COMPOSITE_PRESETS["composite"]
    assert demo.max_primitives == 3 and demo.image_size is None and 60 <= demo.n_sequences <= 90
    assert big.max_primitives == 4 and big.n_sequences >= 500 and big.length == 4 * 70 + 3 * big.transition_steps
    bad = (
        {"min_primitives": 1},
        {"duration": (20, 30)},
        {"block_x": (0.3, 0.6)},
        {"image_size": (0, 64)},
        {"primitives": ("push", "pull"), "max_primitives": 3},
        {"primitives": ("touch", "jump")},
        {"colour": 1},
    )
    for settings in bad:
        with pytest.raises(UserError):
            resolve_composite(settings)
    with pytest.raises(UserError, match="unknown composite preset"):
        resolve_composite("nope")


def test_generate_command_takes_composite_presets(run_cli, monkeypatch, tmp_path):
    from conftest import assert_user_error
    from primspace.sim import composite

    tiny = CompositeConfig(n_sequences=2, max_primitives=2, duration=(31, 32), transition_steps=4)
    monkeypatch.setitem(composite.COMPOSITE_PRESETS, "composite-tiny", tiny)
    out, settings = tmp_path / "long.h5", tmp_path / "s.json"
    settings.write_text('{"n_sequences": 3}')
    res = run_cli(
        "generate",
        "--preset",
        "composite-tiny",
        "--out",
        out,
        "--workers",
        1,
        "--config",
        settings,
        "--height",
        12,
        "--width",
        16,
        "--seed",
        4,
    )
    assert res.code == 0, res.err
    assert "3 long demonstrations of 2-2 primitives" in res.out and "images 12x16" in res.out
    ds = MotionDataset.load(out)
    assert ds.images.shape == (3, tiny.length, 12, 16, 3) and ds.step_segments.shape == (3, tiny.length)
    images = np.asarray(ds.images[0])
    n = int(ds.lengths[0])
    assert (images[n:] == images[n - 1]).all() and not (images[0] == images[n // 2]).all()
    assert '"seed": 4' in ds.source
    assert_user_error(
        run_cli("generate", "--preset", "composite-tiny", "--out", tmp_path / "r.h5", "--backend", "ray"), "locally"
    )
    assert_user_error(run_cli("generate", "--preset", "huge", "--out", tmp_path / "h.h5"), "composite-demo")
