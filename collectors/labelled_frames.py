"""Labelled camera frames of the training objects: the data of the supervised features (the project's ImageNet).

Each frame shows one object of the train split, in the bin of the base task, from the wrist camera at a
random height and yaw above it; its label is the object's index in the split (899 classes: the 900 train
folders but one whose mesh is broken).  The object's pose, size and colour are random, so a classifier must
tell the objects apart by their shape.  The test split's objects (the ones every evaluation grasps) never
appear.

Each frame also carries the object's **pose relative to the camera**, a label the simulator gives for free and
one a grasping policy needs: the object's centre in the wrist's horizontal frame (``u`` along the gripper's
yaw, ``v`` across it, metres) and the wrist's height above it (``h``).  A trunk can learn it from any frame,
where the 899 shapes are hard to tell apart from 24 views each.

``object_frames(per_class, seed)`` renders the same frames for the same arguments: object ``k``'s size draws
from ``numpy.random.default_rng([seed, k])`` and its frame ``j`` from ``default_rng([seed, k, j])``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import mujoco
import numpy as np

from nsl.errors import ConfigError
from nsl.progress import progress_bar

from . import objects as objlib
from .env import EnvConfig
from .render import SceneRenderer
from .scene import build_spec
from .shifts import parse_shift
from .world import BIN_HALF, FINGER_OPEN, ObjectSpec

CAMERA_HEIGHT = (0.15, 0.30)  # wrist heights the frames are taken from (metres)
POSE_LABELS = ("u", "v", "h")  # the object's centre in the wrist's yaw frame, and the wrist's height above it


class ObjectFrames(NamedTuple):
    """Rendered frames of the train objects with both their labels."""

    images: np.ndarray  # (N, H, W, 3) uint8
    labels: np.ndarray  # (N,) int64: the object's index among the train objects
    poses: np.ndarray  # (N, 3) float32: POSE_LABELS, metres


def object_classes(classes: int | None = None) -> tuple[int, ...]:
    """The mesh ids of the first ``classes`` train objects (all 899 when None or 0): the classifier's labels."""
    ids = objlib.object_ids("train")
    if not classes:
        return ids
    if not 2 <= classes <= len(ids):
        raise ConfigError(f"classes {classes} is out of range; use 2..{len(ids)} (the train split's objects)")
    return ids[:classes]


def object_frames(
    per_class: int, seed: int, classes: int | None = None, image_size: int = 64, progress: bool = False
) -> ObjectFrames:
    """``per_class`` frames of each train object, in class order, with their classes and poses."""
    if per_class < 1:
        raise ConfigError(f"frames per class {per_class} must be at least 1")
    ids = object_classes(classes)
    size_range = EnvConfig().object_size
    base = parse_shift("base")
    renderer = SceneRenderer(image_size, image_size)
    images = np.empty((len(ids) * per_class, image_size, image_size, 3), np.uint8)
    labels = np.repeat(np.arange(len(ids), dtype=np.int64), per_class)
    poses = np.empty((len(ids) * per_class, len(POSE_LABELS)), np.float32)
    spread = BIN_HALF - 0.045
    try:
        for k, mesh_id in enumerate(progress_bar(ids, desc="render objects", unit="object", disable=not progress)):
            rng = np.random.default_rng([seed, k])
            mesh = objlib.load_mesh(mesh_id)
            scale = objlib.scale_for(mesh, rng.uniform(*size_range))
            size = (float(scale[0]), float(scale[1]), float(scale[2]))
            obj = ObjectSpec(mesh_id, size, (1.0, 1.0, 1.0, 1.0), (0.0, 0.0, 0.05), (1.0, 0.0, 0.0, 0.0))
            model = build_spec([obj], base, image_size).compile()
            data = mujoco.MjData(model)
            radius = 0.5 * float(np.linalg.norm(mesh.extents * scale))
            joint = int(model.joint("object0_joint").qposadr[0])
            geom = model.geom("object0").id
            wrist = {j: int(model.joint(j).qposadr[0]) for j in ("wrist_x", "wrist_y", "wrist_z", "wrist_yaw")}
            for j in range(per_class):
                r = np.random.default_rng([seed, k, j])
                x, y = r.uniform(-spread, spread, 2)
                q = r.normal(size=4)
                data.qpos[joint : joint + 7] = [x, y, radius, *(q / np.linalg.norm(q))]
                model.geom_rgba[geom] = [*r.uniform(0.15, 1.0, 3), 1.0]
                dx, dy = r.uniform(-0.03, 0.03, 2)
                data.qpos[wrist["wrist_x"]] = x + dx
                data.qpos[wrist["wrist_y"]] = y + dy
                height = r.uniform(*CAMERA_HEIGHT)
                yaw = r.uniform(-math.pi / 2, math.pi / 2)
                data.qpos[wrist["wrist_z"]] = height
                data.qpos[wrist["wrist_yaw"]] = yaw
                cos, sin = math.cos(yaw), math.sin(yaw)  # the object sits at (-dx, -dy) from the wrist
                poses[k * per_class + j] = (-cos * dx - sin * dy, sin * dx - cos * dy, height - radius)
                for finger in ("finger_left", "finger_right"):
                    data.qpos[int(model.joint(finger).qposadr[0])] = FINGER_OPEN
                mujoco.mj_forward(model, data)
                images[k * per_class + j] = renderer.render(model, data, "wrist")
            renderer.release(model)
    finally:
        renderer.close()
    return ObjectFrames(images, labels, poses)
