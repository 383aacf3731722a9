"""The PyBullet engine of ``GraspEnv``: the same world as MuJoCo's, built, stepped and rendered by PyBullet.

:class:`PybulletSim` offers the operations of :class:`.sim_mujoco.MujocoSim` (the task is written
once, in :mod:`.env`).  Each environment owns one PyBullet client in DIRECT mode (no window, no
server) and renders with PyBullet's CPU renderer (TinyRenderer), which needs no OpenGL.

The world comes from :mod:`.world`: the bin, the gripper (a 7 cm jaw on a visible wrist and arm
link, driven in Cartesian space by position motors on three prismatic joints and a yaw hinge,
like MuJoCo's slides and actuators), the cameras' poses and fields of view, and the episode's
objects.  Each episode starts from ``resetSimulation``, so an episode is a pure function of its
seed whatever ran before it in the client (same seed, same bits).  Object meshes are parsed once
per process (:func:`.objects.load_mesh`); each episode hands PyBullet the scaled vertices, from
which it makes the convex hull that collides (as MuJoCo does) and the triangle mesh that is drawn.

A shift edits the :class:`BulletScene` before it is built, through the shift's
``engine_applies["pybullet"]`` (:class:`.shifts.ShiftDef`); a shift without one is refused when
the config is made.  Differences from MuJoCo that remain: Bullet's contact model (a
soft-constraint LCP solver with a friction pyramid, no elliptic cones), no gravity compensation
(the gripper's motors carry its weight), and one directional light in the renderer instead of
MuJoCo's headlight plus ceiling light.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nsl.errors import EnvironmentSetupError

from . import objects as objlib
from .shifts import ShiftSpec
from .world import (
    ARM_FROM_TO,
    ARM_RADIUS,
    ARM_RGBA,
    BIN_HALF,
    BIN_WALL_H,
    BIN_WALL_T,
    DARK_RGBA,
    FINGER_HALF,
    FINGER_TOP,
    FLANGE_HALF_HEIGHT,
    FLANGE_RADIUS,
    FLANGE_Z,
    FLOOR_RGBA,
    METAL_RGBA,
    OBJECT_MASS,
    PALM_HALF,
    PALM_Z,
    SHOULDER_CAM_FOVY,
    SHOULDER_CAM_POS,
    SHOULDER_CAM_TARGET,
    TABLE_RGBA,
    TIMESTEP,
    WALL_RGBA,
    WRIST_CAM_FOVY,
    WRIST_CAM_POS,
    WRIST_CAM_TARGET,
    WRIST_HALF_HEIGHT,
    WRIST_RADIUS,
    EpisodeSpec,
    look_at,
)

# The gripper's links, in the order createMultiBody gets them; the motors drive the joints of MOTOR_LINKS.
X, Y, Z, WRIST_VIS, ARM_VIS, YAW, MOUNT, LEFT, RIGHT = range(9)
MOTOR_LINKS = (X, Y, Z, YAW, LEFT, RIGHT)
# The motors' force limits, as MuJoCo's actuators (N, N m): brisk, too weak to crush an object into the floor.
MOTOR_FORCES = (60.0, 60.0, 60.0, 40.0, 12.0, 12.0)
POSITION_GAINS = (0.2, 0.2, 0.2, 0.3, 0.1, 0.1)  # Bullet's position motors: how much of the error each step removes
SOLVER_ITERATIONS = 50
NEAR, FAR = 0.01, 3.0  # the cameras' clipping planes (m)
_TEXTURES: dict[str, Path] = {}  # the PNG written for each texture image, once per process


@dataclass
class BulletScene:
    """What the PyBullet builder reads, which a shift's PyBullet apply may edit before the scene is built."""

    object_rgba: list[tuple[float, float, float, float]]
    floor_rgba: tuple[float, float, float, float] = FLOOR_RGBA
    floor_texture: np.ndarray | None = None  # an RGB image (uint8) tiled over the bin's floor, tinted by floor_rgba
    floor_texture_repeats: float = 1.0  # how many times it repeats across the floor in each direction
    object_opacity: float = 1.0  # below 1, objects are drawn in their colour blended with the floor's (no alpha here)
    # TinyRenderer's one light: the direction towards it, its colour and the shading coefficients.
    light_direction: tuple[float, float, float] = (0.1, -0.2, 1.0)
    light_colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ambient: float = 0.6
    diffuse: float = 0.45
    specular: float = 0.05
    finger_half: tuple[float, float, float] = FINGER_HALF
    finger_z: float = FINGER_TOP - FINGER_HALF[2]  # the finger boxes' centre below the wrist
    mount_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the finger mount in the hand frame
    finger_friction: float = 1.5
    object_friction: float = 1.0
    extra: dict = field(default_factory=dict)  # anything else a plugin shift wants its own builder code to read


def _quat_z_to(direction: np.ndarray) -> list[float]:
    """The quaternion (x, y, z, w) turning the z axis onto ``direction``."""
    d = direction / np.linalg.norm(direction)
    axis = np.cross([0.0, 0.0, 1.0], d)
    s = float(np.linalg.norm(axis))
    angle = math.atan2(s, float(d[2]))
    if s < 1e-12:
        return [0.0, 0.0, 0.0, 1.0]
    axis = axis / s * math.sin(angle / 2)
    return [float(axis[0]), float(axis[1]), float(axis[2]), math.cos(angle / 2)]


@contextlib.contextmanager
def _quiet_c_output():
    """Drop what PyBullet's C code prints when it is imported and connects ("pybullet build time" on stderr,
    "argv[0]=" on stdout), which would mix into a command's output and progress bars."""
    streams = [s for s in (sys.__stdout__, sys.__stderr__) if s is not None]
    saved: list[tuple[int, int]] = []
    try:
        for stream in streams:
            stream.flush()
            saved.append((stream.fileno(), os.dup(stream.fileno())))
    except (OSError, ValueError):  # no file descriptors (an embedding without them): nothing to protect
        for _, copy in saved:
            os.close(copy)
        saved = []
    try:
        with open(os.devnull, "wb") as null:
            for fd, _ in saved:
                os.dup2(null.fileno(), fd)
            yield
    finally:
        if saved:
            ctypes.CDLL(None).fflush(None)  # what C buffered goes to /dev/null, not to the restored streams
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)


def _connect():
    with _quiet_c_output():
        try:
            import pybullet
            from pybullet_utils import bullet_client
        except ImportError as e:  # pragma: no cover - pybullet is a dependency
            raise EnvironmentSetupError(
                f"pybullet is not importable ({e}); install nsl's dependencies with `make install`"
            ) from None
        try:
            return pybullet, bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
        except Exception as e:  # noqa: BLE001 - any failure to start means no engine
            raise EnvironmentSetupError(
                f"PyBullet failed to start in DIRECT mode ({e}); reinstall it "
                "(`pip install --force-reinstall pybullet`)"
            ) from None


class PybulletSim:
    """One PyBullet episode at a time, in a DIRECT client of its own."""

    engine = "pybullet"

    def __init__(self, image_size: int):
        self.pb, self.client = _connect()
        self.image_size = image_size
        self.scene: BulletScene | None = None
        self.gripper = -1
        self.bodies: list[int] = []
        self._radius: np.ndarray = np.zeros(0)
        self._view_shoulder = self.client.computeViewMatrix(
            SHOULDER_CAM_POS, SHOULDER_CAM_TARGET, self._up(SHOULDER_CAM_POS, SHOULDER_CAM_TARGET)
        )
        self._proj = {
            "wrist": self.client.computeProjectionMatrixFOV(WRIST_CAM_FOVY, 1.0, NEAR, FAR),
            "shoulder": self.client.computeProjectionMatrixFOV(SHOULDER_CAM_FOVY, 1.0, NEAR, FAR),
        }
        self._wrist_up = self._up(WRIST_CAM_POS, WRIST_CAM_TARGET)

    @staticmethod
    def _up(pos, target) -> list[float]:
        return look_at(np.array(pos, dtype=float), np.array(target, dtype=float))[:, 1].tolist()

    # -- building -----------------------------------------------------------------
    def build(self, episode: EpisodeSpec, shift: ShiftSpec) -> None:
        """Build the episode's world from scratch and place the wrist at its start pose (no physics yet)."""
        if self.client is None:
            raise RuntimeError("reset() called on a closed environment; make a new one")
        scene = BulletScene(object_rgba=[o.rgba for o in episode.objects])
        shift.apply_to("pybullet", scene)
        self.scene = scene
        c = self.client
        c.resetSimulation()
        c.setPhysicsEngineParameter(
            fixedTimeStep=TIMESTEP, numSolverIterations=SOLVER_ITERATIONS, deterministicOverlappingPairs=1
        )
        c.setGravity(0.0, 0.0, -9.81)
        self._build_bin(scene)
        self.gripper = self._build_gripper(scene)
        self.bodies = []
        radius = []
        for obj, rgba in zip(episode.objects, self._object_colours(scene)):
            mesh = objlib.load_mesh(obj.mesh_id)
            vertices = (mesh.vertices * obj.scale).tolist()
            try:
                col = c.createCollisionShape(c.GEOM_MESH, vertices=vertices)  # its convex hull, as MuJoCo collides
                vis = c.createVisualShape(
                    c.GEOM_MESH, vertices=vertices, indices=mesh.faces.flatten().tolist(), rgbaColor=list(rgba)
                )
            except self.pb.error as e:
                col = vis = -1
                why = str(e).rstrip(".")
            else:
                why = "no shape id"
            if col < 0 or vis < 0:
                raise EnvironmentSetupError(
                    f"PyBullet could not load object mesh {mesh.name} ({objlib.urdf_root() / mesh.name}: {why}); "
                    "reinstall pybullet (`pip install --force-reinstall pybullet`), whose package holds the meshes"
                )
            w, x, y, z = obj.quat
            body = c.createMultiBody(OBJECT_MASS, col, vis, list(obj.pos), [x, y, z, w])
            c.changeDynamics(
                body, -1, lateralFriction=scene.object_friction, spinningFriction=0.01, rollingFriction=0.001
            )
            self.bodies.append(body)
            radius.append(0.5 * float(np.linalg.norm(mesh.extents * np.array(obj.scale))))
        self._radius = np.array(radius)

    @staticmethod
    def _object_colours(scene: BulletScene) -> list[tuple[float, ...]]:
        """The objects' drawn colours: below full opacity, blended with the floor's mean colour."""
        a = scene.object_opacity
        if a >= 1.0:
            return list(scene.object_rgba)
        floor = np.array(scene.floor_rgba[:3])
        if scene.floor_texture is not None:
            floor = floor * scene.floor_texture.reshape(-1, 3).mean(axis=0) / 255.0
        return [(*(a * np.array(rgba[:3]) + (1.0 - a) * floor).tolist(), 1.0) for rgba in scene.object_rgba]

    def _floor_visual(self, scene: BulletScene) -> int:
        """The bin floor's visual: a flat box, or a square over which the floor texture is tiled."""
        c = self.client
        if scene.floor_texture is None:
            return c.createVisualShape(
                c.GEOM_BOX, halfExtents=[BIN_HALF, BIN_HALF, 0.0002], rgbaColor=list(scene.floor_rgba)
            )
        h, r = BIN_HALF, scene.floor_texture_repeats
        return c.createVisualShape(
            c.GEOM_MESH,
            vertices=[[-h, -h, 0.0002], [h, -h, 0.0002], [h, h, 0.0002], [-h, h, 0.0002]],
            indices=[0, 1, 2, 0, 2, 3],
            uvs=[[0, 0], [r, 0], [r, r], [0, r]],
            normals=[[0, 0, 1]] * 4,
            rgbaColor=list(scene.floor_rgba),
        )

    def _floor_texture(self, image: np.ndarray) -> int:
        """PyBullet's id of ``image`` as a texture, written once per process to a PNG that PyBullet reads."""
        import hashlib
        import tempfile

        from PIL import Image

        key = hashlib.sha256(image.tobytes() + str(image.shape).encode()).hexdigest()[:16]
        path = _TEXTURES.get(key)
        if path is None:
            folder = Path(tempfile.gettempdir()) / f"nsl-textures-{os.getpid()}"
            folder.mkdir(exist_ok=True)
            path = folder / f"{key}.png"
            tmp = path.with_name(f".{key}.tmp.png")
            Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8)).save(tmp)
            tmp.replace(path)
            _TEXTURES[key] = path
        texture = self.client.loadTexture(str(path))
        if texture < 0:
            raise EnvironmentSetupError(f"PyBullet could not load the floor texture {path}; check that it is writable")
        return texture

    def _build_bin(self, scene: BulletScene) -> None:
        c = self.client
        table = c.createVisualShape(c.GEOM_BOX, halfExtents=[0.5, 0.5, 0.02], rgbaColor=list(TABLE_RGBA))
        c.createMultiBody(0, -1, table, [0, 0, -0.0205])
        # The floor collides as a half-space (nothing can tunnel through it) and is drawn as the bin's floor.
        floor = c.createMultiBody(0, c.createCollisionShape(c.GEOM_PLANE), self._floor_visual(scene), [0, 0, 0])
        c.resetBasePositionAndOrientation(floor, [0, 0, 0], [0, 0, 0, 1])
        if scene.floor_texture is not None:
            c.changeVisualShape(floor, -1, textureUniqueId=self._floor_texture(scene.floor_texture))
        for x, y, hx, hy in (
            (BIN_HALF + BIN_WALL_T, 0, BIN_WALL_T, BIN_HALF + 2 * BIN_WALL_T),
            (-BIN_HALF - BIN_WALL_T, 0, BIN_WALL_T, BIN_HALF + 2 * BIN_WALL_T),
            (0, BIN_HALF + BIN_WALL_T, BIN_HALF, BIN_WALL_T),
            (0, -BIN_HALF - BIN_WALL_T, BIN_HALF, BIN_WALL_T),
        ):
            half = [hx, hy, BIN_WALL_H / 2]
            c.createMultiBody(
                0,
                c.createCollisionShape(c.GEOM_BOX, halfExtents=half),
                c.createVisualShape(c.GEOM_BOX, halfExtents=half, rgbaColor=list(WALL_RGBA)),
                [x, y, BIN_WALL_H / 2],
            )

    def _build_gripper(self, scene: BulletScene) -> int:
        """A fixed-base chain: x, y, z slides (the wrist, its cylinder and the arm link ride on z), the yaw hinge
        (the flange), the finger mount (the palm), and two finger slides along the hand's x axis."""
        c = self.client
        none = -1
        arm_from, arm_to = np.array(ARM_FROM_TO[0]), np.array(ARM_FROM_TO[1])
        fh = scene.finger_half
        shapes = {
            WRIST_VIS: (
                none,
                c.createVisualShape(
                    c.GEOM_CYLINDER, radius=WRIST_RADIUS, length=2 * WRIST_HALF_HEIGHT, rgbaColor=list(DARK_RGBA)
                ),
            ),
            ARM_VIS: (
                none,
                c.createVisualShape(
                    c.GEOM_CAPSULE,
                    radius=ARM_RADIUS,
                    length=float(np.linalg.norm(arm_to - arm_from)),
                    rgbaColor=list(ARM_RGBA),
                    visualFramePosition=((arm_from + arm_to) / 2).tolist(),
                    visualFrameOrientation=_quat_z_to(arm_to - arm_from),
                ),
            ),
            YAW: (none, self._flange_visual(scene)),
            MOUNT: (
                c.createCollisionShape(c.GEOM_BOX, halfExtents=list(PALM_HALF), collisionFramePosition=[0, 0, PALM_Z]),
                c.createVisualShape(
                    c.GEOM_BOX,
                    halfExtents=list(PALM_HALF),
                    rgbaColor=list(METAL_RGBA),
                    visualFramePosition=[0, 0, PALM_Z],
                ),
            ),
        }
        for side in (LEFT, RIGHT):
            shapes[side] = (
                c.createCollisionShape(c.GEOM_BOX, halfExtents=list(fh), collisionFramePosition=[0, 0, scene.finger_z]),
                c.createVisualShape(
                    c.GEOM_BOX,
                    halfExtents=list(fh),
                    rgbaColor=list(DARK_RGBA),
                    visualFramePosition=[0, 0, scene.finger_z],
                ),
            )
        masses = {
            X: 0.1,
            Y: 0.1,
            Z: 0.4,
            WRIST_VIS: 0.01,
            ARM_VIS: 0.01,
            YAW: 0.1,
            MOUNT: 0.15,
            LEFT: 0.03,
            RIGHT: 0.03,
        }
        parents = {X: 0, Y: X + 1, Z: Y + 1, WRIST_VIS: Z + 1, ARM_VIS: Z + 1, YAW: Z + 1, MOUNT: YAW + 1}
        parents |= {LEFT: MOUNT + 1, RIGHT: MOUNT + 1}
        prismatic, revolute, fixed = c.JOINT_PRISMATIC, c.JOINT_REVOLUTE, c.JOINT_FIXED
        joints = {X: prismatic, Y: prismatic, Z: prismatic, WRIST_VIS: fixed, ARM_VIS: fixed, YAW: revolute}
        joints |= {MOUNT: fixed, LEFT: prismatic, RIGHT: prismatic}
        axes = {X: [1, 0, 0], Y: [0, 1, 0], LEFT: [-1, 0, 0], RIGHT: [1, 0, 0]}
        links = range(9)
        body = c.createMultiBody(
            baseMass=0,
            basePosition=[0, 0, 0],
            linkMasses=[masses[i] for i in links],
            linkCollisionShapeIndices=[shapes.get(i, (none, none))[0] for i in links],
            linkVisualShapeIndices=[shapes.get(i, (none, none))[1] for i in links],
            linkPositions=[list(scene.mount_offset) if i == MOUNT else [0, 0, 0] for i in links],
            linkOrientations=[[0, 0, 0, 1]] * 9,
            linkInertialFramePositions=[[0, 0, 0]] * 9,
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * 9,
            linkParentIndices=[parents[i] for i in links],
            linkJointTypes=[joints[i] for i in links],
            linkJointAxis=[axes.get(i, [0, 0, 1]) for i in links],
        )
        for link in (LEFT, RIGHT):
            c.changeDynamics(body, link, lateralFriction=scene.finger_friction, spinningFriction=0.02)
        for link in links:  # no joint friction or damping beyond the motors'
            c.setJointMotorControl2(body, link, c.VELOCITY_CONTROL, force=0)
        return body

    def _flange_visual(self, scene: BulletScene) -> int:
        """The flange below the wrist, and where the finger mount is offset, the bracket that joins them."""
        c = self.client
        half = scene.mount_offset[1] / 2.0
        if abs(half) < 1e-4:
            return c.createVisualShape(
                c.GEOM_CYLINDER,
                radius=FLANGE_RADIUS,
                length=2 * FLANGE_HALF_HEIGHT,
                rgbaColor=list(METAL_RGBA),
                visualFramePosition=[0, 0, FLANGE_Z],
            )
        return c.createVisualShapeArray(
            shapeTypes=[c.GEOM_CYLINDER, c.GEOM_BOX],
            radii=[FLANGE_RADIUS, 0],
            lengths=[2 * FLANGE_HALF_HEIGHT, 0],
            halfExtents=[[0, 0, 0], [0.008, abs(half), 0.006]],
            rgbaColors=[list(METAL_RGBA)] * 2,
            visualFramePositions=[[0, 0, FLANGE_Z], [scene.mount_offset[0], half, -0.012]],
        )

    # -- the operations the task is written in ------------------------------------
    @property
    def tip_below_wrist(self) -> float:
        assert self.scene is not None  # build() made it
        return -(self.scene.finger_z - self.scene.finger_half[2])

    def set_joints(self, pose: np.ndarray, fingers: float | None = None) -> None:
        c = self.client
        for link, v in zip((X, Y, Z, YAW), pose):
            c.resetJointState(self.gripper, link, float(v))
        if fingers is not None:
            for link in (LEFT, RIGHT):
                c.resetJointState(self.gripper, link, float(fingers))

    def set_targets(self, pose: np.ndarray, fingers: float) -> None:
        x, y, z, yaw = (float(v) for v in pose)
        self.client.setJointMotorControlArray(
            self.gripper,
            list(MOTOR_LINKS),
            self.pb.POSITION_CONTROL,
            targetPositions=[x, y, z, yaw, float(fingers), float(fingers)],
            forces=list(MOTOR_FORCES),
            positionGains=list(POSITION_GAINS),
        )

    def step(self, n: int) -> None:
        for _ in range(n):
            self.client.stepSimulation()

    def place(self, pose: np.ndarray, fingers: float) -> None:
        self.set_joints(pose)  # resetJointState also zeroes the joint's velocity
        for link in (LEFT, RIGHT):
            pos = self.client.getJointState(self.gripper, link)[0]
            self.client.resetJointState(self.gripper, link, pos)
        for body in self.bodies:
            self.client.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0])
        self.set_targets(pose, fingers)

    def object_tops(self) -> np.ndarray:
        return self.object_poses()[0][:, 2] + self._radius

    def object_poses(self) -> tuple[np.ndarray, np.ndarray]:
        c = self.client
        pos, mats = [], []
        for body in self.bodies:
            p, q = c.getBasePositionAndOrientation(body)
            pos.append(p)
            mats.append(c.getMatrixFromQuaternion(q))
        return np.array(pos, dtype=np.float64), np.array(mats, dtype=np.float64).reshape(-1, 3, 3)

    def joints(self) -> np.ndarray:
        if self.gripper < 0:
            raise RuntimeError("the environment's state was read before reset()")
        states = self.client.getJointStates(self.gripper, list(MOTOR_LINKS))
        return np.array([s[0] for s in states], dtype=np.float64)

    def finger_offset(self) -> np.ndarray:
        assert self.scene is not None  # build() made it
        return np.array(self.scene.mount_offset[:2], dtype=np.float64)

    def render(self, camera: str) -> np.ndarray:
        if self.client is None:
            raise RuntimeError("render() called on a closed environment")
        assert self.scene is not None  # build() made it
        if camera == "wrist":
            x, y, z = self.joints()[:3]
            wrist = np.array([x, y, z])
            view = self.client.computeViewMatrix(
                (wrist + WRIST_CAM_POS).tolist(), (wrist + WRIST_CAM_TARGET).tolist(), self._wrist_up
            )
        else:
            view = self._view_shoulder
        s = self.scene
        n = self.image_size
        _, _, rgba, _, segmentation = self.client.getCameraImage(
            n,
            n,
            view,
            self._proj[camera],
            lightDirection=list(s.light_direction),
            lightColor=list(s.light_colour),
            lightAmbientCoeff=s.ambient,
            lightDiffuseCoeff=s.diffuse,
            lightSpecularCoeff=s.specular,
            shadow=0,
            renderer=self.pb.ER_TINY_RENDERER,
        )
        image = np.array(np.asarray(rgba, dtype=np.uint8).reshape(n, n, 4)[:, :, :3])
        image[np.asarray(segmentation).reshape(n, n) < 0] = 0  # no body there: black, as MuJoCo's background
        return image

    def close(self) -> None:
        if self.client is not None:
            self.client.disconnect()
            self.client = None


__all__ = ["BulletScene", "PybulletSim"]
