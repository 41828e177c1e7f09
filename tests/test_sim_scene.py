"""The scene, the scripted paths and the inverse kinematics."""

from __future__ import annotations

import numpy as np
import pytest

import primspace.sim
from primspace.sim import scene as scene_module
from primspace.sim.ik import solve_path
from primspace.sim.primitives import (
    PRIMITIVES,
    R_DOWN,
    SCRIPT,
    circle_radius,
    finger_geometry,
    grip_height,
    home_posture,
    primitive_index,
    script_motion,
)
from primspace.sim.scene import FINGER_MAX, JOINT_NAMES, Scene
from primspace.utils.errors import UserError


@pytest.fixture(scope="module")
def scene():
    return Scene()


def test_gl_platform_keeps_the_users_choice_and_defaults_to_a_headless_one():
    assert primspace.sim.choose_gl_platform({"MUJOCO_GL": "osmesa"}) == "osmesa"
    env: dict = {}
    assert primspace.sim.choose_gl_platform(env) in ("egl", "osmesa")
    assert env["LP_NUM_THREADS"] == "1"


def test_model_has_the_panda_joints_and_only_collision_meshes(scene):
    m = scene.model
    assert [m.joint(i).name for i in range(m.njnt)] == list(JOINT_NAMES)
    assert m.nq == 9 and m.nmesh == 10 + 1  # 10 collision meshes, the finger drawn from its collision file
    assert not m.geom_contype.any() and not m.geom_conaffinity.any()  # kinematic: nothing collides
    assert len(scene.left_finger_geoms) == len(scene.right_finger_geoms) == 13


def test_missing_robot_package_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(scene_module.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(UserError, match="pip install --no-deps gymnasium-robotics==1.4.2"):
        scene_module.franka_assets_dir()


def test_home_posture_points_down_at_the_home_tcp(scene):
    scene.set_joints(home_posture(scene))
    pos, rot = scene.tcp_pose()
    np.testing.assert_allclose(pos, SCRIPT.home_tcp, atol=1e-5)
    np.testing.assert_allclose(rot, R_DOWN, atol=1e-4)


def test_finger_geometry_is_plausible(scene):
    geo = finger_geometry(scene)
    for size in (0.035, 0.065):
        h = grip_height(size)
        # the pads meet a cube of edge s when each finger is opened by about s / 2
        assert abs(geo.grip_opening(size, h) - size / 2) < 0.002
        # closed fingers reach 1.5 - 2.5 cm ahead of the TCP, symmetric for push and pull
        assert 0.015 < geo.reach(0, 1, size, h) < 0.025
        assert geo.reach(0, 1, size, h) == pytest.approx(geo.reach(0, -1, size, h), abs=1e-6)
        assert 0.015 < geo.touch_reach(1, 1, size, h) < 0.03


@pytest.mark.parametrize("primitive", PRIMITIVES)
def test_scripts_start_at_home_are_smooth_and_track_by_ik(scene, primitive):
    x, y, size = 0.58, -0.12, 0.05
    script = script_motion(scene, primitive, x, y, size, 61)
    np.testing.assert_allclose(script.tcp[0], SCRIPT.home_tcp)
    assert script.fingers.min() >= 0 and script.fingers.max() <= FINGER_MAX
    # smooth in time: no jumps (at most 5 cm a step), and speeds change gradually
    step = np.linalg.norm(np.diff(script.tcp, axis=0), axis=1)
    assert step.max() < 0.05
    assert np.abs(np.diff(script.tcp, n=2, axis=0)).max() < 0.02
    ik = solve_path(scene, script.tcp, R_DOWN, finger_geometry(scene).home)
    assert ik.max_position_error < 1e-4 and ik.rotation_error.max() < 1e-3
    # joint curves are smooth too (no branch flips of the redundant degree of freedom)
    assert np.abs(np.diff(ik.q, axis=0)).max() < 0.2
    assert np.abs(np.diff(ik.q, n=2, axis=0)).max() < 0.06


def test_primitive_specific_geometry(scene):
    x, y, size = 0.5, 0.05, 0.04
    push = script_motion(scene, "push", x, y, size, 61)
    pull = script_motion(scene, "pull", x, y, size, 61)
    assert push.tcp[-1, 0] > x + 0.1 and pull.tcp[-1, 0] < x - 0.1
    grasp = script_motion(scene, "grasp", x, y, size, 61)
    assert grasp.fingers.max() == FINGER_MAX and grasp.fingers[-1] < size / 2 + 0.001
    for name, sign in (("circle_cw", -1), ("circle_ccw", 1)):
        circle = script_motion(scene, name, x, y, size, 61)
        phase = circle.tcp[18:58]
        rel = phase[:, :2] - [x, y]
        np.testing.assert_allclose(np.hypot(*rel.T), circle_radius(size), atol=1e-9)
        angle = np.unwrap(np.arctan2(rel[:, 1], rel[:, 0]))
        assert sign * (angle[-1] - angle[0]) == pytest.approx(2 * np.pi, abs=0.05)
    right = script_motion(scene, "touch_right", x, y, size, 61)
    assert right.tcp[25:, 1].max() < y - size / 2  # always on the right (-y) of the block


def test_primitive_names_and_indices():
    assert PRIMITIVES == ("touch", "grasp", "push", "pull", "touch_right", "circle_cw", "circle_ccw")
    assert primitive_index("circle_ccw") == 6 and primitive_index(np.int64(2)) == 2
    with pytest.raises(UserError, match="unknown primitive 'wave'"):
        primitive_index("wave")
