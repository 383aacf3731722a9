"""The MuJoCo engine of ``GraspEnv``: one episode's compiled model, its actuators, stepping and camera.

:class:`MujocoSim` turns an :class:`~.world.EpisodeSpec` into a compiled ``MjModel`` (the scene from
:func:`.scene.build_spec`, with the shift applied) and offers the few operations the task is written
in (:mod:`.env`): set the wrist's and fingers' targets, step the physics, place the wrist
kinematically, read the joints and the objects, render a camera.  The PyBullet engine
(:mod:`.sim_pybullet`) offers the same operations.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from .render import SceneRenderer  # sets MUJOCO_GL before mujoco is used
from .scene import build_spec
from .shifts import ShiftSpec
from .world import EpisodeSpec

WRIST_JOINTS = ("wrist_x", "wrist_y", "wrist_z", "wrist_yaw")
JOINTS = (*WRIST_JOINTS, "finger_left", "finger_right")
ACTUATORS = ("act_x", "act_y", "act_z", "act_yaw", "act_finger_left", "act_finger_right")


@dataclass
class _Handles:
    """Indices into the compiled model, looked up once per episode."""

    qpos: dict[str, int] = field(default_factory=dict)
    act: dict[str, int] = field(default_factory=dict)
    object_bodies: list[int] = field(default_factory=list)
    object_qpos: list[int] = field(default_factory=list)
    object_geoms: list[int] = field(default_factory=list)


class MujocoSim:
    """One MuJoCo episode at a time; the GL context (a :class:`SceneRenderer`) may be shared."""

    engine = "mujoco"

    def __init__(self, image_size: int, renderer: SceneRenderer | None = None):
        self.owns_renderer = renderer is None
        self.renderer: SceneRenderer | None = SceneRenderer(image_size, image_size) if renderer is None else renderer
        self.image_size = image_size
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self._h = _Handles()

    def build(self, episode: EpisodeSpec, shift: ShiftSpec) -> None:
        """Compile the episode's scene and place the wrist at its start pose, fingers open (no physics yet)."""
        if self.renderer is None:
            raise RuntimeError("reset() called on a closed environment; make a new one")
        if self.model is not None:
            self.renderer.release(self.model)
        objects = list(episode.objects)
        self.model = m = build_spec(objects, shift, self.image_size).compile()
        self.data = mujoco.MjData(m)
        h = self._h = _Handles()
        for j in JOINTS:
            h.qpos[j] = int(m.joint(j).qposadr[0])
        for a in ACTUATORS:
            h.act[a] = m.actuator(a).id
        h.object_bodies = [m.body(f"object{i}").id for i in range(len(objects))]
        h.object_qpos = [int(m.joint(f"object{i}_joint").qposadr[0]) for i in range(len(objects))]
        h.object_geoms = [m.geom(f"object{i}").id for i in range(len(objects))]

    @property
    def tip_below_wrist(self) -> float:
        """The lowest finger point below the wrist in this (possibly shifted) model."""
        assert self.model is not None  # build() made it
        fl = self.model.geom("finger_left")
        return -(float(fl.pos[2]) - float(fl.size[2]))

    def set_joints(self, pose: np.ndarray, fingers: float | None = None) -> None:
        """Put the wrist at ``pose`` (x, y, z, yaw) and, if given, both fingers at ``fingers``; velocities kept."""
        d, h = self.data, self._h
        assert d is not None  # build() made it
        for j, v in zip(WRIST_JOINTS, pose):
            d.qpos[h.qpos[j]] = v
        if fingers is not None:
            d.qpos[h.qpos["finger_left"]] = d.qpos[h.qpos["finger_right"]] = fingers

    def set_targets(self, pose: np.ndarray, fingers: float) -> None:
        """The position actuators' targets: the wrist's pose and each finger's distance from the centre."""
        d, h = self.data, self._h
        assert d is not None  # build() made it
        x, y, z, yaw = pose
        d.ctrl[h.act["act_x"]], d.ctrl[h.act["act_y"]], d.ctrl[h.act["act_z"]] = x, y, z
        d.ctrl[h.act["act_yaw"]] = yaw
        d.ctrl[h.act["act_finger_left"]] = d.ctrl[h.act["act_finger_right"]] = fingers

    def step(self, n: int) -> None:
        mujoco.mj_step(self.model, self.data, n)

    def place(self, pose: np.ndarray, fingers: float) -> None:
        """Move the wrist to ``pose`` kinematically (every velocity zeroed), with matching targets."""
        assert self.data is not None  # build() made it
        self.set_joints(pose)
        self.data.qvel[:] = 0.0
        self.set_targets(pose, fingers)
        mujoco.mj_forward(self.model, self.data)

    def object_tops(self) -> np.ndarray:
        """Each object's highest possible point: its centre's height plus its bounding radius."""
        assert self.model is not None and self.data is not None  # build() made them
        return self.data.xpos[self._h.object_bodies, 2] + self.model.geom_rbound[self._h.object_geoms]

    def object_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """The objects' centres (N, 3) and rotation matrices (N, 3, 3)."""
        assert self.data is not None  # build() made it
        b = self._h.object_bodies
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(-1, 3, 3)

    def joints(self) -> np.ndarray:
        """The joints' positions: wrist x, y, z, yaw, left and right finger."""
        d, h = self.data, self._h
        if d is None:
            raise RuntimeError("the environment's state was read before reset()")
        return np.array([d.qpos[h.qpos[j]] for j in JOINTS])

    def finger_offset(self) -> np.ndarray:
        """Offset of the finger mount from the wrist in the hand frame (the offset shift moves it)."""
        assert self.model is not None  # build() made it
        return np.array(self.model.body("finger_mount").pos[:2])

    def render(self, camera: str) -> np.ndarray:
        if self.renderer is None:
            raise RuntimeError("render() called on a closed environment")
        return self.renderer.render(self.model, self.data, camera)

    def close(self) -> None:
        if self.renderer is not None:
            if self.owns_renderer:
                self.renderer.close()
            elif self.model is not None:
                self.renderer.release(self.model)
            self.renderer = None
