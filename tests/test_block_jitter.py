"""``block_jitter``: each sample jittered on its own (``each``, every preset's default, the
data as before) or one jitter per (primitive, grid cell) shared by the cell's sizes
(``shared``, the paper's layout); seeded by the sample's index alone, whatever the shards."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.sim import generate
from primspace.sim.config import BLOCK_JITTERS, PRESETS, GenerationConfig, sample_params
from primspace.utils.errors import UserError

PAPER = PRESETS["paper"]
SHARED = dataclasses.replace(PAPER, block_jitter="shared")

#: ``sample_params`` before ``block_jitter`` existed (computed with the unmodified code):
#: (preset, seed, index) -> (label, block_x, block_y, block_size).
PINNED = [
    ("paper", 0, 0, (0, 0.4220544253098218, -0.15575533215590323, 0.035)),
    ("paper", 0, 1, (0, 0.425846081869172, -0.14857154874484435, 0.0425)),
    ("paper", 0, 244, (0, 0.5986647512945003, 0.1439594419425795, 0.065)),
    ("paper", 7, 1000, (4, 0.4145824598270371, 0.052840266866829834, 0.035)),
    ("demo", 3, 17, (0, 0.5712117931891837, 0.13575475794831082, 0.06)),
    ("demo", 3, 125, (6, 0.593284637607136, 0.12749394488358154, 0.06)),
]

#: 2 primitives x 2 x 2 positions x 2 sizes = 16 motions, joints only (a fraction of a second).
TINY = GenerationConfig(
    block_x=(0.46, 0.54), block_y=(-0.05, 0.05), block_size=(0.04, 0.06), primitives=("push", "touch"), length=31
)


def all_params(config: GenerationConfig, seed: int, indices=None) -> np.ndarray:
    indices = range(config.n_samples) if indices is None else indices
    return np.array([sample_params(config, seed, i) for i in indices])


def cells(config: GenerationConfig, params: np.ndarray) -> np.ndarray:
    """``params`` (N, 4) as (primitive, x cell, y cell, size, 4)."""
    shape = (len(config.primitives), len(config.block_x), len(config.block_y), len(config.block_size), 4)
    return params.reshape(shape)


# ------------------------------------------------------------------------- each


def test_presets_keep_each():
    assert BLOCK_JITTERS == ("each", "shared")
    assert all(config.block_jitter == "each" for config in PRESETS.values())
    assert GenerationConfig().block_jitter == "each"


@pytest.mark.parametrize("preset, seed, index, expected", PINNED)
def test_each_gives_the_parameters_of_before(preset, seed, index, expected):
    config = PRESETS[preset]
    assert sample_params(config, seed, index) == expected  # exactly: same floats
    assert sample_params(dataclasses.replace(config, block_jitter="each"), seed, index) == expected


def test_each_moves_the_sizes_of_a_cell_apart():
    grid = cells(PAPER, all_params(PAPER, 0))
    assert np.all(np.ptp(grid[..., 1], axis=3) > 0) and np.all(np.ptp(grid[..., 2], axis=3) > 0)


# ----------------------------------------------------------------------- shared


def test_shared_sizes_of_a_cell_share_one_position():
    params = all_params(SHARED, 0)
    grid = cells(SHARED, params)
    # the five sizes of every (primitive, cell) at exactly one position
    assert np.all(grid[..., 1] == grid[..., :1, 1]) and np.all(grid[..., 2] == grid[..., :1, 2])
    np.testing.assert_array_equal(grid[0, 0, 0, :, 3], PAPER.block_size)
    # labels, sizes and the grid order are those of "each"; only the positions moved
    each = all_params(PAPER, 0)
    np.testing.assert_array_equal(params[:, [0, 3]], each[:, [0, 3]])
    # within the jitter's reach of the grid point, as with "each"
    for axis, column in (("block_x", 1), ("block_y", 2)):
        centres = np.asarray(getattr(PAPER, axis))
        offset = grid[..., column] - (centres[:, None, None] if axis == "block_x" else centres[None, :, None])
        assert np.abs(offset).max() <= PAPER.jitter * PAPER.spacing(axis) + 1e-12
    # every (primitive, cell) draws its own position: 7 x 49 distinct ones
    positions = {tuple(p) for p in grid[:, :, :, 0, 1:3].reshape(-1, 2)}
    assert len(positions) == len(PAPER.primitives) * PAPER.n_positions
    # the same cell differs between primitives, and neighbouring cells differ
    assert np.all(grid[0, :, :, 0, 1] != grid[1, :, :, 0, 1])
    assert np.all(grid[:, 0, :, 0, 2] != grid[:, 1, :, 0, 2])


def test_shared_is_reproducible_and_seeded():
    first, again = all_params(SHARED, 5), all_params(SHARED, 5)
    np.testing.assert_array_equal(first, again)
    other = all_params(SHARED, 6)
    assert np.all(first[:, 1] != other[:, 1])
    np.testing.assert_array_equal(first[:, [0, 3]], other[:, [0, 3]])


def test_shared_does_not_depend_on_the_order_or_the_shards():
    reference = all_params(SHARED, 2)
    shuffled = np.random.default_rng(0).permutation(SHARED.n_samples)
    np.testing.assert_array_equal(all_params(SHARED, 2, shuffled), reference[shuffled])
    for a, b in reversed(generate.shard_ranges(SHARED.n_samples)):
        np.testing.assert_array_equal(all_params(SHARED, 2, range(a, b)), reference[a:b])


def test_shared_positions_do_not_depend_on_the_other_primitives():
    push = dataclasses.replace(SHARED, primitives=("push",))
    full = cells(SHARED, all_params(SHARED, 1))
    np.testing.assert_array_equal(cells(push, all_params(push, 1))[0], full[SHARED.primitives.index("push")])


def test_shared_without_jitter_is_the_exact_grid():
    exact = dataclasses.replace(SHARED, jitter=0.0)
    np.testing.assert_array_equal(all_params(exact, 0), all_params(dataclasses.replace(exact, block_jitter="each"), 0))


def test_shared_motions_do_not_depend_on_the_shards():
    config = dataclasses.replace(TINY, images=False, block_jitter="shared")
    whole = generate.generate_shard(config, 4, range(config.n_samples))
    parts = [generate.generate_shard(config, 4, range(a, a + 4)) for a in (12, 8, 4, 0)][::-1]
    for name in ("motor", "params", "labels"):
        np.testing.assert_array_equal(np.concatenate([p[name] for p in parts]), whole[name])
    grid = whole["params"].reshape(2, 2, 2, 2, 3)
    assert np.all(grid[..., 0, :2] == grid[..., 1, :2])  # both sizes at one position
    assert not np.array_equal(whole["motor"][0], whole["motor"][1])  # sizes still differ


# ----------------------------------------------------------------- validation


@pytest.mark.parametrize("value", ["both", "", "Shared"])
def test_a_bad_block_jitter_is_refused(value):
    with pytest.raises(UserError, match=r"block_jitter = .*must be one of each, shared") as info:
        dataclasses.replace(TINY, block_jitter=value).validate()
    assert "\n" not in str(info.value)


def test_block_jitter_in_the_saved_config():
    d = dataclasses.replace(TINY, block_jitter="shared").to_dict()
    assert d["block_jitter"] == "shared"
    assert GenerationConfig.from_dict(d).block_jitter == "shared"
    del d["block_jitter"]  # as written before the field existed
    assert GenerationConfig.from_dict(d).block_jitter == "each"
    with pytest.raises(UserError, match="block_jitter: 3 is not a string"):
        GenerationConfig.from_dict({"block_jitter": 3})


# ------------------------------------------------------------------------ CLI


@pytest.fixture
def tiny_preset(monkeypatch):
    monkeypatch.setitem(generate.PRESETS, "tiny", TINY)
    return "tiny"


def source_config(ds: MotionDataset) -> dict:
    prefix = "primspace.sim "
    assert ds.source.startswith(prefix), ds.source
    return json.loads(ds.source[len(prefix) :])["config"]


def test_generate_block_jitter_shared(run_cli, tiny_preset, tmp_path):
    out = tmp_path / "shared.h5"
    res = run_cli(
        "generate", "--preset", tiny_preset, "--out", out, "--workers", 1, "--no-images", "--block-jitter", "shared"
    )
    assert res.code == 0, res.err
    ds = MotionDataset.load(out)
    assert source_config(ds)["block_jitter"] == "shared"
    shared = dataclasses.replace(TINY, images=False, block_jitter="shared")
    np.testing.assert_array_equal(ds.params, all_params(shared, 0)[:, 1:].astype(np.float32))
    grid = ds.params.reshape(2, 2, 2, 2, 3)
    assert np.all(grid[..., 0, :2] == grid[..., 1, :2])


def test_generate_defaults_to_the_presets_each(run_cli, tiny_preset, tmp_path):
    out = tmp_path / "each.h5"
    assert run_cli("generate", "--preset", tiny_preset, "--out", out, "--workers", 1, "--no-images").code == 0
    ds = MotionDataset.load(out)
    assert source_config(ds)["block_jitter"] == "each"
    np.testing.assert_array_equal(ds.params, all_params(TINY, 0)[:, 1:].astype(np.float32))


@pytest.mark.parametrize(
    "args, fragments",
    [
        (("--preset", "tiny", "--block-jitter", "both"), ("--block-jitter 'both'", "each, shared")),
        (("--preset", "composite-demo", "--block-jitter", "shared"), ("--block-jitter", "composite-demo")),
    ],
)
def test_generate_bad_block_jitter_is_one_line(run_cli, tiny_preset, tmp_path, args, fragments):
    assert_user_error(run_cli("generate", "--out", tmp_path / "d.h5", *args), *fragments)
    assert list(tmp_path.iterdir()) == []


def test_generate_bad_block_jitter_in_a_config_file(run_cli, tiny_preset, tmp_path):
    settings = tmp_path / "bad.json"
    settings.write_text('{"block_jitter": "cells"}')
    res = run_cli("generate", "--preset", tiny_preset, "--config", settings, "--out", tmp_path / "d.h5")
    assert_user_error(res, "bad.json", "block_jitter = 'cells'", "each, shared")
