"""See the motion (issue 13, item 4): animated GIFs of a sample, `primspace animate`, the
simulator's replay of generated joints, and the report's one animation per primitive."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from conftest import assert_user_error
from primspace.plots.animation import FRAME_MS, MAX_FRAMES, MAX_SIZE, animation_frames, frame_steps, save_gif

# flat panel colours that nothing else in the figure has
RED, GREEN, BLUE = (250, 0, 0), (0, 250, 0), (0, 0, 250)


def _coloured_frames(t_len: int, base, h: int = 12, w: int = 16) -> np.ndarray:
    """Flat frames whose colour encodes the step: ``base`` with its zero channels = 4 * t."""
    frames = np.zeros((t_len, h, w, 3), dtype=np.uint8)
    for t in range(t_len):
        frames[t] = [c if c else 4 * t for c in base]
    return frames


def _motor(t_len: int, n_joints: int = 3) -> np.ndarray:
    t = np.linspace(0, 1, t_len)[:, None]
    return np.sin(3 * t + np.arange(n_joints)) * (1 + np.arange(n_joints))


def _pixels(frame: np.ndarray, colour) -> np.ndarray:
    """Column indices of the pixels of exactly ``colour``."""
    return np.nonzero((frame == np.array(colour, dtype=np.uint8)).all(axis=-1))[1]


def _gif_frames(path) -> list[np.ndarray]:
    with Image.open(path) as gif:
        out = []
        for i in range(gif.n_frames):
            gif.seek(i)
            out.append(np.asarray(gif.convert("RGB")))
    return out


# ----------------------------------------------------------------------- frames (arrays only)


def test_frames_show_each_panel_at_its_step_and_a_moving_cursor():
    t_len = 61
    recorded, generated, replayed = (_coloured_frames(t_len, c) for c in (RED, GREEN, BLUE))
    frames, steps = animation_frames(
        _motor(t_len),
        _motor(t_len) + 0.1,
        images=recorded,
        generated_images=generated,
        replay_images=replayed,
        joint_names=["a", "b", "c"],
        dt=0.5,
        title="three panels",
    )
    assert len(frames) == MAX_FRAMES and np.array_equal(steps, frame_steps(t_len)) and steps[0] == 0 and steps[-1] == 60
    assert frames.dtype == np.uint8 and frames.shape[1] <= MAX_SIZE[0] and frames.shape[2] <= MAX_SIZE[1]
    right_of_panels = []
    for frame, t in zip(frames, steps):
        # every panel shows its frame of step t (a flat colour covering a panel: > 1000 px), left to right
        cols = [_pixels(frame, (c[0] or 4 * t, c[1] or 4 * t, c[2] or 4 * t)) for c in (RED, GREEN, BLUE)]
        assert all(len(c) > 1000 for c in cols), (t, [len(c) for c in cols])
        assert cols[0].max() < cols[1].min() and cols[1].max() < cols[2].min()
        right_of_panels.append(cols[2].max())
    # the cursor moves right: the pixels that change between two frames right of the panels
    # are the old and new cursor columns, so their mean column grows frame after frame
    x0 = max(right_of_panels) + 1
    centres = []
    for a, b in zip(frames[:-1], frames[1:]):
        changed = np.nonzero((a[:, x0:] != b[:, x0:]).any(axis=-1))[1]
        assert changed.size > 0
        centres.append(changed.mean())
    assert np.all(np.diff(centres) > 0), centres


def test_frames_and_size_are_bounded():
    t_len = 61
    frames, steps = animation_frames(_motor(t_len), images=_coloured_frames(t_len, RED), max_frames=8)
    assert len(frames) == len(steps) == 8 and steps[-1] == t_len - 1
    few, steps = animation_frames(_motor(5), max_frames=MAX_FRAMES)  # fewer steps than frames: every step once
    assert len(few) == 5 and list(steps) == [0, 1, 2, 3, 4]
    # a tighter pixel bound lowers the resolution; panels widen the figure
    small, _ = animation_frames(_motor(t_len), images=_coloured_frames(t_len, RED), max_frames=2, max_size=(100, 300))
    assert small.shape[1] <= 100 and small.shape[2] <= 300
    three, _ = animation_frames(
        _motor(t_len),
        images=_coloured_frames(t_len, RED),
        generated_images=_coloured_frames(t_len, GREEN),
        replay_images=_coloured_frames(t_len, BLUE),
        max_frames=2,
    )
    assert three.shape[2] > frames.shape[2] > few.shape[2]
    with pytest.raises(ValueError, match="recorded frames must have shape"):
        animation_frames(_motor(t_len), images=_coloured_frames(t_len - 1, RED))


def _moving_square(t_len: int, colour, h: int = 36, w: int = 48) -> np.ndarray:
    """Grey frames with a 6 x 6 square of ``colour`` moving from the left edge to the right one."""
    frames = np.full((t_len, h, w, 3), 128, dtype=np.uint8)
    for t in range(t_len):
        x = round(t * (w - 6) / (t_len - 1))
        frames[t, 15:21, x : x + 6] = colour
    return frames


def test_gif_is_a_looping_animation_of_the_frames_written_atomically(tmp_path):
    t_len = 40
    frames, _ = animation_frames(
        _motor(t_len), images=_moving_square(t_len, RED), replay_images=_moving_square(t_len, BLUE)
    )
    path = save_gif(frames, tmp_path / "a.gif")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.gif"]  # no temporary left
    assert path.read_bytes()[:6] == b"GIF89a"
    with Image.open(path) as gif:
        assert gif.is_animated and gif.n_frames == len(frames) == 30
        assert gif.size == (frames.shape[2], frames.shape[1])
        assert gif.info["loop"] == 0 and gif.info["duration"] == FRAME_MS
    decoded = _gif_frames(path)
    assert max(np.abs(d.astype(int) - f).mean() for d, f in zip(decoded, frames)) < 2  # 255 colours suffice here
    for d, f in zip(decoded, frames):  # white and black stay exact (background, text, cursor)
        for value in (255, 0):
            assert (d[(f == value).all(axis=-1)] == value).all()
    # each panel's square moves right, frame after frame; the recorded panel lies left of the replay
    centres = {"red": [], "blue": []}
    for d in decoded:
        d = d.astype(int)
        red = np.nonzero((d[..., 0] > 200) & (d[..., 1] < 50) & (d[..., 2] < 50))[1]
        blue = np.nonzero((d[..., 2] > 200) & (d[..., 0] < 50) & (d[..., 1] < 50))[1]
        assert red.size > 100 and blue.size > 100 and red.max() < blue.min()
        centres["red"].append(red.mean())
        centres["blue"].append(blue.mean())
    assert all(np.all(np.diff(c) > 0) for c in centres.values()), centres
    with pytest.raises(ValueError):
        save_gif(frames[..., 0], tmp_path / "b.gif")
    assert not (tmp_path / "b.gif").exists()


# -------------------------------------------------------------------------- the simulator


@pytest.fixture(scope="module")
def sim_file(tmp_path_factory):
    """Touch and push at two block positions: 4 motions of 31 steps with 48 x 64 frames."""
    from primspace.sim.generate import GenerationConfig, generate_dataset

    config = GenerationConfig(
        block_x=(0.45, 0.55), block_y=(0.0,), block_size=(0.05,), primitives=("touch", "push"), length=31
    )
    path = tmp_path_factory.mktemp("sim") / "sim.h5"
    generate_dataset(config, seed=0, out=path, progress=False)
    return path


@pytest.fixture(scope="module")
def sim_run(sim_file, tmp_path_factory):
    """A small run with an image head on samples 0, 1, 2 (sample 3 left out)."""
    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, fit

    ds = MotionDataset.load(sim_file).load_images()
    out = tmp_path_factory.mktemp("run") / "run"
    fit(
        ds,
        out,
        model_config=ModelConfig(latent_dim=3, layer_sizes=(12, 6), image_channels=(4, 4, 4)),
        train_config=TrainConfig(epochs=1, batch_size=4, threads=1),
        indices=[0, 1, 2],
        progress=False,
    )
    return out


def test_replay_of_the_recorded_joints_shows_the_recorded_frames(sim_file):
    from primspace.data import MotionDataset
    from primspace.sim.render import replay_frames
    from primspace.sim.scene import Scene

    ds = MotionDataset.load(sim_file)
    scene = Scene()
    images = np.asarray(ds.images[:])
    for i in (1, 3):  # a touch and a push (the block moves)
        frames = replay_frames(ds.motor[i], ds.params[i], int(ds.labels[i]), 48, 64, scene=scene)
        assert frames.shape == images[i].shape and frames.dtype == np.uint8
        # the stored joints are float32, the generator rendered float64: a few edge pixels differ
        assert (frames != images[i]).any(axis=-1).mean() < 0.01
        other = replay_frames(ds.motor[i], ds.params[i - 1], int(ds.labels[i]), 48, 64, scene=scene)  # block elsewhere
        assert (other != images[i]).any(axis=-1).mean() > 0.01
    assert replay_frames(ds.motor[0], ds.params[0], "grasp", 24, 32, scene=scene).shape == (31, 24, 32, 3)


# ---------------------------------------------------------------------------------- the CLI


def test_animate_writes_a_gif_with_every_panel(run_cli, sim_run, tmp_path):
    out = tmp_path / "a.gif"
    res = run_cli("animate", sim_run, "--sample", 2, "--out", out, "--frames", 12)
    assert res.code == 0, res.err
    assert f"wrote {out}" in res.out and "panels: recorded, generated, simulator replay" in res.out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.gif"]
    with Image.open(out) as gif:
        assert gif.is_animated and gif.n_frames == 12 and gif.size[0] <= MAX_SIZE[1] and gif.size[1] <= MAX_SIZE[0]
        width = gif.size[0]
    # the block is red: it shows in the recorded and the replay panels (the 1-epoch model's frames are grey)
    first = _gif_frames(out)[0].astype(int)
    red = (first[..., 0] > 150) & (first[..., 1] < 60) & (first[..., 2] < 60)
    cols = np.nonzero(red)[1]
    assert cols.size > 20 and cols.max() - cols.min() > width / 3, (cols.min(), cols.max(), width)
    res = run_cli("animate", sim_run, "--sample", 2, "--out", tmp_path / "b.gif", "--no-replay")
    assert res.code == 0, res.err
    assert "panels: recorded, generated," in res.out and "replay" not in res.out
    with Image.open(tmp_path / "b.gif") as gif:
        assert gif.size[0] < width and gif.n_frames == MAX_FRAMES  # 31 steps, 30 frames by default


@pytest.mark.slow
def test_animate_refuses_bad_options_in_one_line(run_cli, sim_run, tmp_path):
    out = tmp_path / "a.gif"
    assert_user_error(
        run_cli("animate", sim_run, "--sample", 3, "--out", out), "sample 3 is not one of the run's 3 samples"
    )
    assert_user_error(run_cli("animate", sim_run, "--sample", 99, "--out", out), "sample 99 is not one of the run's")
    for frames in (1, 0, -4):
        assert_user_error(
            run_cli("animate", sim_run, "--sample", 0, "--out", out, "--frames", frames),
            f"--frames {frames}: must be at least 2",
        )
    assert not out.exists()
    assert run_cli("animate", sim_run, "--sample", 0, "--out", out, "--frames", 3).code == 0
    before = out.read_bytes()
    assert_user_error(run_cli("animate", sim_run, "--sample", 1, "--out", out), str(out), "--overwrite")
    assert out.read_bytes() == before
    assert run_cli("animate", sim_run, "--sample", 1, "--out", out, "--overwrite").code == 0
    assert out.read_bytes() != before
    assert_user_error(
        run_cli("animate", sim_run, "--sample", 0, "--out", sim_run / "config.json", "--overwrite"), "config.json"
    )


def test_animate_leaves_the_replay_out_for_data_not_of_the_simulator(run_cli, tmp_path):
    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, fit

    rng = np.random.default_rng(0)
    ds = MotionDataset(
        np.stack([_motor(10) * a for a in (1.0, 1.5, 2.0)]),
        images=rng.integers(0, 255, (3, 10, 8, 8, 3), dtype=np.uint8),
        labels=np.array([0, 1, 0]),
        dt=0.5,
    )
    ds.save(tmp_path / "d.h5")
    fit(
        MotionDataset.load(tmp_path / "d.h5").load_images(),
        tmp_path / "run",
        model_config=ModelConfig(latent_dim=2, layer_sizes=(8, 4), image_channels=(4, 4, 4)),
        train_config=TrainConfig(epochs=1, batch_size=4, threads=1),
        progress=False,
    )
    res = run_cli("animate", tmp_path / "run", "--sample", 1, "--out", tmp_path / "a.gif")
    assert res.code == 0, res.err
    assert "panels: recorded, generated, joint trace; no simulator replay: not the simulator's data" in res.out
    with Image.open(tmp_path / "a.gif") as gif:
        assert gif.n_frames == 10


def test_the_cli_default_is_the_plots_bound():
    from primspace.cli import animate

    assert animate._MAX_FRAMES == MAX_FRAMES


# ---------------------------------------------------------------------- experiment and report


@pytest.mark.slow
def test_one_animation_per_primitive_in_the_report(sim_file, tmp_path):
    """The intra experiment writes each primitive's arrays and GIF; figures redraw them from
    the results alone; the report embeds the GIFs that exist and leaves out a missing one."""
    from primspace.experiments import figures
    from primspace.experiments.intra import run_intra
    from primspace.experiments.workspace import ExperimentDir
    from primspace.report import build_report
    from test_experiments import TINY

    exp = ExperimentDir(
        tmp_path / "out", replace(TINY, inits=("projection",)), data=sim_file, workers=1, progress=False
    )
    run_intra(exp)
    meta = json.loads((exp.path / "results" / "intra_animation.json").read_text())
    assert [a["name"] for a in meta["animations"]] == ["touch", "push"]
    assert all(a["panels"] == ["recorded", "simulator replay"] and a["note"] is None for a in meta["animations"])
    gifs = sorted(p.name for p in (exp.path / "figures").glob("*.gif"))
    assert gifs == ["animation_push.gif", "animation_touch.gif"]
    for name in gifs:
        with Image.open(exp.path / "figures" / name) as gif:
            assert gif.is_animated and gif.n_frames == MAX_FRAMES
        assert (exp.path / "figures" / name).stat().st_size < 300_000
    html = build_report(exp.path).read_text()
    assert html.count('src="data:image/gif;base64,') == 2 and ">Motions, animated" in html
    assert "sample 1 (primitive touch): infer run, init projection, q=4. Panels: recorded, simulator replay." in html

    copy = tmp_path / "copy"  # drawn from the results alone
    shutil.copytree(exp.path / "results", copy / "results")
    drawn = figures.draw_animations(copy)
    assert sorted(p.name for p in drawn) == gifs
    for path in drawn:
        assert all(
            np.array_equal(a, b) for a, b in zip(_gif_frames(path), _gif_frames(exp.path / "figures" / path.name))
        )

    (exp.path / "figures" / "animation_push.gif").unlink()
    html = build_report(exp.path).read_text()
    assert html.count('src="data:image/gif;base64,') == 1 and "animation_push" not in html
