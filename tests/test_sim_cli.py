"""``primspace generate`` and ``primspace show``: files made, and bad input as one line."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import assert_figure, assert_user_error
from primspace.data import MotionDataset
from primspace.sim import generate

TINY = generate.GenerationConfig(block_x=(0.5,), block_y=(-0.05, 0.05), block_size=(0.05,), length=31)


@pytest.fixture
def tiny_preset(monkeypatch):
    """A 14-sample preset, so the command runs in a second (workers=1 runs in-process)."""
    monkeypatch.setitem(generate.PRESETS, "tiny", TINY)
    return "tiny"


def test_generate_writes_a_data_set(run_cli, tiny_preset, tmp_path):
    out = tmp_path / "sim.h5"
    res = run_cli(
        "generate", "--preset", tiny_preset, "--out", out, "--workers", 1, "--seed", 2, "--height", 24, "--width", 32
    )
    assert res.code == 0, res.err
    assert f"wrote {out}: 14 motions x 31 steps x 9 joints, images 24x32" in res.out
    ds = MotionDataset.load(out)
    assert ds.images.shape == (14, 31, 24, 32, 3)
    assert list(np.bincount(ds.labels)) == [2] * 7
    assert '"seed": 2' in ds.source


def test_generate_without_images(run_cli, tiny_preset, tmp_path):
    out = tmp_path / "joints.h5"
    res = run_cli("generate", "--preset", tiny_preset, "--out", out, "--workers", 1, "--no-images")
    assert res.code == 0, res.err
    assert "no images" in res.out and MotionDataset.load(out).images is None


@pytest.mark.slow
def test_show_draws_a_png(run_cli, tiny_preset, tmp_path):
    data, png = tmp_path / "sim.h5", tmp_path / "fig" / "sample.png"
    assert run_cli("generate", "--preset", tiny_preset, "--out", data, "--workers", 1).code == 0
    res = run_cli("show", data, "--sample", 5, "--out", png)
    assert res.code == 0, res.err
    assert_figure(png, height=(200, 3000), width=(300, 4000))
    assert_user_error(run_cli("show", data, "--sample", 14, "--out", png), "sample 14 out of range 0..13")


@pytest.mark.parametrize(
    "args, fragments",
    [
        (("--preset", "huge"), ("unknown preset 'huge'", "paper, demo")),
        (("--preset", "tiny", "--height", "0"), ("image size 0x64",)),
        (("--preset", "tiny", "--width", "5000"), ("image size 48x5000",)),
        (("--preset", "tiny", "--workers", "0"), ("--workers 0",)),
    ],
)
def test_generate_bad_input_is_one_line_and_writes_nothing(run_cli, tiny_preset, tmp_path, args, fragments):
    out = tmp_path / "d.h5"
    assert_user_error(run_cli("generate", "--out", out, *args), *fragments)
    assert list(tmp_path.iterdir()) == []


def test_generate_refuses_an_existing_file(run_cli, tiny_preset, tmp_path):
    out = tmp_path / "d.h5"
    out.write_bytes(b"old")
    assert_user_error(run_cli("generate", "--preset", tiny_preset, "--out", out), str(out), "--overwrite")
    assert out.read_bytes() == b"old"


def test_generate_ik_miss_names_the_sample(run_cli, monkeypatch, tmp_path):
    monkeypatch.setitem(generate.PRESETS, "strict", dataclasses.replace(TINY, ik_tolerance=1e-9))
    out = tmp_path / "d.h5"
    res = run_cli("generate", "--preset", "strict", "--out", out, "--workers", 1, "--no-images")
    assert_user_error(res, str(out), "sample 0", "inverse kinematics misses", "mm")
    assert list(tmp_path.iterdir()) == []


def test_show_missing_file(run_cli, tmp_path):
    assert_user_error(run_cli("show", tmp_path / "none.h5", "--out", tmp_path / "x.png"), "none.h5", "no such file")


def test_generate_with_a_config_file(run_cli, tiny_preset, tmp_path):
    settings = tmp_path / "grid.json"
    settings.write_text(
        '{"block_x": [0.44, 0.56], "block_y": [0.0], "primitives": ["push", "pull"], "jitter": 0, "images": false}'
    )
    out = tmp_path / "d.h5"
    res = run_cli("generate", "--preset", tiny_preset, "--config", settings, "--out", out, "--workers", 1)
    assert res.code == 0, res.err
    ds = MotionDataset.load(out)
    assert ds.images is None
    np.testing.assert_array_equal(ds.labels, [2, 2, 3, 3])
    np.testing.assert_allclose(ds.params[:, 0], [0.44, 0.56, 0.44, 0.56], atol=1e-6)


@pytest.mark.parametrize(
    "text, fragments",
    [
        ('{"block_x": [0.5, 0.9], "jitter": 0}', ("block_x = 0.9 m", "outside the table")),
        ('{"block_size": [0.01]}', ("block_size = 0.01 m", "outside the table")),
        ('{"block_y": [-0.4]}', ("block_y = -0.4 m",)),
        ('{"primitives": ["dance"]}', ("unknown primitive 'dance'",)),
        ('{"length": "long"}', ("length", "not an integer")),
        ('{"speed": 2}', ("unknown generation setting(s): speed",)),
        ("[1, 2", ("cannot read a JSON object",)),
    ],
)
def test_generate_bad_config_file(run_cli, tiny_preset, tmp_path, text, fragments):
    settings = tmp_path / "bad.json"
    settings.write_text(text)
    out = tmp_path / "d.h5"
    res = run_cli("generate", "--preset", tiny_preset, "--config", settings, "--out", out)
    assert_user_error(res, "bad.json", *fragments)
    assert not out.exists()
