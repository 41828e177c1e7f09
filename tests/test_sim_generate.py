"""Simulated data generation: shapes, labels, params, determinism, images, bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from primspace.sim.generate import (
    PARAM_NAMES,
    PRESETS,
    GenerationConfig,
    generate_dataset,
    resolve_config,
    sample_params,
    simulate_sample,
)
from primspace.sim.primitives import PRIMITIVES, script_motion
from primspace.sim.render import Camera
from primspace.sim.scene import JOINT_NAMES, Scene
from primspace.utils.errors import DataError, OutputExistsError, UserError

TINY = GenerationConfig(block_x=(0.45, 0.55), block_y=(0.0,), block_size=(0.05,), length=31, height=24, width=32)


@pytest.fixture(scope="module")
def tiny():
    return generate_dataset(TINY, seed=3, workers=1, progress=False)


@pytest.fixture(scope="module")
def scene():
    return Scene()


def test_shapes_labels_and_params(tiny):
    n = 7 * 2
    assert len(tiny) == n
    assert tiny.motor.shape == (n, 31, 9) and tiny.motor.dtype == np.float32
    assert tiny.images.shape == (n, 31, 24, 32, 3) and tiny.images.dtype == np.uint8
    assert tiny.joint_names == list(JOINT_NAMES)
    assert tiny.label_names == list(PRIMITIVES)
    assert tiny.param_names == list(PARAM_NAMES)
    # primitive-major order: two positions per primitive
    np.testing.assert_array_equal(tiny.labels, np.repeat(np.arange(7), 2))
    # jitter keeps every block within a quarter of the grid spacing of its grid point
    grid_x = np.tile([0.45, 0.55], 7)
    assert np.all(np.abs(tiny.params[:, 0] - grid_x) <= 0.25 * 0.10 + 1e-6)
    assert np.all(tiny.params[:, 1] == 0.0)  # one y value: no spacing, no jitter
    np.testing.assert_allclose(tiny.params[:, 2], 0.05)
    assert tiny.dt == 1.0 and '"seed": 3' in tiny.source


def test_every_generated_sample_passes_the_success_judge(tiny):
    from primspace.sim.success import evaluate_dataset

    results = evaluate_dataset(tiny)  # the stored float32 joints, replayed
    assert all(r.success for r in results), [r.reason for r in results if not r.success]


def test_every_motion_starts_at_the_same_home_pose(tiny):
    start = tiny.motor[:, 0]
    np.testing.assert_allclose(start, np.broadcast_to(start[0], start.shape), atol=1e-6)


def test_ik_tracks_the_scripted_path_within_2mm(tiny, scene):
    for i in range(len(tiny)):
        label, x, y, size = (int(tiny.labels[i]), *map(float, tiny.params[i]))
        script = script_motion(scene, label, x, y, size, tiny.length)
        tcp, rot = scene.tcp_path(tiny.motor[i])
        err = np.linalg.norm(tcp - script.tcp, axis=1).max()
        assert err < 0.002, (i, err)
        # gripper pointing down throughout
        assert np.all(rot[:, 2, 2] < -0.999)


@pytest.mark.slow
def test_same_seed_same_arrays_for_any_worker_count(tmp_path):
    one = generate_dataset(TINY, seed=5, workers=1, out=tmp_path / "one.h5", progress=False)
    two = generate_dataset(TINY, seed=5, workers=2, out=tmp_path / "two.h5", progress=False)
    np.testing.assert_array_equal(one.motor, two.motor)
    np.testing.assert_array_equal(one.params, two.params)
    np.testing.assert_array_equal(one.labels, two.labels)
    np.testing.assert_array_equal(np.asarray(one.images), np.asarray(two.images))


def test_seed_moves_blocks_within_their_cells_only():
    cfg = PRESETS["demo"]
    a = [sample_params(cfg, 0, i) for i in range(0, cfg.n_samples, 5)]
    b = [sample_params(cfg, 1, i) for i in range(0, cfg.n_samples, 5)]
    xy_a, xy_b = np.array(a)[:, 1:3], np.array(b)[:, 1:3]
    # every block moves in x and in y, by a few mm to cm (two uniform jitters: mean |difference|
    # 2/3 of the jitter range, measured 15 mm), and each stays within a quarter spacing of its grid point
    assert (xy_a != xy_b).all()
    limit = cfg.jitter * np.array([cfg.spacing("block_x"), cfg.spacing("block_y")])
    assert np.abs(xy_a - xy_b).mean() > 0.2 * limit.min()
    for xy in (xy_a, xy_b):
        for axis, grid in enumerate((cfg.block_x, cfg.block_y)):
            off_grid = np.abs(xy[:, axis, None] - np.array(grid)[None, :]).min(axis=1)
            assert (off_grid <= limit[axis] + 1e-12).all(), (axis, off_grid.max())
    assert [s[0] for s in a] == [s[0] for s in b]  # labels and sizes do not depend on the seed
    assert [s[3] for s in a] == [s[3] for s in b]
    exact = dataclasses.replace(cfg, jitter=0.0)
    assert sample_params(exact, 0, 7) == sample_params(exact, 99, 7)


def test_presets_have_the_documented_sizes():
    paper, demo = PRESETS["paper"], PRESETS["demo"]
    assert (len(paper.block_x), len(paper.block_y), len(paper.block_size)) == (7, 7, 5)
    assert paper.n_per_primitive == 245 and paper.n_samples == 1715
    assert paper.length == 61 and (paper.height, paper.width) == (48, 64)
    assert demo.n_samples == 126 and demo.length == 61
    for cfg in (paper, demo):
        cfg.validate()
        assert GenerationConfig.from_dict(cfg.to_dict()) == cfg


def test_the_block_is_visible_and_moves_when_pushed(scene):
    cfg = PRESETS["paper"]  # the real 48 x 64 frames
    with Camera(scene, cfg.height, cfg.width) as camera:
        motor, images, _ = simulate_sample(scene, camera, cfg, PRIMITIVES.index("push"), 0.45, 0.0, 0.045, 0)
    red = (images[..., 0] > 150) & (images[..., 1] < 70) & (images[..., 2] < 70)
    counts = red.reshape(len(red), -1).sum(axis=1)
    assert counts[0] >= 4 and counts[-1] >= 2, counts  # a 4.5 cm block is a few pixels wide
    centre = [np.argwhere(r).mean(axis=0) for r in (red[0], red[-1])]
    assert np.linalg.norm(centre[1] - centre[0]) > 5  # pushed 25 cm: it moves across the image
    # the arm is in view too (light-grey pixels), and the image changes as it moves
    grey = (images[..., 0] > 180) & (np.abs(images[..., 0].astype(int) - images[..., 2]) < 30)
    assert grey[0].sum() > 20
    # measured: 10% of the 48 x 64 pixels differ by more than 30 (of 255) between steps 0 and 30,
    # 20% by the last step; a static scene stays put (a moving camera would change almost every pixel)
    changed = np.abs(images.astype(int) - images[0]).max(axis=-1) > 30
    fraction = changed.reshape(len(changed), -1).mean(axis=1)
    assert 0.05 < fraction[30] < 0.4 and 0.1 < fraction[-1] < 0.5, fraction[[30, -1]]


def test_ik_miss_names_the_sample_and_writes_nothing(tmp_path):
    strict = dataclasses.replace(TINY, ik_tolerance=1e-9)
    out = tmp_path / "bad.h5"
    with pytest.raises(DataError, match=r"sample 0: inverse kinematics misses the scripted path by [0-9.]+ mm"):
        generate_dataset(strict, workers=1, out=out, progress=False)
    assert list(tmp_path.iterdir()) == []


def test_existing_output_is_refused_before_any_work(tmp_path):
    out = tmp_path / "d.h5"
    out.write_text("keep me")
    with pytest.raises(OutputExistsError):
        generate_dataset(TINY, out=out, progress=False)
    assert out.read_text() == "keep me"


@pytest.mark.parametrize(
    "change, fragment",
    [
        ({"block_x": (0.50, 0.90)}, "block_x = 0.9 m"),
        ({"block_y": (-0.5, 0.0)}, "block_y = -0.5 m"),
        ({"block_size": (0.2,)}, "block_size = 0.2 m"),
        ({"block_size": (0.0,)}, "block_size = 0 m"),
        ({"block_x": (0.38, 0.62), "jitter": 0.25}, "with jitter"),
        ({"primitives": ("touch", "wave")}, "unknown primitive 'wave'"),
        ({"length": 10}, "length (T) = 10"),
        ({"height": 0}, "image size 0x32"),
    ],
)
def test_bad_settings_are_one_clear_error(change, fragment):
    with pytest.raises(UserError) as info:
        resolve_config(dataclasses.replace(TINY, **change))
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_unknown_preset():
    with pytest.raises(UserError, match="unknown preset 'huge'; choose from paper, demo"):
        resolve_config("huge")


def test_joints_only_generation_has_no_images():
    ds = generate_dataset(dataclasses.replace(TINY, images=False, primitives=("grasp",)), workers=1, progress=False)
    assert ds.images is None and len(ds) == 2
    np.testing.assert_array_equal(ds.labels, [1, 1])  # labels stay the primitive's index
