"""`show` on long demonstrations draws their segments (the step fields) and only their valid
steps, and a prediction's observed steps where the data set marks them (issue 37, section 3)."""

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402

from primspace.data import MotionDataset  # noqa: E402
from primspace.plots.samples import plot_sim_sample, step_segments  # noqa: E402


def _long():
    """Two demonstrations of T = 12: push (0-4) then pull (5-8) and 3 padded steps; pull alone (0-11)."""
    rng = np.random.default_rng(0)
    step_labels = [[0] * 5 + [1] * 4 + [-1] * 3, [1] * 12]
    step_segments_ = [[0] * 5 + [1] * 4 + [-1] * 3, [0] * 12]
    return MotionDataset(
        rng.normal(size=(2, 12, 3)),
        labels=[-1, 1],
        label_names=["push", "pull"],
        lengths=[9, 12],
        step_labels=step_labels,
        step_segments=step_segments_,
        dt=0.1,
    )


def _bands(ax):
    return [p for p in ax.patches if p.get_alpha() is not None]


def test_the_segments_of_a_long_demonstration_are_drawn_and_named(tmp_path, run_cli):
    data = _long()
    assert step_segments(data, 0) == [(0, 5, "push"), (5, 9, "pull")]
    fig = plot_sim_sample(data, 0)
    joints = [ax for ax in fig.axes if ax.lines]
    assert len(joints) == 3 and all(len(_bands(ax)) == 2 for ax in joints)  # before: no bands
    assert [t.get_text() for t in joints[0].texts] == ["push", "pull"]
    assert all(len(ax.lines[0].get_xdata()) == 9 for ax in joints)  # the 3 padded steps are not drawn
    data.save(tmp_path / "long.h5")
    assert run_cli("show", tmp_path / "long.h5", "--sample", 1, "--out", tmp_path / "s.png").code == 0


def test_observed_steps_are_shaded_where_the_data_set_marks_them():
    data = MotionDataset(np.zeros((1, 10, 2)))
    assert step_segments(data, 0) is None
    assert not any(_bands(ax) for ax in plot_sim_sample(data, 0).axes)
    data.observed = np.arange(10)[None] < 4  # a per-step boolean field 'observed' (a prediction's)
    fig = plot_sim_sample(data, 0)
    shaded = [_bands(ax) for ax in fig.axes if ax.lines]
    assert all(len(b) == 1 for b in shaded)
    box = shaded[0][0].get_extents().transformed(fig.axes[0].transData.inverted())  # in data units
    assert np.isclose(box.x0, -0.5) and np.isclose(box.x1, 3.5)
