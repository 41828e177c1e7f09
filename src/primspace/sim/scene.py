"""The MuJoCo scene: a Franka Emika Panda on a table, a red block and a fixed camera.

The robot (7 arm hinge joints + 2 finger slide joints, 9 joint values) comes from the
files bundled with ``gymnasium-robotics`` (``envs/assets/kitchen_franka/franka_assets``,
Apache-2.0); they are read from the installed package (never copied) and merged into a
scene of our own. In that model joint 6's zero is shifted: ``q6 = standard q6 - pi/2``.

For speed the robot is drawn with its collision meshes (about 200 triangles a link) and
the heavy visual meshes are never loaded; nothing casts shadows. The simulator is purely
kinematic: no geom collides (``contype = conaffinity = 0``); contacts are measured on
demand by :mod:`primspace.sim.contact` with :func:`mujoco.mj_geomDistance`.

World frame: the robot base at the origin on the table top (``z = 0``), the robot faces
``+x``; "far" is ``+x``, "near" is ``-x``, the robot's right is ``-y``.

The block is a cube (edge ``size``) resting on the table, held by a mocap body so that
scripts can move it kinematically; its size is changed per sample in the compiled model.
"""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import primspace.sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from primspace.utils.errors import UserError  # noqa: E402

__all__ = [
    "Table",
    "TABLE",
    "Scene",
    "franka_assets_dir",
    "build_model",
    "ARM_JOINTS",
    "FINGER_JOINTS",
    "JOINT_NAMES",
    "FINGER_MAX",
    "CAMERA",
    "HIDDEN_Z",
]

_ASSET_SUBDIR = ("envs", "assets", "kitchen_franka", "franka_assets")

#: The model's joint names, in the order of the 9 joint values.
ARM_JOINTS = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))
FINGER_JOINTS = ("robot:panda0_finger_joint1", "robot:panda0_finger_joint2")
JOINT_NAMES = ARM_JOINTS + FINGER_JOINTS

#: Travel of each finger slide joint (m): 0 closed, 0.04 open (8 cm between the pads).
FINGER_MAX = 0.04

#: Tool centre point in the link-7 frame: the axis of the lowest fingertip capsules,
#: midway between the two fingers (the fingers are mounted at z = 0.1654 and their
#: lowest capsule axis is 0.0875 further). Its frame is the fingers' frame: local y is
#: the direction in which the fingers open, local z points out of the gripper.
TCP_POS = (0.0, 0.0, 0.1654 + 0.0875)
TCP_QUAT = (0.92388, 0.0, 0.0, -0.382683)

#: Radius of the lowest fingertip capsule: the fingertips reach this far below the TCP.
FINGERTIP_RADIUS = 0.007


@dataclass(frozen=True)
class Table:
    """The table top (``z = 0``) and where on it a block may be.

    Attributes
    ----------
    x_range, y_range : (float, float)
        The table top's extent (m); the robot base stands on it at the origin.
    block_x, block_y : (float, float)
        Where a block's centre may start: every primitive, including pushing it to the
        far side (x = 0.70) or pulling it to the near side (x = 0.32) and circling around
        it, stays within the arm's reach with the gripper pointing down (checked).
    block_size : (float, float)
        The cube edges the gripper can grasp (it opens 8 cm) and the camera can see.
    """

    x_range: tuple[float, float] = (-0.25, 0.95)
    y_range: tuple[float, float] = (-0.50, 0.50)
    block_x: tuple[float, float] = (0.38, 0.62)
    block_y: tuple[float, float] = (-0.22, 0.22)
    block_size: tuple[float, float] = (0.02, 0.065)


TABLE = Table()


@dataclass(frozen=True)
class CameraSpec:
    """The fixed camera: where it is, what it looks at, its vertical field of view (degrees).

    The default looks from the front right over the table at the work area, so the arm,
    the gripper and the block (2 to 5 pixels wide) are all in view at 64 x 48.
    """

    pos: tuple[float, float, float] = (0.95, -0.55, 0.65)
    target: tuple[float, float, float] = (0.44, 0.0, 0.15)
    fovy: float = 45.0


CAMERA = CameraSpec()

# colours (RGBA): light-grey arm, dark hand and fingers, wooden table, red block
_ARM_RGBA = "0.92 0.92 0.90 1"
_HAND_RGBA = "0.25 0.25 0.28 1"
_TABLE_RGBA = "0.72 0.60 0.45 1"
_FLOOR_RGBA = "0.30 0.33 0.38 1"
_BLOCK_RGBA = "0.85 0.05 0.05 1"

#: Height (m) at which the distractor waits out of sight, below the floor.
HIDDEN_Z = -2.0


def franka_assets_dir() -> Path:
    """The folder of Panda files inside the installed gymnasium-robotics package.

    The package is located without importing it (importing it prints a banner).

    Raises
    ------
    UserError
        If gymnasium-robotics (1.4.2) is not installed or lacks the files.
    """
    spec = importlib.util.find_spec("gymnasium_robotics")
    if spec is None or not spec.submodule_search_locations:
        raise UserError(
            "the simulator needs the Panda files of gymnasium-robotics; "
            "install them with: pip install --no-deps gymnasium-robotics==1.4.2"
        )
    folder = Path(spec.submodule_search_locations[0]).joinpath(*_ASSET_SUBDIR)
    if not (folder / "chain.xml").is_file():
        raise UserError(f"{folder}: the Panda files (chain.xml) are missing; reinstall gymnasium-robotics==1.4.2")
    return folder


def _camera_quat(pos, target) -> np.ndarray:
    """Orientation of a camera at ``pos`` looking at ``target`` with world z up."""
    pos, target = np.asarray(pos, float), np.asarray(target, float)
    back = pos - target
    back /= np.linalg.norm(back)  # camera z axis points away from the scene
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([right, up, back]).ravel())
    return quat


def _collision_meshes(asset_root: ET.Element, assets: Path) -> tuple[ET.Element, dict[str, bytes]]:
    """The ``<asset>`` of the robot's collision meshes and their files (the heavy visual
    meshes are never loaded)."""
    meshes = ET.Element("asset")
    files: dict[str, bytes] = {}
    for mesh in asset_root.find("asset").findall("mesh"):
        rel = mesh.get("file")
        if not rel.startswith("collision/"):
            continue  # the heavy visual meshes are never loaded
        name = "franka_" + rel.replace("/", "_")
        files[name] = (assets / "meshes" / rel).read_bytes()
        meshes.append(
            ET.Element(
                "mesh", name=mesh.get("name"), file=name, **({"scale": mesh.get("scale")} if mesh.get("scale") else {})
            )
        )
    return meshes, files


def _robot_body(chain_root: ET.Element) -> ET.Element:
    """The robot's body tree at the origin, its collision meshes drawn, with the TCP site."""
    robot = chain_root.find("body")
    robot.set("pos", "0 0 0")
    for body in robot.iter("body"):
        for geom in list(body.findall("geom")):
            cls, mesh = geom.get("class"), geom.get("mesh", "")
            if cls == "panda_viz" and mesh != "finger_viz":
                body.remove(geom)  # replaced by the collision mesh below
            elif cls == "panda_col":
                # the collision mesh, drawn: visible group 0, coloured, no mass
                geom.set("group", "0")
                geom.set("rgba", _HAND_RGBA if mesh == "hand_col" else _ARM_RGBA)
            elif cls == "panda_viz":
                geom.set("rgba", _HAND_RGBA)  # the finger meshes
                geom.set("mass", "0")
        if body.get("name") == "panda0_link7":
            ET.SubElement(
                body,
                "site",
                name="tcp",
                pos=" ".join(map(str, TCP_POS)),
                quat=" ".join(map(str, TCP_QUAT)),
                size="0.005",
                group="4",
            )
    return robot


def _scene_xml(assets: Path, camera: CameraSpec, distractor: bool = False) -> tuple[str, dict[str, bytes]]:
    """The scene's MJCF text and its mesh files (a MuJoCo virtual file system); with
    ``distractor``, a mocap body ``distractor`` after the robot (its geom a cylinder, out of
    sight below the floor until it is placed: :mod:`primspace.sim.variation`)."""
    asset_root = ET.parse(assets / "assets.xml").getroot()
    chain_root = ET.parse(assets / "chain.xml").getroot()
    defaults = asset_root.find("default")
    meshes, files = _collision_meshes(asset_root, assets)
    robot = _robot_body(chain_root)

    cam_quat = " ".join(f"{v:.8f}" for v in _camera_quat(camera.pos, camera.target))
    tx0, tx1 = TABLE.x_range
    ty0, ty1 = TABLE.y_range
    root = ET.Element("mujoco", model="primspace_panda_block")
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    ET.SubElement(root, "option", timestep="0.002")
    vis = ET.SubElement(root, "visual")
    ET.SubElement(vis, "global", offwidth="640", offheight="480")
    ET.SubElement(vis, "quality", shadowsize="0", offsamples="4")
    ET.SubElement(vis, "headlight", ambient="0.35 0.35 0.35", diffuse="0.45 0.45 0.45", specular="0.05 0.05 0.05")
    ET.SubElement(vis, "rgba", haze="0.3 0.33 0.38 1")
    root.append(defaults)
    root.append(meshes)
    world = ET.SubElement(root, "worldbody")
    ET.SubElement(
        world,
        "light",
        name="key",
        directional="true",
        castshadow="false",
        pos="0.5 -0.5 2",
        dir="-0.2 0.3 -1",
        diffuse="0.55 0.55 0.55",
        specular="0.1 0.1 0.1",
    )
    ET.SubElement(world, "geom", name="floor", type="plane", size="3 3 0.1", pos="0 0 -0.75", rgba=_FLOOR_RGBA)
    ET.SubElement(
        world,
        "geom",
        name="table",
        type="box",
        size=f"{(tx1 - tx0) / 2} {(ty1 - ty0) / 2} 0.02",
        pos=f"{(tx0 + tx1) / 2} {(ty0 + ty1) / 2} -0.02",
        rgba=_TABLE_RGBA,
    )
    ET.SubElement(
        world,
        "camera",
        name="front",
        pos=" ".join(map(str, camera.pos)),
        quat=cam_quat,
        fovy=str(camera.fovy),
    )
    block = ET.SubElement(world, "body", name="block", mocap="true", pos="0.5 0 0.025")
    ET.SubElement(block, "geom", name="block", type="box", size="0.025 0.025 0.025", rgba=_BLOCK_RGBA)
    world.append(robot)
    if distractor:  # after the robot: every other body and geom keeps its id
        other = ET.SubElement(world, "body", name="distractor", mocap="true", pos=f"0.8 0.4 {HIDDEN_Z}")
        ET.SubElement(other, "geom", name="distractor", type="cylinder", size="0.025 0.03", rgba="0.2 0.4 0.9 1")
    return ET.tostring(root, encoding="unicode"), files


@lru_cache(maxsize=4)
def build_model(camera: CameraSpec = CAMERA, distractor: bool = False) -> mujoco.MjModel:
    """Compile the scene (cached per process; callers copy it before changing sizes).

    ``distractor`` adds the distractor body of the scenes that vary (:mod:`primspace.sim.variation`);
    without it the model is the standard scene's."""
    xml, files = _scene_xml(franka_assets_dir(), camera, distractor)
    model = mujoco.MjModel.from_xml_string(xml, files)
    # no geom collides: the simulator is kinematic, contacts are measured on demand
    model.geom_contype[:] = 0
    model.geom_conaffinity[:] = 0
    return model


class Scene:
    """A compiled scene with its state, and the ids the other modules need.

    Parameters
    ----------
    camera : CameraSpec
        Where the camera is (the default frames arm, gripper and block at 64 x 48).
    distractor : bool
        Add the distractor body of the scenes that vary (:mod:`primspace.sim.variation`);
        its geom (``distractor_geom``, else None) is never among the judge's geoms.

    Attributes
    ----------
    model, data : mujoco.MjModel, mujoco.MjData
        A private copy of the model (the block size is changed in it) and its state.
    arm_qpos, finger_qpos : ndarray of int
        qpos addresses of the 7 arm joints and the 2 finger joints.
    tcp : int
        Site id of the tool centre point (:data:`TCP_POS`).
    light : int
        Light id of the key light (a scene that varies turns and dims it).
    camera_pose : (ndarray, ndarray)
        The compiled camera's position (3,) and quaternion (4,), from which a scene that
        varies moves the camera (:func:`primspace.sim.variation.apply_scene`).
    distractor_geom, distractor_mocap : int or None
        The distractor's geom and mocap index (None without ``distractor``).
    """

    def __init__(self, camera: CameraSpec = CAMERA, distractor: bool = False) -> None:
        self.model = build_model(camera, distractor).__copy__()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.joint_qpos = np.array([m.jnt_qposadr[m.joint(n).id] for n in JOINT_NAMES])
        self.arm_qpos = self.joint_qpos[:7]
        self.arm_dof = np.array([m.jnt_dofadr[m.joint(n).id] for n in ARM_JOINTS])
        self.joint_range = np.array([m.jnt_range[m.joint(n).id] for n in JOINT_NAMES])
        self.tcp = m.site("tcp").id
        self.block_geom = m.geom("block").id
        self.block_mocap = m.body_mocapid[m.body("block").id]
        self.table_geom = m.geom("table").id
        self.camera = m.camera("front").id
        self.left_finger_geoms = self._collision_geoms("panda0_leftfinger")
        self.right_finger_geoms = self._collision_geoms("panda0_rightfinger")
        self.hand_geoms = self._collision_geoms("panda0_link7") + self._collision_geoms("panda0_link6")
        self.block_size = float(2 * m.geom_size[self.block_geom, 0])
        self.light = m.light("key").id
        self.camera_pose = (m.cam_pos[self.camera].copy(), m.cam_quat[self.camera].copy())
        self.distractor_geom = m.geom("distractor").id if distractor else None
        self.distractor_mocap = m.body_mocapid[m.body("distractor").id] if distractor else None

    def _collision_geoms(self, body: str) -> list[int]:
        """Ids of a body's contact-relevant geoms (meshes drawn and primitive shapes)."""
        m = self.model
        bid = m.body(body).id
        ids = [g for g in range(m.ngeom) if m.geom_bodyid[g] == bid]
        if body.endswith("finger"):
            # fingers: the capsules and boxes (accurate shapes), not the drawn mesh
            return [g for g in ids if m.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH]
        return ids

    # ------------------------------------------------------------------ state
    def set_block(self, x: float, y: float, size: float, z: float | None = None) -> None:
        """Place the cube of edge ``size`` with its centre at (x, y, z); z defaults to resting on the table."""
        m, g = self.model, self.block_geom
        half = 0.5 * size
        if size != self.block_size:
            m.geom_size[g] = half
            m.geom_rbound[g] = np.sqrt(3.0) * half
            m.geom_aabb[g] = [0.0, 0.0, 0.0, half, half, half]
            self.block_size = float(size)
        self.data.mocap_pos[self.block_mocap] = (x, y, half if z is None else z)

    def set_joints(self, q: np.ndarray) -> None:
        """Set the 9 joint values and update positions (forward kinematics)."""
        self.data.qpos[self.joint_qpos] = q
        mujoco.mj_kinematics(self.model, self.data)

    def tcp_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) and rotation matrix (3, 3) of the TCP after :meth:`set_joints`."""
        return self.data.site_xpos[self.tcp].copy(), self.data.site_xmat[self.tcp].reshape(3, 3).copy()

    def tcp_path(self, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """TCP positions (T, 3) and rotations (T, 3, 3) of a joint trajectory (T, 9)."""
        joints = np.asarray(joints, dtype=float)
        pos = np.empty((len(joints), 3))
        rot = np.empty((len(joints), 3, 3))
        for t, q in enumerate(joints):
            self.set_joints(q)
            pos[t], rot[t] = self.tcp_pose()
        return pos, rot
