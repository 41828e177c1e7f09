"""The fixed RGB camera: offscreen rendering on the CPU (EGL or OSMesa, Mesa llvmpipe).

Cost (measured, see docs/simulator.md): with the collision meshes drawn, no shadows,
no reflections and 4x multisampling a 64 x 48 frame takes about 1.2-1.4 ms in software
(0.5 ms without multisampling, at the price of jagged edges).
"""

from __future__ import annotations

import os

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import primspace.sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from primspace.sim.scene import Scene  # noqa: E402
from primspace.utils.errors import UserError, first_line  # noqa: E402

__all__ = ["Camera", "MAX_IMAGE_SIZE", "replay_frames"]

#: Largest (H, W) the offscreen buffer of the scene holds.
MAX_IMAGE_SIZE = (480, 640)


class Camera:
    """Render the scene's fixed camera into ``(H, W, 3)`` uint8 frames.

    Use it as a context manager (or call :meth:`close`): it owns an OpenGL context.

    Parameters
    ----------
    scene : Scene
    height, width : int
        Frame size in pixels (the paper: 48 x 64).

    Raises
    ------
    UserError
        If the size is out of range or no offscreen OpenGL context can be created.
    """

    def __init__(self, scene: Scene, height: int = 48, width: int = 64) -> None:
        if not (1 <= height <= MAX_IMAGE_SIZE[0] and 1 <= width <= MAX_IMAGE_SIZE[1]):
            raise UserError(
                f"image size {height}x{width} out of range: height 1..{MAX_IMAGE_SIZE[0]}, width 1..{MAX_IMAGE_SIZE[1]}"
            )
        self.scene = scene
        try:
            self._renderer = mujoco.Renderer(scene.model, height=height, width=width)
        except Exception as exc:  # no display library, no EGL device ...
            if primspace.sim.MUJOCO_IMPORTED_TOO_EARLY:
                hint = "mujoco was imported before primspace.sim; set MUJOCO_GL=egl in the environment"
            else:
                hint = "try MUJOCO_GL=osmesa (apt-get install libosmesa6) or generate with --no-images"
            gl = os.environ.get("MUJOCO_GL", "")
            raise UserError(f"cannot render offscreen with MUJOCO_GL={gl} ({first_line(exc)}); {hint}") from None
        flags = self._renderer.scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
        self._option = mujoco.MjvOption()
        self._option.geomgroup[:] = 0
        self._option.geomgroup[0] = 1  # drawn geoms only (finger capsules and sites are hidden)
        self._option.sitegroup[:] = 0
        self.height, self.width = height, width

    def render(self, out: np.ndarray | None = None) -> np.ndarray:
        """The current frame of the scene's state (``mj_forward`` places the camera first)."""
        scene = self.scene
        mujoco.mj_forward(scene.model, scene.data)
        self._renderer.update_scene(scene.data, camera=scene.camera, scene_option=self._option)
        return self._renderer.render(out=out)

    def close(self) -> None:
        """Release the OpenGL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> Camera:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def replay_frames(
    joints, params, primitive, height: int = 48, width: int = 64, scene: Scene | None = None, scene_values=None
) -> np.ndarray:
    """The camera's view of a joint trajectory replayed in the simulator, e.g. a
    generated motion: what :func:`primspace.sim.generate.simulate_sample` renders.

    The block moves as the success judge sees it (:func:`primspace.sim.rollout.replay`
    with the primitive's push axis and direction).

    Parameters
    ----------
    joints : array-like, shape (T, 9)
        7 arm angles (rad) and 2 finger positions (m) per step.
    params : array-like, shape (3,)
        ``block_x, block_y, block_size`` (m).
    primitive : str or int
        The primitive's name or label index (it says whether the fingers push the block).
    height, width : int
        Frame size in pixels.
    scene : Scene, optional
        A scene to reuse (building one takes ~0.7 s); a new one by default.
    scene_values : array-like, shape (S,), optional
        A sample's recorded scene (its row of a data file's ``scene`` array,
        :mod:`primspace.sim.variation`), set in the scene first, so a varied sample replays
        in its own scene; ``scene``, if given, must then be built with ``distractor=True``.

    Returns
    -------
    ndarray, shape (T, height, width, 3), uint8
    """
    from primspace.sim.primitives import get_primitive
    from primspace.sim.rollout import replay

    scene = Scene(distractor=scene_values is not None) if scene is None else scene
    if scene_values is not None:
        from primspace.sim.variation import apply_scene

        apply_scene(scene, scene_values)
    joints = np.asarray(joints, dtype=float)
    x, y, size = (float(v) for v in np.asarray(params, dtype=float).reshape(3))
    prim = get_primitive(primitive)
    rollout = replay(scene, joints, (x, y), size, prim.push_axis, prim.push_sign)
    frames = np.empty((len(joints), height, width, 3), dtype=np.uint8)
    with Camera(scene, height, width) as camera:
        for t in range(len(joints)):
            scene.set_joints(joints[t])
            scene.data.mocap_pos[scene.block_mocap] = rollout.block[t]
            camera.render(out=frames[t])
    return frames
