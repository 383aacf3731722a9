"""The task without an engine: the world's geometry and each episode's contents, drawn from its seed.

Every physics engine builds the same world from this module: a table with a 30 cm bin, a
parallel-jaw gripper (7 cm between the fingers' centres when open) on a visible wrist, a wrist
camera and a shoulder camera at fixed poses and fields of view, and per episode 1-5 objects
(:class:`ObjectSpec`: mesh, per-axis scale, colour, pose) and a start pose of the wrist
(:class:`EpisodeSpec`).  :func:`draw_episode` is the one place an episode is drawn from its
random generator, so the same seed gives the same episode on every engine, bit for bit.  The
engines' scene builders are :mod:`.scene` (MuJoCo, with :mod:`.sim_mujoco` and :mod:`.render`)
and :mod:`.sim_pybullet` (PyBullet).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import objects as objlib

ENGINES = ("mujoco", "pybullet")  # EnvConfig.engine; the first is the default

# Geometry (metres).  The table top is z = 0.
BIN_HALF = 0.15  # inner half-width of the bin
BIN_WALL_H = 0.06
BIN_WALL_T = 0.01
FINGER_HALF = (0.006, 0.014, 0.03)  # finger box half sizes: thickness, width, length
PALM_Z = -0.035  # palm centre below the wrist
PALM_HALF = (0.035 + 0.012, 0.016, 0.008)  # palm box half sizes (it spans the open fingers)
WRIST_RADIUS, WRIST_HALF_HEIGHT = 0.022, 0.015  # the visible wrist: a cylinder at the wrist's origin
FLANGE_RADIUS, FLANGE_HALF_HEIGHT, FLANGE_Z = 0.018, 0.008, -0.022  # the flange below it, turning with the yaw
FINGER_TOP = -0.045  # where fingers attach, below the wrist
FINGER_OPEN = 0.035  # each finger's distance from centre when open (7 cm opening)
WRIST_Z_RANGE = (0.095, 0.34)  # wrist height limits
START_Z = 0.25  # wrist height at the start of an episode
WORKSPACE_HALF = 0.13  # wrist x/y limits
TIMESTEP = 0.002
MAX_OBJECTS = 5
OBJECT_MASS = 0.08  # kg

# Colours (RGBA) of the fixed parts.
TABLE_RGBA = (0.55, 0.42, 0.3, 1.0)
FLOOR_RGBA = (0.42, 0.44, 0.47, 1.0)
WALL_RGBA = (0.62, 0.64, 0.68, 1.0)
METAL_RGBA = (0.75, 0.75, 0.78, 1.0)
DARK_RGBA = (0.15, 0.15, 0.17, 1.0)
ARM_RGBA = (0.9, 0.55, 0.1, 1.0)
ARM_FROM_TO = ((0.0, 0.0, 0.015), (0.16, 0.22, 0.40))  # the arm link's axis, in the wrist frame
ARM_RADIUS = 0.022

# Cameras.  The wrist camera rides on the wrist (it moves with x, y and z but does not turn with the
# yaw), behind the palm and tilted forward to look between the fingers at the floor below them.
WRIST_CAM_POS = (0.0, -0.085, -0.05)  # wrist camera, in the wrist frame
WRIST_CAM_TARGET = (0.0, 0.0, -0.13)  # the point it looks at: the floor below the fingers at the last step
WRIST_CAM_FOVY = 65.0
# The shoulder camera is fixed and framed on the bin, so that at 64x64 an object covers tens of pixels.
SHOULDER_CAM_POS = (0.0, -0.20, 0.34)
SHOULDER_CAM_TARGET = (0.0, 0.01, 0.0)
SHOULDER_CAM_FOVY = 48.0
CAMERAS = ("wrist", "shoulder")  # EnvConfig.camera picks one


@dataclass(frozen=True)
class ObjectSpec:
    """One object of an episode: which mesh, how large, what colour, where (``quat`` is w, x, y, z)."""

    mesh_id: int
    scale: tuple[float, float, float]  # per-axis mesh scale
    rgba: tuple[float, float, float, float]
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float]


@dataclass(frozen=True)
class EpisodeSpec:
    """What an episode starts from, on any engine: its objects and the wrist's start pose (x, y, z, yaw)."""

    objects: tuple[ObjectSpec, ...]
    start: tuple[float, float, float, float]


def finger_tip_offset() -> float:
    """Distance from the wrist down to the finger tips (base gripper)."""
    return -(FINGER_TOP - 2 * FINGER_HALF[2])


def look_at(pos: np.ndarray, target: np.ndarray) -> np.ndarray:
    """A camera's rotation (columns: right, up, backward) looking from ``pos`` to ``target`` with world z up."""
    fwd = target - pos
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return np.stack([right, up, -fwd], axis=1)  # the camera looks along -z


def random_colour(rng: np.random.Generator) -> tuple[float, float, float, float]:
    h, s, v = rng.uniform(0, 1), rng.uniform(0.35, 0.9), rng.uniform(0.35, 0.95)
    i = int(h * 6) % 6
    f = h * 6 - int(h * 6)
    p, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    r, g, b = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)][i]
    return (float(r), float(g), float(b), 1.0)


def draw_objects(
    rng: np.random.Generator,
    object_ids: tuple[int, ...],
    count: tuple[int, int],
    size: tuple[float, float],
) -> list[ObjectSpec]:
    """``count[0]..count[1]`` distinct objects of ``object_ids`` of middle extent in ``size``, dropped in the bin."""
    n = int(rng.integers(count[0], count[1] + 1))
    ids = rng.choice(len(object_ids), size=n, replace=False)
    spread = BIN_HALF - 0.045
    out: list[ObjectSpec] = []
    placed: list[tuple[float, float, float]] = []  # x, y, radius of objects already placed
    for idx in ids:
        mesh = objlib.load_mesh(object_ids[int(idx)])
        extent = rng.uniform(*size)
        scale = objlib.scale_for(mesh, extent)
        radius = 0.5 * float(np.linalg.norm(mesh.extents * scale))
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        # Drop each object just above the floor where it overlaps no other object
        # (a short fall settles fast); if the bin is too crowded, stack it above.
        x, y = rng.uniform(-spread, spread, 2)
        z = radius + 0.002
        for _ in range(20):
            if all((x - px) ** 2 + (y - py) ** 2 > (radius + pr) ** 2 for px, py, pr in placed):
                break
            x, y = rng.uniform(-spread, spread, 2)
        else:
            z = radius + 0.002 + 2 * max(pr for _, _, pr in placed) * len(placed)
        placed.append((float(x), float(y), radius))
        out.append(
            ObjectSpec(
                mesh_id=object_ids[int(idx)],
                scale=(float(scale[0]), float(scale[1]), float(scale[2])),
                rgba=random_colour(rng),
                pos=(float(x), float(y), float(z)),
                quat=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
            )
        )
    return out


def draw_start(rng: np.random.Generator) -> tuple[float, float, float, float]:
    """The wrist's start pose: high above a random point near the bin centre, at a random yaw."""
    x, y, yaw = rng.uniform(-0.06, 0.06), rng.uniform(-0.06, 0.06), rng.uniform(-math.pi / 2, math.pi / 2)
    return (float(x), float(y), START_Z, float(yaw))


def draw_episode(
    rng: np.random.Generator,
    object_ids: tuple[int, ...],
    count: tuple[int, int],
    size: tuple[float, float],
) -> EpisodeSpec:
    """An episode's objects, then its start pose, drawn in that order from ``rng`` (the order is part of the task)."""
    objects = draw_objects(rng, object_ids, count, size)
    return EpisodeSpec(tuple(objects), draw_start(rng))
