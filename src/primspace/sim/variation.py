"""Scenes that vary: per-sample block and table colours, light, camera pose and a distractor.

:class:`SceneVariation` says what varies and by how much; :data:`VARIATIONS` names its
levels (``none``: the standard scene; ``varied``: everything on, the ``paper-varied``
preset's). Sample ``index`` of a generation draws its scene from its own stream,
``np.random.SeedSequence([seed, VARIATION_KEY, index])`` (apart from the block jitter's
streams, so the blocks and the motions stay those of the standard scene): the same seed
gives the same scenes, and no sample's draw depends on another's. Every sample draws the
same :data:`N_UNIFORMS` uniform numbers in a fixed order whatever is switched on, so
switching one part off leaves the others' draws unchanged.

A draw is a vector of :data:`SCENE_NAMES` values (the ``scene`` array of the data file,
``scene_names`` naming its columns); :func:`apply_scene` sets them in a scene's compiled
model (materials, light, camera, the distractor's body): no new model per sample, and a
recorded row re-renders its scene. A part that does not vary records the standard
scene's value (the distractor's ``distractor_kind`` is -1 when there is none).

**Where the distractor stands.** On the robot's left, ``x`` in :data:`DISTRACTOR_X`,
``y`` in :data:`DISTRACTOR_Y` (its centre; radius at most 3 cm): in the camera's view, and
clear of the arm. Measured: with the block anywhere the table allows (``y`` up to 0.22 m,
every primitive, the smallest and largest block), the arm's geoms come no closer than
13 mm to a 3 cm cylinder centred at ``y = 0.40`` m, so from 0.41 m on the clearance is
at least 2 cm (a test checks the primitives at the paper grid's corners). The success
judge measures fingers, hand, wrist, block and table only: the distractor never counts.
"""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass, fields

import mujoco
import numpy as np

from primspace.sim.scene import HIDDEN_Z
from primspace.utils.errors import UserError

__all__ = [
    "SceneVariation",
    "VARIATIONS",
    "SCENE_NAMES",
    "VARIATION_KEY",
    "N_UNIFORMS",
    "DISTRACTOR_X",
    "DISTRACTOR_Y",
    "resolve_variation",
    "draw_scene",
    "standard_scene",
    "apply_scene",
]

#: The second entry of a scene draw's seed, "SCEN" in ASCII: it names the stream and keeps
#: it apart from the block jitter's (``[seed, index]`` and the shared ``[seed, "SHAR", ...]``).
VARIATION_KEY = 0x5343454E

#: The columns of a drawn scene (the data file's ``scene_names``): the block's hue (0..1)
#: and colour, the table's colour, the key light's unit direction and diffuse intensity,
#: the camera's offset (m) and turn (degrees; roll about the view axis, pitch about its
#: horizontal, yaw about its vertical), the distractor's centre on the table (m), kind (-1
#: none, 0 cylinder, 1 sphere), radius and height (m) and colour.
SCENE_NAMES = (
    "block_hue",
    "block_r",
    "block_g",
    "block_b",
    "table_r",
    "table_g",
    "table_b",
    "light_dir_x",
    "light_dir_y",
    "light_dir_z",
    "light_intensity",
    "camera_dx",
    "camera_dy",
    "camera_dz",
    "camera_roll",
    "camera_pitch",
    "camera_yaw",
    "distractor_x",
    "distractor_y",
    "distractor_kind",
    "distractor_radius",
    "distractor_height",
    "distractor_r",
    "distractor_g",
    "distractor_b",
)

#: Uniform numbers every sample draws (in this order: block 3, table 3, light 3, camera 6,
#: distractor 8).
N_UNIFORMS = 23

#: Where the distractor's centre may stand (m): see the module docstring.
DISTRACTOR_X = (0.28, 0.68)
DISTRACTOR_Y = (0.41, 0.46)

# The standard scene (primspace.sim.scene): red block, wooden table, the key light.
_BLOCK_RGB = (0.85, 0.05, 0.05)
_TABLE_RGB = (0.72, 0.60, 0.45)
_LIGHT_DIR = tuple(np.array([-0.2, 0.3, -1.0]) / np.linalg.norm([-0.2, 0.3, -1.0]))
_LIGHT_INTENSITY = 0.55
_RANGES = ("block_saturation", "block_value", "table_saturation", "table_value", "light_intensity")


@dataclass(frozen=True)
class SceneVariation:
    """What varies from sample to sample, and within which ranges (all off by default).

    Parameters
    ----------
    block_hue : (float, float), optional
        Hue range (HSV, 0..1; ``lo > hi`` wraps through red) of the block; None: red.
    block_saturation, block_value : (float, float)
        Its saturation and value ranges (with ``block_hue``).
    table_saturation : (float, float), optional
        Saturation range of the table (any hue); None: the wooden table.
    table_value : (float, float)
        Its value range (with ``table_saturation``).
    light_cone : float
        The key light's direction within this many degrees of the standard one (0: fixed).
    light_intensity : (float, float), optional
        Its diffuse intensity range (standard: 0.55); None: fixed.
    camera_shift : float
        The camera moves by up to this many metres along each world axis.
    camera_turn : float
        It turns by up to this many degrees about each of its axes.
    distractor : bool
        A cylinder or sphere of any colour stands on the table beside the work area.
    """

    block_hue: tuple[float, float] | None = None
    block_saturation: tuple[float, float] = (0.75, 1.0)
    block_value: tuple[float, float] = (0.6, 0.95)
    table_saturation: tuple[float, float] | None = None
    table_value: tuple[float, float] = (0.45, 0.8)
    light_cone: float = 0.0
    light_intensity: tuple[float, float] | None = None
    camera_shift: float = 0.0
    camera_turn: float = 0.0
    distractor: bool = False

    @property
    def enabled(self) -> bool:
        """Whether anything varies (else the standard scene, with no ``scene`` array in the file)."""
        return any(
            getattr(self, f.name) not in (None, 0.0, False)
            for f in fields(self)
            if f.name not in ("block_saturation", "block_value", "table_value")
        )

    def validate(self) -> SceneVariation:
        """Check every range; :class:`UserError` naming the setting. Returns self."""
        for name in _RANGES + ("block_hue",):
            value = getattr(self, name)
            if value is None:
                continue
            top = 2.0 if name == "light_intensity" else 1.0
            if len(value) != 2 or not all(0.0 <= float(v) <= top for v in value):
                raise UserError(f"scene variation {name} = {value}: must be two numbers in [0, {top:g}]")
            if name != "block_hue" and value[0] > value[1]:
                raise UserError(f"scene variation {name} = {value}: the low end is above the high end")
        for name, top in (("light_cone", 60.0), ("camera_shift", 0.1), ("camera_turn", 10.0)):
            value = getattr(self, name)
            if not (0.0 <= value <= top):
                raise UserError(f"scene variation {name} = {value}: must be in [0, {top:g}]")
        return self


#: The named levels of ``--scene-variation``: ``varied`` draws a block of any hue, a table
#: of any muted colour, the key light within 30 degrees and at 0.3-0.8 intensity, the camera
#: within 2 cm and 2 degrees, and a distractor.
VARIATIONS: dict[str, SceneVariation] = {
    "none": SceneVariation(),
    "varied": SceneVariation(
        block_hue=(0.0, 1.0),
        table_saturation=(0.0, 0.35),
        light_cone=30.0,
        light_intensity=(0.3, 0.8),
        camera_shift=0.02,
        camera_turn=2.0,
        distractor=True,
    ),
}


def resolve_variation(name: str) -> SceneVariation:
    """The :class:`SceneVariation` of a level's name (:class:`UserError` for an unknown one)."""
    if name not in VARIATIONS:
        raise UserError(f"unknown scene variation {name!r}; choose from {', '.join(VARIATIONS)}")
    return VARIATIONS[name].validate()


def _between(u: float, bounds) -> float:
    return float(bounds[0] + u * (bounds[1] - bounds[0]))


def _hue(u: float, bounds) -> float:
    lo, hi = bounds
    span = hi - lo if hi >= lo else hi + 1.0 - lo  # lo > hi wraps through red
    return float((lo + u * span) % 1.0)


def _in_cone(direction, cone_deg: float, u1: float, u2: float) -> np.ndarray:
    """A unit vector within ``cone_deg`` of ``direction``, uniform on the spherical cap."""
    d = np.asarray(direction, dtype=float)
    cos_t = 1.0 - u1 * (1.0 - math.cos(math.radians(cone_deg)))
    sin_t, phi = math.sqrt(max(0.0, 1.0 - cos_t * cos_t)), 2.0 * math.pi * u2
    a = np.cross(d, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(d, a)
    out = cos_t * d + sin_t * (math.cos(phi) * a + math.sin(phi) * b)
    return out / np.linalg.norm(out)


def standard_scene() -> np.ndarray:
    """The :data:`SCENE_NAMES` values of the standard scene (what a part that does not vary records)."""
    hue = colorsys.rgb_to_hsv(*_BLOCK_RGB)[0]
    return np.array(
        [hue, *_BLOCK_RGB, *_TABLE_RGB, *_LIGHT_DIR, _LIGHT_INTENSITY, *[0.0] * 6, 0.0, 0.0, -1.0, *[0.0] * 5]
    )


def draw_scene(variation: SceneVariation, seed: int, index: int) -> np.ndarray:
    """The scene of sample ``index``: :data:`SCENE_NAMES` values (float64) from its own stream."""
    u = np.random.default_rng(np.random.SeedSequence([int(seed), VARIATION_KEY, int(index)])).uniform(size=N_UNIFORMS)
    v = dict(zip(SCENE_NAMES, standard_scene()))
    if variation.block_hue is not None:
        hue = _hue(u[0], variation.block_hue)
        rgb = colorsys.hsv_to_rgb(
            hue, _between(u[1], variation.block_saturation), _between(u[2], variation.block_value)
        )
        v.update(block_hue=hue, block_r=rgb[0], block_g=rgb[1], block_b=rgb[2])
    if variation.table_saturation is not None:
        rgb = colorsys.hsv_to_rgb(
            u[3], _between(u[4], variation.table_saturation), _between(u[5], variation.table_value)
        )
        v.update(table_r=rgb[0], table_g=rgb[1], table_b=rgb[2])
    if variation.light_cone > 0:
        v.update(
            zip(("light_dir_x", "light_dir_y", "light_dir_z"), _in_cone(_LIGHT_DIR, variation.light_cone, *u[6:8]))
        )
    if variation.light_intensity is not None:
        v["light_intensity"] = _between(u[8], variation.light_intensity)
    for k, name in enumerate(("camera_dx", "camera_dy", "camera_dz")):
        v[name] = (2.0 * u[9 + k] - 1.0) * variation.camera_shift
    for k, name in enumerate(("camera_roll", "camera_pitch", "camera_yaw")):
        v[name] = (2.0 * u[12 + k] - 1.0) * variation.camera_turn
    if variation.distractor:
        kind = float(u[17] >= 0.5)
        radius = _between(u[18], (0.02, 0.03))
        height = 2.0 * radius if kind else _between(u[19], (0.04, 0.08))
        rgb = colorsys.hsv_to_rgb(u[20], _between(u[21], (0.5, 1.0)), _between(u[22], (0.5, 0.95)))
        v.update(distractor_x=_between(u[15], DISTRACTOR_X), distractor_y=_between(u[16], DISTRACTOR_Y))
        v.update(distractor_kind=kind, distractor_radius=radius, distractor_height=height)
        v.update(distractor_r=rgb[0], distractor_g=rgb[1], distractor_b=rgb[2])
    return np.array([v[name] for name in SCENE_NAMES], dtype=float)


def _turned(quat: np.ndarray, roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``quat`` turned in its own frame: roll about z (the view axis), pitch about x, yaw about y (degrees)."""
    out = np.array(quat, dtype=float)
    for axis, angle in (((0.0, 0.0, 1.0), roll), ((1.0, 0.0, 0.0), pitch), ((0.0, 1.0, 0.0), yaw)):
        turn, result = np.empty(4), np.empty(4)
        mujoco.mju_axisAngle2Quat(turn, np.array(axis), math.radians(angle))
        mujoco.mju_mulQuat(result, out, turn)
        out = result
    return out


def apply_scene(scene, values) -> None:
    """Set a drawn (or recorded) scene, :data:`SCENE_NAMES` values, in ``scene``'s model.

    ``scene`` is a :class:`~primspace.sim.scene.Scene` built with ``distractor=True`` (the
    distractor is placed on the table, or hidden when ``distractor_kind`` is -1). The
    camera moves relative to the compiled model's (``scene.camera_pose``).
    """
    v = dict(zip(SCENE_NAMES, np.asarray(values, dtype=float)))
    m = scene.model
    m.geom_rgba[scene.block_geom, :3] = (v["block_r"], v["block_g"], v["block_b"])
    m.geom_rgba[scene.table_geom, :3] = (v["table_r"], v["table_g"], v["table_b"])
    m.light_dir[scene.light] = (v["light_dir_x"], v["light_dir_y"], v["light_dir_z"])
    m.light_diffuse[scene.light] = v["light_intensity"]
    pos, quat = scene.camera_pose
    m.cam_pos[scene.camera] = pos + (v["camera_dx"], v["camera_dy"], v["camera_dz"])
    m.cam_quat[scene.camera] = _turned(quat, v["camera_roll"], v["camera_pitch"], v["camera_yaw"])
    g, r, h = scene.distractor_geom, v["distractor_radius"], v["distractor_height"]
    if v["distractor_kind"] < 0:
        scene.data.mocap_pos[scene.distractor_mocap] = (0.8, 0.4, HIDDEN_Z)
        return
    sphere = v["distractor_kind"] > 0
    m.geom_type[g] = mujoco.mjtGeom.mjGEOM_SPHERE if sphere else mujoco.mjtGeom.mjGEOM_CYLINDER
    m.geom_size[g] = (r, r, r) if sphere else (r, 0.5 * h, 0.0)
    m.geom_rbound[g] = r if sphere else math.hypot(r, 0.5 * h)
    m.geom_aabb[g] = (0.0, 0.0, 0.0, r, r, r if sphere else 0.5 * h)
    m.geom_rgba[g, :3] = (v["distractor_r"], v["distractor_g"], v["distractor_b"])
    scene.data.mocap_pos[scene.distractor_mocap] = (v["distractor_x"], v["distractor_y"], 0.5 * h)
