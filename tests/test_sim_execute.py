"""Step-by-step execution in the scene with the block moved during the motion (issue 40)."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest

from primspace.sim.execute import WORKSPACE, Executor, Perturbation, check_block
from primspace.sim.ik import solve_path
from primspace.sim.primitives import PRIMITIVES, R_DOWN, finger_geometry, get_primitive, script_motion
from primspace.sim.rollout import Rollout, replay
from primspace.sim.scene import Scene
from primspace.sim.success import evaluate
from primspace.utils.errors import UserError

T = 61
SIZE = 0.05
A = (0.51, -0.02)  # where the block starts
MOVE_Y = (0.0, 0.04)  # the perturbation: 4 cm to the left (+y), B = (0.51, 0.02)
B = (A[0] + MOVE_Y[0], A[1] + MOVE_Y[1])
AT = Perturbation().step_index(T)  # 30 %: step 18


@pytest.fixture(scope="module")
def scene():
    return Scene()


@pytest.fixture(scope="module")
def motions(scene):
    """Ground-truth joints ``{(primitive, (x, y)): (T, 9)}``, solved once as the judge's tests do."""
    cache = {}

    def get(primitive, xy, size=SIZE):
        key = (primitive, tuple(xy), size)
        if key not in cache:
            script = script_motion(scene, primitive, xy[0], xy[1], size, T)
            ik = solve_path(scene, script.tcp, R_DOWN, finger_geometry(scene).home)
            assert ik.max_position_error < 0.002
            cache[key] = np.column_stack([ik.q, script.fingers, script.fingers])
        return cache[key]

    return get


def execute(scene, primitive, joints, start, moves=None, size=SIZE) -> Executor:
    ex = Executor(primitive, start[0], start[1], size, len(joints), image_size=None, scene=scene)
    ex.run(joints, moves)
    return ex


def assert_rollouts_equal(a: Rollout, b: Rollout) -> None:
    assert a.size == b.size
    for f in fields(Rollout):
        if f.name != "size":
            assert np.array_equal(getattr(a, f.name), getattr(b, f.name)), f.name


@pytest.mark.parametrize("primitive", PRIMITIVES)
def test_step_by_step_without_moves_is_the_replay(scene, motions, primitive):
    for x, y, size in ((0.51, 0.0, SIZE), (0.42, -0.15, 0.035)):
        joints = motions(primitive, (x, y), size)
        prim = get_primitive(primitive)
        expected = replay(scene, joints, (x, y), size, prim.push_axis, prim.push_sign)
        ex = Executor(primitive, x, y, size, T, image_size=None, scene=scene)
        for t, q in enumerate(joints):
            assert ex.t == t
            ex.step(q)
        got = ex.rollout()
        assert_rollouts_equal(got, expected)
        assert not got.external.any()
        assert ex.judge() == evaluate(primitive, joints, (x, y, size))


def test_a_rollout_made_without_external_has_none():
    r = Rollout(*(np.zeros((3, 3)),) * 4, 0.05, *(np.zeros((3, 2)),) * 2, np.zeros(3), np.zeros(3))
    assert r.external.dtype == bool and r.external.shape == (3,) and not r.external.any()


@pytest.mark.parametrize("primitive", PRIMITIVES)
def test_after_a_move_only_the_motion_planned_for_the_new_place_succeeds(scene, motions, primitive):
    """The block starts at A and is moved 4 cm sideways (+y) to B just before 30 % of the
    motion. The ground truth planned for A then acts at the empty place (fails); the one
    planned for B succeeds: every primitive's approach in [0, 0.30] goes to a key pose
    above the block (touch, grasp, push, pull, touch_right) or at the circle's radius on its
    near side (circles), and passes neither the old nor the new place on the way."""
    moves = {AT: MOVE_Y}
    old_plan = execute(scene, primitive, motions(primitive, A), A, moves).judge()
    assert not old_plan.success, old_plan.measures
    new_plan = execute(scene, primitive, motions(primitive, B), A, moves)
    verdict = new_plan.judge()
    assert verdict.success, verdict.reason
    assert np.allclose(new_plan.rollout().block[AT:, 1], B[1]) and np.allclose(new_plan.rollout().block[:AT, :2], A)


@pytest.mark.parametrize("primitive", ["push", "pull"])
def test_push_and_pull_planned_for_the_old_place_survive_a_move_along_x(scene, motions, primitive):
    """The push/pull target is a fixed x and the hand starts 3 cm behind the block's face:
    a block moved 2 cm along x (either way) is still pushed there from behind (not a bug)."""
    for dx in (-0.02, 0.02):
        verdict = execute(scene, primitive, motions(primitive, A), A, {AT: (dx, 0.0)}).judge()
        assert verdict.success, (dx, verdict.reason)


def test_external_marks_the_moved_step_and_push_does_not_count_it(scene, motions):
    start, dx = (B[0] - 0.03, B[1]), 0.03  # moved along the push direction, 3 cm
    ex = execute(scene, "push", motions("push", B), start, {AT: (dx, 0.0)})
    r = ex.rollout()
    assert np.array_equal(np.flatnonzero(r.external), [AT])
    assert np.diff(r.block[:, 0])[AT - 1] == pytest.approx(dx)  # the block's x jumps at that step
    verdict = ex.judge()
    assert verdict.success, verdict.reason
    # counted as the robot's push, the jump (hand 5 cm above the block) would fail "height"
    as_robot = get_primitive("push").judge(replace(r, external=np.zeros(T, bool)))
    assert not as_robot.criteria["height"]
    assert verdict.measures["height"] < as_robot.measures["height"]


def test_a_block_put_into_the_pushing_fingers_is_not_pushed_by_them(scene, motions):
    joints, k = motions("push", A), 40  # the push is under way at step 40
    ex = Executor("push", *A, SIZE, T, image_size=None, scene=scene)
    for q in joints[:k]:
        ex.step(q)
    before = ex.block
    assert before[0] > A[0]  # being pushed
    ex.move_block(-0.02, 0.0)  # towards the hand: into the fingers
    ex.step(joints[k])
    assert ex.rollout().block[k, 0] == pytest.approx(before[0] - 0.02)  # not shoved out again
    assert not ex.judge().criteria["no_penetration"]


def test_frame_shows_the_block_where_it_is(scene, motions):
    joints = motions("touch", A)
    with Executor("touch", *A, SIZE, T, scene=scene) as ex:
        with pytest.raises(UserError, match="no step"):
            ex.frame()
        ex.step(joints[0])
        first = ex.frame()
        assert first.shape == (48, 64, 3) and first.dtype == np.uint8
        assert np.array_equal(ex.frame(), first)
        ex.move_block(0.0, 0.04)
        moved = ex.frame()
    red = [(f[..., 0] > 120) & (f[..., 1] < 60) & (f[..., 2] < 60) for f in (first, moved)]
    assert red[0].sum() > 2 and red[1].sum() > 2
    centres = [np.argwhere(m).mean(axis=0) for m in red]
    assert np.abs(centres[1] - centres[0]).max() > 1.0  # the block moved in the image


def test_bad_inputs_are_user_errors_naming_the_field(scene, motions):
    with pytest.raises(UserError, match=r"block_y = 0.31 is outside the workspace -0.1625..0.1625 m"):
        Executor("push", 0.5, 0.31, SIZE, T, image_size=None, scene=scene)
    with pytest.raises(UserError, match="block_x = 0.3 is outside"):
        Executor("push", 0.3, 0.0, SIZE, T, image_size=None, scene=scene)
    with pytest.raises(UserError, match="block_size = 0.08 is outside the block sizes"):
        Executor("push", 0.5, 0.0, 0.08, T, image_size=None, scene=scene)
    with pytest.raises(UserError, match="block_x = nan"):
        check_block(float("nan"), 0.0, SIZE)
    with pytest.raises(UserError, match="unknown primitive 'shove'; choose from touch, grasp, push"):
        Executor("shove", 0.5, 0.0, SIZE, T, image_size=None, scene=scene)
    with pytest.raises(UserError, match="steps"):
        Executor("push", 0.5, 0.0, SIZE, 1, image_size=None, scene=scene)
    ex = Executor("touch", 0.5, 0.15, SIZE, 2, image_size=None, scene=scene)
    with pytest.raises(UserError, match=r"moving the block by .* block_y = 0.19 is outside the workspace"):
        ex.move_block(0.0, 0.04)
    assert np.allclose(ex.block[:2], (0.5, 0.15))  # refused, not clipped
    with pytest.raises(UserError, match="9 finite values"):
        ex.step(np.zeros(7))
    with pytest.raises(UserError, match="frames"):
        ex.frame()
    joints = motions("touch", (0.5, 0.15))
    ex.step(joints[0])
    ex.step(joints[-1])
    with pytest.raises(UserError, match="all 2 steps"):
        ex.step(joints[-1])
    with pytest.raises(UserError, match="all 2 steps"):
        ex.move_block(0.01, 0.0)


def test_perturbation_is_seeded_and_stays_in_the_workspace():
    p = Perturbation()
    assert p.step_index(61) == 18 and Perturbation(at=1.0).step_index(61) == 60
    draw = p.draw(np.random.default_rng(7), 0.51, 0.0, SIZE)
    assert draw == p.draw(np.random.default_rng(7), 0.51, 0.0, SIZE)
    assert draw != p.draw(np.random.default_rng(8), 0.51, 0.0, SIZE)
    rng = np.random.default_rng(0)
    (xlo, xhi), (ylo, yhi) = WORKSPACE["block_x"], WORKSPACE["block_y"]
    angles = []
    for x, y in [(0.51, 0.0), (xlo, ylo), (xhi, yhi), (0.42, 0.15)] * 50:
        at, dx, dy = p.draw(rng, x, y, SIZE)
        assert at == 0.3
        assert 0.02 - 1e-12 <= np.hypot(dx, dy) <= 0.04 + 1e-12
        check_block(x + dx, y + dy, SIZE)
        angles.append(np.arctan2(dy, dx))
    # a corner allows only a quarter of the directions; the centre all of them
    assert np.ptp(angles) > 5.0
    # nowhere to go that far (a workspace 19.5 cm wide): shortened to its edge
    at, dx, dy = Perturbation(distance=(0.5, 0.6)).draw(np.random.default_rng(1), 0.51, 0.0, SIZE)
    check_block(0.51 + dx, dy, SIZE)
    assert 0 < np.hypot(dx, dy) < 0.5
    for bad in (dict(at=1.5), dict(distance=(0.04, 0.02)), dict(distance=(-0.01, 0.02))):
        with pytest.raises(UserError):
            Perturbation(**bad)
    with pytest.raises(UserError, match="block_x"):
        p.draw(rng, 0.7, 0.0, SIZE)
