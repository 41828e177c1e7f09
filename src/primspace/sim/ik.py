"""Inverse kinematics along a path: damped least squares on position and orientation.

For each target pose ``(p*, R*)`` of the tool centre point the solver iterates

.. math::

    e = \\begin{bmatrix} p^* - p(q) \\\\ \\log(R^* R(q)^\\top) \\end{bmatrix},\\qquad
    \\Delta q = J^\\top (J J^\\top + \\lambda^2 I)^{-1} e + (I - J^+ J)\\,k\\,(q_{home} - q)

with ``J`` the 6 x 7 site Jacobian (``mj_jacSite``); the second term moves the redundant
seventh degree of freedom towards the home posture without disturbing the pose. Each
point is iterated until both the pose error and the null-space step vanish, so the
solution is the configuration nearest the home posture (locally) that reaches the pose:
a smooth function of the pose, independent of iteration counts and of earlier samples. Each
path point is warm-started from the previous one; the first from the home posture, so a
trajectory depends on its path only (never on what the process solved before).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import primspace.sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from primspace.sim.scene import Scene  # noqa: E402

__all__ = ["IKResult", "solve_pose", "solve_path", "rotation_error"]


@dataclass
class IKResult:
    """Arm joint values along a path and how far they miss it.

    Attributes
    ----------
    q : ndarray, shape (T, 7)
        Arm joint angles (rad).
    position_error : ndarray, shape (T,)
        Distance between the TCP and its target (m).
    rotation_error : ndarray, shape (T,)
        Angle between the TCP orientation and its target (rad).
    """

    q: np.ndarray
    position_error: np.ndarray
    rotation_error: np.ndarray

    @property
    def max_position_error(self) -> float:
        return float(self.position_error.max())

    @property
    def worst_step(self) -> int:
        return int(np.argmax(self.position_error))


def rotation_error(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Axis-angle vector (3,) of ``target @ current.T`` (world frame)."""
    qt, qc, dq = np.empty(4), np.empty(4), np.empty(3)
    mujoco.mju_mat2Quat(qt, np.ascontiguousarray(target).ravel())
    mujoco.mju_mat2Quat(qc, np.ascontiguousarray(current).ravel())
    mujoco.mju_subQuat(dq, qt, qc)  # qc * quat(dq) = qt: dq in the current frame's axes
    return np.asarray(current) @ dq  # in world axes


class _Solver:
    """Reusable buffers for the iterations on one scene."""

    def __init__(self, scene: Scene, home: np.ndarray, damping: float, posture_gain: float, null_tol: float) -> None:
        self.scene = scene
        self.null_tol = null_tol
        self.home = np.asarray(home, dtype=float)
        self.damping2 = damping**2
        self.posture_gain = posture_gain
        nv = scene.model.nv
        self.jacp = np.zeros((3, nv))
        self.jacr = np.zeros((3, nv))
        lo, hi = scene.joint_range[:7].T
        margin = 1e-3
        self.lo, self.hi = lo + margin, hi - margin
        self.qt, self.qc, self.dq = np.empty(4), np.empty(4), np.empty(3)

    def solve(self, q: np.ndarray, pos: np.ndarray, rot: np.ndarray, tol: float, rot_tol: float, max_iter: int):
        s, m, d = self.scene, self.scene.model, self.scene.data
        arm, dof = s.arm_qpos, s.arm_dof
        mujoco.mju_mat2Quat(self.qt, rot.ravel())
        q = q.copy()
        for _ in range(max_iter + 1):
            d.qpos[arm] = q
            mujoco.mj_kinematics(m, d)
            err_p = pos - d.site_xpos[s.tcp]
            mujoco.mju_mat2Quat(self.qc, d.site_xmat[s.tcp])
            mujoco.mju_subQuat(self.dq, self.qt, self.qc)  # in the TCP frame's axes
            err_r = d.site_xmat[s.tcp].reshape(3, 3) @ self.dq  # in world axes, like jacr
            ep, er = float(np.linalg.norm(err_p)), float(np.linalg.norm(err_r))
            mujoco.mj_comPos(m, d)
            mujoco.mj_jacSite(m, d, self.jacp, self.jacr, s.tcp)
            jac = np.vstack([self.jacp[:, dof], self.jacr[:, dof]])
            jjt = jac @ jac.T
            # the null-space projector uses the exact pseudo-inverse (a damped one leaks
            # a little of the posture pull into the pose); the pose step is damped
            null = self.posture_gain * (self.home - q)
            null -= jac.T @ np.linalg.solve(jjt, jac @ null)
            if ep <= tol and er <= rot_tol and float(np.abs(null).max()) <= self.null_tol:
                break
            jjt[np.diag_indices(6)] += self.damping2
            step = jac.T @ np.linalg.solve(jjt, np.concatenate([err_p, err_r])) + null
            q = np.clip(q + step, self.lo, self.hi)
        return q, ep, er


def solve_path(
    scene: Scene,
    positions: np.ndarray,
    rotations: np.ndarray,
    home: np.ndarray,
    *,
    tol: float = 1e-5,
    rot_tol: float = 1e-4,
    max_iter: int = 60,
    damping: float = 1e-3,
    posture_gain: float = 1.0,
    null_tol: float = 1e-6,
) -> IKResult:
    """Joint angles that put the TCP on a path of poses.

    Parameters
    ----------
    scene : Scene
    positions : ndarray, shape (T, 3)
        TCP target positions (m, world frame).
    rotations : ndarray, shape (T, 3, 3) or (3, 3)
        TCP target orientations (one for all steps, or one per step).
    home : ndarray, shape (7,)
        Home posture: the start of the first solve and the null-space attractor.
    tol, rot_tol : float
        Stop iterating a point once within ``tol`` metres and ``rot_tol`` radians.
    max_iter : int
        Iterations per path point at most.
    damping : float
        lambda of the damped least squares (regularises near singularities).
    posture_gain : float
        k, the null-space pull towards ``home`` (1: a full Gauss-Newton step).
    null_tol : float
        Stop only once the null-space step is below this (rad): every point is then the
        pose's solution closest to ``home``, a smooth function of the pose, so a smooth
        path gives smooth joint curves whatever the iteration count.

    Returns
    -------
    IKResult
        Never raises for a miss: callers check :attr:`IKResult.position_error`.
    """
    positions = np.asarray(positions, dtype=float)
    rotations = np.asarray(rotations, dtype=float)
    if rotations.ndim == 2:
        rotations = np.broadcast_to(rotations, (len(positions), 3, 3))
    solver = _Solver(scene, home, damping, posture_gain, null_tol)
    n = len(positions)
    out = np.empty((n, 7))
    pos_err, rot_err = np.empty(n), np.empty(n)
    q = np.asarray(home, dtype=float)
    for t in range(n):
        q, pos_err[t], rot_err[t] = solver.solve(
            q, positions[t], np.ascontiguousarray(rotations[t]), tol, rot_tol, max_iter
        )
        out[t] = q
    return IKResult(out, pos_err, rot_err)


def solve_pose(scene: Scene, position, rotation, start: np.ndarray, **kwargs) -> IKResult:
    """Joint angles for one pose, starting from (and pulled towards) ``start``."""
    return solve_path(scene, np.asarray(position, float)[None], np.asarray(rotation, float), start, **kwargs)
