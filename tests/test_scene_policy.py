"""The scene policy (issue 40): the motion from the block's colour in the first frame, per primitive;
surprise at a later frame corrects the belief; a new plan continues from the executed steps.

On a tiny simulated set (touch and push, a 3 x 3 grid of blocks, T = 31, with frames); the centre
block of each primitive is held out."""

from __future__ import annotations

import numpy as np
import pytest

from primspace.act.scene_policy import ScenePolicy, continue_from
from primspace.data import MotionDataset
from primspace.data.scaling import JointScaler
from primspace.utils.errors import UserError

#: The primitives simulated (labels 0 and 2 of the simulator's seven).
PRIMS = ("touch", "push")
#: Steps of a motion: the simulator's shortest.
T = 31
#: The steps whose frames the fixture's policy predicts.
STEPS = (0, 6, 12)


def simulate(path, images: bool = True) -> MotionDataset:
    """Touch and push on a 3 x 3 grid of 5 cm blocks (18 motions of 31 steps; 48 x 64 frames); ~3 s."""
    from primspace.sim.generate import GenerationConfig, generate_dataset

    config = GenerationConfig(
        primitives=PRIMS,
        block_x=(0.45, 0.5, 0.55),
        block_y=(-0.05, 0.0, 0.05),
        block_size=(0.05,),
        length=T,
        images=images,
    )
    generate_dataset(config, seed=0, out=path, progress=False)
    return MotionDataset.load(path)


def held_out(data: MotionDataset) -> np.ndarray:
    """Per primitive, the sample whose block is nearest the grid's centre (0.5, 0.0): inside the others' hull."""
    out = []
    for label in np.unique(data.labels):
        rows = np.flatnonzero(data.labels == label)
        out.append(rows[np.argmin(np.hypot(data.params[rows, 0] - 0.5, data.params[rows, 1]))])
    return np.array(out)


pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    data = simulate(tmp_path_factory.mktemp("sim") / "sim.h5")
    held = held_out(data)
    fitted = np.setdiff1d(np.arange(len(data)), held)
    scaler = JointScaler().fit(data.motor[fitted])
    motor = scaler.transform(data.motor).astype(np.float64)
    frames = np.asarray(data.images)
    policy = ScenePolicy(steps=STEPS, label_names=data.label_names).fit(
        motor[fitted], data.labels[fitted], None, frames[fitted]
    )
    return dict(data=data, held=held, fitted=fitted, scaler=scaler, motor=motor, frames=frames, policy=policy)


def _primitive(policy, label) -> int:
    return int(policy.primitives_.for_labels([int(label)])[0])


# ------------------------------------------------------------------------ forecast


@pytest.mark.slow
def test_forecast_has_the_shape_starts_at_the_given_joints_and_is_deterministic(sim):
    policy, held, motor, frames = sim["policy"], sim["held"], sim["motor"], sim["frames"]
    labels = sim["data"].labels[held]
    query = motor[held] + 0.05  # first joints other than any demonstration's: the plan must start there
    a = policy.forecast(query, labels=labels, frames=frames[held])
    assert a.motor.shape == (len(held), T, 9) and a.codes is None
    np.testing.assert_array_equal(a.motor[:, 0], query[:, 0])  # continuity: step 0 is the given joints
    assert np.isfinite(a.motor).all()
    b = policy.forecast(query, labels=labels, frames=frames[held])
    np.testing.assert_array_equal(a.motor, b.motor)
    first_only = policy.forecast(query, labels=labels, frames=frames[held, 0])  # (n, H, W, 3): the first frames
    np.testing.assert_array_equal(a.motor, first_only.motor)
    assert a.details["policy"]["steps"] == list(STEPS) and a.details["policy"]["space"] == "motion"
    assert a.details["policy"]["primitives"]["names"] == list(PRIMS)
    assert a.details["model_share"] == 0.0 and policy.model_share() == 0.0  # the motion map: no decoder
    assert ScenePolicy(space="code").model_share() == 1.0  # the codes map: all of it decoded
    # fitted again (the same seed; the motion map does not depend on the later steps): the same plans
    again = ScenePolicy(steps=(0,), label_names=sim["data"].label_names)
    again.fit(motor[sim["fitted"]], sim["data"].labels[sim["fitted"]], None, frames[sim["fitted"]])
    np.testing.assert_array_equal(again.forecast(query, labels=labels, frames=frames[held]).motor, a.motor)


def test_the_policy_is_closer_to_a_held_out_blocks_motion_than_the_mean_motion_and_succeeds(sim):
    from primspace.sim.success import evaluate

    data, held, fitted, motor = sim["data"], sim["held"], sim["fitted"], sim["motor"]
    plans = sim["policy"].forecast(motor[held], labels=data.labels[held], frames=sim["frames"][held]).motor
    physical = sim["scaler"].inverse_transform(plans)
    successes = 0
    for plan, joints, i in zip(plans, physical, held):
        mean = motor[fitted[data.labels[fitted] == data.labels[i]]].mean(axis=0)
        mean[0] = motor[i, 0]
        policy_mse = float(((plan - motor[i]) ** 2).mean())
        mean_mse = float(((mean - motor[i]) ** 2).mean())
        assert policy_mse < 0.25 * mean_mse, (data.label_names[data.labels[i]], policy_mse, mean_mse)
        successes += evaluate(int(data.labels[i]), joints, data.params[i, :3]).success
    assert successes >= 1


# ------------------------------------------------------------------------ surprise and correction


def test_surprise_is_small_on_the_demonstrations_own_frames(sim):
    policy, data, frames = sim["policy"], sim["data"], sim["frames"]
    for i in sim["fitted"]:
        k = _primitive(policy, data.labels[i])
        belief = policy.see(frames[i, :1])[0]
        for t in STEPS[1:]:
            error = policy.surprise(k, t, belief, policy.see(frames[i, t : t + 1])[0])
            assert error.shape == (3,) and np.abs(error).max() < policy.threshold, (i, t, error)
            assert policy.correct(k, t, belief, policy.see(frames[i, t : t + 1])[0]) is None
        # a step without a prediction: no surprise
        assert not policy.surprise(k, 5, belief, policy.see(frames[i, 5:6])[0]).any()


def test_a_block_moved_4_cm_surprises_and_the_belief_follows_it(sim):
    from primspace.sim.execute import Executor
    from primspace.sim.primitives import PRIMITIVES

    policy, data, frames, fitted = sim["policy"], sim["data"], sim["frames"], sim["fitted"]
    push = fitted[data.labels[fitted] == PRIMITIVES.index("push")]
    i = push[np.argmin(np.hypot(data.params[push, 0] - 0.45, data.params[push, 1]))]  # y ~ 0: room to move 4 cm
    x, y, size = (float(v) for v in data.params[i, :3])
    k, t = _primitive(policy, data.labels[i]), STEPS[1]
    with Executor("push", x, y, size, T) as ex:
        for q in data.motor[i, : t + 1]:
            ex.step(q)
        still = policy.see(ex.frame()[None])[0]
        ex.move_block(0.0, 0.04)
        moved = policy.see(ex.frame()[None])[0]
    belief = policy.see(frames[i, :1])[0]
    assert np.abs(policy.surprise(k, t, belief, still)).max() < policy.threshold
    assert policy.correct(k, t, belief, still) is None
    error = policy.surprise(k, t, belief, moved)
    assert np.abs(error).max() > policy.threshold, error
    corrected = policy.correct(k, t, belief, moved)
    assert corrected is not None and corrected.shape == belief.shape
    shift, seen_shift = corrected[1:] - belief[1:], moved[1:] - still[1:]  # the centroid (column, row), pixels
    assert np.linalg.norm(seen_shift) > 1.0
    cosine = shift @ seen_shift / (np.linalg.norm(shift) * np.linalg.norm(seen_shift))
    assert cosine > 0.9 and np.linalg.norm(shift) > 0.5 * np.linalg.norm(seen_shift), (shift, seen_shift)


# ------------------------------------------------------------------------ continuing a plan


def test_a_new_plan_keeps_the_executed_steps_and_joins_the_plan_after_the_horizon(sim):
    policy, data, motor, frames = sim["policy"], sim["data"], sim["motor"], sim["frames"]
    i = sim["held"][1]
    k, s, h = _primitive(policy, data.labels[i]), 8, int(policy.horizon)
    belief = policy.see(frames[i, :1])[0]
    plan = policy.plans([k], belief[None])[0][0]
    executed = motor[i, : s + 1] + 0.1  # executed elsewhere than planned
    out = policy.replan(k, belief, executed)
    assert out.shape == (T, 9)
    np.testing.assert_array_equal(out[: s + 1], executed)  # the executed steps are kept
    np.testing.assert_allclose(out[s + h :], plan[s + h :], atol=1e-12)  # joined the plan at s + horizon
    residual = executed[-1] - plan[s]
    np.testing.assert_allclose(out[s + 1] - out[s], plan[s + 1] - plan[s] - residual / h, atol=1e-12)  # no jump
    between = out[s + 1 : s + h] - plan[s + 1 : s + h]
    np.testing.assert_allclose(between, (1 - np.arange(1, h) / h)[:, None] * residual[None], atol=1e-12)


def test_continue_from_on_plain_arrays():
    plan = np.linspace(0, 1, 10)[:, None] * np.ones((1, 2))
    executed = np.full((4, 2), 5.0)
    out = continue_from(plan, executed, 1)  # horizon 1: the plan from the next step on
    np.testing.assert_array_equal(out[:4], executed)
    np.testing.assert_array_equal(out[4:], plan[4:])
    out = continue_from(plan, executed[:1], 3)
    assert out[0].tolist() == [5.0, 5.0] and np.array_equal(out[3:], plan[3:])
    np.testing.assert_allclose(out[1], plan[1] + (2 / 3) * (5.0 - plan[0]))
    assert np.array_equal(continue_from(plan, plan[:5], 4), plan)  # executed as planned: the plan unchanged


# ------------------------------------------------------------------------ bad inputs


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        (dict(steps=(T,)), "steps must lie in 0..30"),
        (dict(steps=(0, -1)), "steps must lie"),
        (dict(steps=()), "steps must lie"),
        (dict(threshold=0), "threshold"),
        (dict(threshold=-1.0), "threshold"),
        (dict(threshold="4"), "threshold"),
        (dict(horizon=0), "horizon"),
        (dict(horizon=2.5), "horizon"),
        (dict(horizon=True), "horizon"),
        (dict(space="pixels"), "space must be one of motion, code"),
        (dict(space="code"), "give the run"),
        (dict(primitive="pull"), "unknown primitive 'pull'"),
        (dict(primitive=5), "out of range"),
    ],
)
def test_bad_settings_are_user_errors(sim, kwargs, fragment):
    fitted = sim["fitted"]
    policy = ScenePolicy(label_names=sim["data"].label_names, **kwargs)
    with pytest.raises(UserError, match=fragment):
        policy.fit(sim["motor"][fitted], sim["data"].labels[fitted], None, sim["frames"][fitted])


@pytest.mark.parametrize("threshold", [np.float32(4.0), np.int64(4)])
def test_a_numpy_scalar_threshold_is_accepted(sim, threshold):
    fitted = sim["fitted"]
    policy = ScenePolicy(steps=(0,), threshold=threshold, label_names=sim["data"].label_names)
    policy.fit(sim["motor"][fitted], sim["data"].labels[fitted], None, sim["frames"][fitted])
    assert policy.summary()["threshold"] == 4.0


def test_a_bool_threshold_is_refused(sim):
    fitted = sim["fitted"]
    with pytest.raises(UserError, match="threshold"):
        ScenePolicy(steps=(0,), threshold=True).fit(
            sim["motor"][fitted], sim["data"].labels[fitted], None, sim["frames"][fitted]
        )


def test_bad_data_are_user_errors(sim):
    data, fitted, motor, frames = sim["data"], sim["fitted"], sim["motor"], sim["frames"]
    names = data.label_names
    with pytest.raises(UserError, match="reads camera frames"):
        ScenePolicy(label_names=names).fit(motor[fitted], data.labels[fitted], None, None)
    with pytest.raises(UserError, match="frames must have shape"):
        ScenePolicy(label_names=names).fit(motor[fitted], data.labels[fitted], None, frames[fitted, :, :, :, 0])
    with pytest.raises(UserError, match="labelled"):
        ScenePolicy(label_names=names).fit(motor[fitted], None, None, frames[fitted])
    one_touch = np.concatenate([fitted[:1], fitted[data.labels[fitted] != data.labels[fitted[0]]]])
    with pytest.raises(UserError, match="touch has 1 demonstration"):
        ScenePolicy(label_names=names).fit(motor[one_touch], data.labels[one_touch], None, frames[one_touch])
    policy, held = sim["policy"], sim["held"]
    with pytest.raises(UserError, match="first camera frame"):
        policy.forecast(motor[held], labels=data.labels[held])
    with pytest.raises(UserError, match="pass labels"):
        policy.forecast(motor[held], frames=frames[held])
    with pytest.raises(UserError, match=r"label\(s\) \[3\] stand for no primitive"):
        policy.forecast(motor[held], labels=np.array([3, 3]), frames=frames[held])
    with pytest.raises(UserError, match="unknown primitive 'lift'"):
        policy.primitives_.resolve("lift")
