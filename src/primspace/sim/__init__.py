"""The simulated robot-arm data set (the paper's "Artificial Data" experiment) in MuJoCo.

A Franka Emika Panda (7 arm joints + 2 finger joints), a table, a red block and a fixed
RGB camera. Seven motion primitives are scripted relative to the block, turned into joint
trajectories by inverse kinematics and rendered headless on the CPU:

- :mod:`primspace.sim.scene`      the MuJoCo model (robot files from gymnasium-robotics)
- :mod:`primspace.sim.primitives` the seven primitives, one class each (script, success
  criteria, metadata), and their registry in label order
- :mod:`primspace.sim.ik`         damped-least-squares inverse kinematics along a path
- :mod:`primspace.sim.rollout`    replay through the kinematics: block motion, contacts
- :mod:`primspace.sim.render`     the offscreen camera
- :mod:`primspace.sim.variation`  scenes that vary per sample (colours, light, camera, a distractor)
- :mod:`primspace.sim.config`     what to generate: settings, presets, each sample's block
- :mod:`primspace.sim.shards`     the shard layout of a generation into a file
- :mod:`primspace.sim.generate`   sharded parallel generation into HDF5 (or memory)
- :mod:`primspace.sim.success`    the objective success judge of a joint trajectory
- :mod:`primspace.sim.execute`    step-by-step execution with the block moved during it

Importing this package chooses the OpenGL platform before anything imports ``mujoco``:
``MUJOCO_GL`` keeps a value the user set; otherwise it is ``egl`` when libEGL can be
found, else ``osmesa`` when libOSMesa can be found, else ``egl`` (rendering then fails
with a message that says what to install). No other primspace package imports mujoco.
"""

from __future__ import annotations

import ctypes.util
import os
import sys

__all__ = ["choose_gl_platform", "MUJOCO_IMPORTED_TOO_EARLY"]

#: True when ``mujoco`` was imported before this package with ``MUJOCO_GL`` unset: its
#: OpenGL platform is then already chosen (GLFW, which needs a display) and headless
#: rendering fails; the renderer's error message says so.
MUJOCO_IMPORTED_TOO_EARLY = "mujoco" in sys.modules and "MUJOCO_GL" not in os.environ


def choose_gl_platform(environ=os.environ) -> str:
    """Set ``MUJOCO_GL`` (and ``LP_NUM_THREADS``) unless already set; return ``MUJOCO_GL``.

    Data generation runs one rendering process per core, so llvmpipe (Mesa's software
    OpenGL) is kept to one thread per process (``LP_NUM_THREADS=1``) rather than starting
    a thread per core in every process; a 64 x 48 frame renders no slower that way
    (measured, within the noise of a shared machine).
    """
    if "MUJOCO_GL" not in environ:
        if ctypes.util.find_library("EGL"):
            environ["MUJOCO_GL"] = "egl"
        elif ctypes.util.find_library("OSMesa"):
            environ["MUJOCO_GL"] = "osmesa"
        else:
            environ["MUJOCO_GL"] = "egl"
    environ.setdefault("LP_NUM_THREADS", "1")
    return environ["MUJOCO_GL"]


choose_gl_platform()
