"""The bin-grasping scene, built with ``mujoco.MjSpec``.

A table with a 30 cm bin, 1-5 procedural objects, and a parallel-jaw gripper
on a visible wrist and arm link.  The gripper is driven in Cartesian space by
position actuators on three slides (x, y, z of the wrist) and a hinge (yaw);
two slide fingers close along the gripper's local x axis (7 cm apart when
open).  Two cameras: ``wrist`` rides on the wrist body, behind the palm, and
looks between the fingers at the floor below them; ``shoulder`` is fixed and
frames the whole bin.

Everything a shift or the environment reads later is named.  Grasp physics
follow what made grasps reliable in the prototype measured on this machine:
elliptic friction cones with ``impratio=10``, gravity-compensated gripper,
stiff position control, objects normalised to graspable sizes.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from .objects import load_mesh
from .shifts import ShiftSpec
from .world import (  # the engine-neutral geometry; also read from here by older code
    ARM_FROM_TO,
    ARM_RADIUS,
    ARM_RGBA,
    BIN_HALF,
    BIN_WALL_H,
    BIN_WALL_T,
    CAMERAS,
    DARK_RGBA,
    FINGER_HALF,
    FINGER_OPEN,
    FINGER_TOP,
    FLANGE_HALF_HEIGHT,
    FLANGE_RADIUS,
    FLANGE_Z,
    FLOOR_RGBA,
    MAX_OBJECTS,
    METAL_RGBA,
    OBJECT_MASS,
    PALM_HALF,
    PALM_Z,
    SHOULDER_CAM_FOVY,
    SHOULDER_CAM_POS,
    SHOULDER_CAM_TARGET,
    START_Z,
    TABLE_RGBA,
    TIMESTEP,
    WALL_RGBA,
    WORKSPACE_HALF,
    WRIST_CAM_FOVY,
    WRIST_CAM_POS,
    WRIST_CAM_TARGET,
    WRIST_HALF_HEIGHT,
    WRIST_RADIUS,
    WRIST_Z_RANGE,
    ObjectSpec,
    finger_tip_offset,
    look_at,
)

__all__ = ["CAMERAS", "ObjectSpec", "START_Z", "build_spec", "finger_tip_offset"]


def _look_at_quat(pos: np.ndarray, target: np.ndarray) -> list[float]:
    """Camera quaternion looking from pos to target with world z up."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, look_at(pos, target).flatten())
    return quat.tolist()


def build_spec(objects: list[ObjectSpec], shift: ShiftSpec, image_size: int = 64) -> mujoco.MjSpec:
    """The scene for one episode, with its shift applied (not yet compiled)."""
    spec = mujoco.MjSpec()
    spec.modelname = "nsl_bin_grasp"
    spec.compiler.degree = False  # all angles in this file are radians
    opt = spec.option
    opt.timestep = TIMESTEP
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    opt.impratio = 10.0
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.visual.global_.offwidth = max(image_size, 64)
    spec.visual.global_.offheight = max(image_size, 64)
    spec.visual.quality.shadowsize = 0
    spec.visual.quality.offsamples = 0  # no MSAA: 64x64 frames gain nothing from it
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
    spec.visual.headlight.specular = [0.05, 0.05, 0.05]

    world = spec.worldbody
    ceiling = world.add_light(name="ceiling", pos=[0.1, -0.2, 1.0], dir=[-0.1, 0.2, -1.0])
    ceiling.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    ceiling.diffuse = [0.5, 0.5, 0.5]
    ceiling.castshadow = False

    box, plane = mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_PLANE
    world.add_geom(
        name="table",
        type=box,
        size=[0.5, 0.5, 0.02],
        pos=[0, 0, -0.0205],
        rgba=list(TABLE_RGBA),
        contype=0,
        conaffinity=0,
    )
    # The bin floor is a plane: for collisions a half-space, so nothing can tunnel through it.
    spec.add_material(name="bin_floor", rgba=list(FLOOR_RGBA))
    world.add_geom(name="bin_floor", type=plane, size=[BIN_HALF, BIN_HALF, 0.01], pos=[0, 0, 0.0], material="bin_floor")
    wall = list(WALL_RGBA)
    for i, (x, y, hx, hy) in enumerate(
        [
            (BIN_HALF + BIN_WALL_T, 0, BIN_WALL_T, BIN_HALF + 2 * BIN_WALL_T),
            (-BIN_HALF - BIN_WALL_T, 0, BIN_WALL_T, BIN_HALF + 2 * BIN_WALL_T),
            (0, BIN_HALF + BIN_WALL_T, BIN_HALF, BIN_WALL_T),
            (0, -BIN_HALF - BIN_WALL_T, BIN_HALF, BIN_WALL_T),
        ]
    ):
        world.add_geom(
            name=f"bin_wall{i}", type=box, size=[hx, hy, BIN_WALL_H / 2], pos=[x, y, BIN_WALL_H / 2], rgba=wall
        )

    # Framed on the bin; the gripper leaves the top of the frame when it is high and near the back wall.
    cam_pos = np.array(SHOULDER_CAM_POS)
    world.add_camera(
        name="shoulder",
        pos=cam_pos.tolist(),
        quat=_look_at_quat(cam_pos, np.array(SHOULDER_CAM_TARGET)),
        fovy=SHOULDER_CAM_FOVY,
    )

    _add_gripper(spec, image_size)
    for i, obj in enumerate(objects):
        _add_object(spec, i, obj)
    for i in range(len(objects), MAX_OBJECTS):
        # Unused mesh slots keep every scene's asset list the same shape, so the
        # renderer can reuse one GPU context across episodes (no geom uses them).
        spec.add_mesh(
            name=f"mesh{i}",
            uservert=[0, 0, 0, 0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01],
            userface=[0, 1, 2, 0, 1, 3, 0, 2, 3, 1, 2, 3],
        )
    shift.apply(spec)
    return spec


def _add_gripper(spec: mujoco.MjSpec, image_size: int = 64) -> None:
    slide, hinge = mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_HINGE
    box, cyl, cap = mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE
    metal, dark = list(METAL_RGBA), list(DARK_RGBA)

    wrist = spec.worldbody.add_body(name="wrist", pos=[0, 0, 0], gravcomp=1.0)
    for axis_name, axis, rng in (("x", [1, 0, 0], WORKSPACE_HALF), ("y", [0, 1, 0], WORKSPACE_HALF)):
        wrist.add_joint(
            name=f"wrist_{axis_name}",
            type=slide,
            axis=axis,
            range=[-rng, rng],
            limited=True,
            armature=0.01,
            damping=5.0,
        )
    wrist.add_joint(
        name="wrist_z", type=slide, axis=[0, 0, 1], range=list(WRIST_Z_RANGE), limited=True, armature=0.01, damping=5.0
    )
    # The visible wrist and the arm link reaching back to the robot; visual only.
    wrist.add_geom(
        name="wrist_geom",
        type=cyl,
        size=[WRIST_RADIUS, WRIST_HALF_HEIGHT, 0],
        pos=[0, 0, 0.0],
        rgba=dark,
        contype=0,
        conaffinity=0,
        mass=0.4,
    )
    wrist.add_geom(
        name="arm_link",
        type=cap,
        fromto=[*ARM_FROM_TO[0], *ARM_FROM_TO[1]],
        size=[ARM_RADIUS, 0, 0],
        rgba=list(ARM_RGBA),
        contype=0,
        conaffinity=0,
        mass=0.01,
    )

    # The wrist camera rides on the wrist (it moves with x, y and z but does not turn with the yaw), behind
    # the palm and tilted forward to look between the fingers at the floor below them.  World-frame motions
    # then shift the picture the same way wherever the gripper is, and the fingers stay in view.
    cam_pos = np.array(WRIST_CAM_POS)
    wrist.add_camera(
        name="wrist", pos=cam_pos.tolist(), quat=_look_at_quat(cam_pos, np.array(WRIST_CAM_TARGET)), fovy=WRIST_CAM_FOVY
    )

    hand = wrist.add_body(name="hand", pos=[0, 0, 0], gravcomp=1.0)
    hand.add_joint(
        name="wrist_yaw",
        type=hinge,
        axis=[0, 0, 1],
        range=[-math.pi, math.pi],
        limited=True,
        armature=0.005,
        damping=0.5,
    )
    hand.add_geom(
        name="flange",
        type=cyl,
        size=[FLANGE_RADIUS, FLANGE_HALF_HEIGHT, 0],
        pos=[0, 0, FLANGE_Z],
        rgba=metal,
        mass=0.1,
        contype=0,
        conaffinity=0,
    )
    # The bracket joins the flange to the finger mount; the offset shift lengthens it.
    hand.add_geom(
        name="offset_bracket",
        type=box,
        size=[0.008, 1e-4, 0.006],
        pos=[0, 1e-4, -0.012],
        rgba=metal,
        contype=0,
        conaffinity=0,
        mass=0.01,
    )
    mount = hand.add_body(name="finger_mount", pos=[0, 0, 0], gravcomp=1.0)
    mount.add_geom(name="palm", type=box, size=list(PALM_HALF), pos=[0, 0, PALM_Z], rgba=metal, mass=0.15)
    fh = FINGER_HALF
    for side, sign in (("left", -1.0), ("right", 1.0)):
        f = mount.add_body(name=f"finger_{side}_body", pos=[0, 0, 0], gravcomp=1.0)
        f.add_joint(
            name=f"finger_{side}",
            type=slide,
            axis=[sign, 0, 0],
            range=[0.0, FINGER_OPEN],
            limited=True,
            armature=0.001,
            damping=2.0,
        )
        f.add_geom(
            name=f"finger_{side}",
            type=box,
            size=list(fh),
            pos=[0, 0, FINGER_TOP - fh[2]],
            rgba=dark,
            friction=[1.5, 0.02, 0.001],
            condim=4,
            solref=[0.02, 1.0],
            mass=0.03,
            priority=1,
        )

    def position(name: str, joint: str, kp: float, force: float) -> None:
        act = spec.add_actuator(name=name, target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=kp, dampratio=1.0)
        act.forcelimited = True
        act.forcerange = [-force, force]

    # Force limits like a real arm's: strong enough to move briskly, too weak to crush objects into the floor.
    position("act_x", "wrist_x", 3000.0, 60.0)
    position("act_y", "wrist_y", 3000.0, 60.0)
    position("act_z", "wrist_z", 3000.0, 60.0)
    position("act_yaw", "wrist_yaw", 200.0, 40.0)
    for side in ("left", "right"):
        position(f"act_finger_{side}", f"finger_{side}", 400.0, 12.0)


def _add_object(spec: mujoco.MjSpec, i: int, obj: ObjectSpec) -> None:
    mesh = load_mesh(obj.mesh_id)
    spec.add_mesh(
        name=f"mesh{i}",
        uservert=(mesh.vertices * obj.scale).flatten().tolist(),
        userface=mesh.faces.flatten().tolist(),
        maxhullvert=32,
    )
    body = spec.worldbody.add_body(name=f"object{i}", pos=list(obj.pos), quat=list(obj.quat))
    body.add_freejoint(name=f"object{i}_joint")
    body.add_geom(
        name=f"object{i}",
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=f"mesh{i}",
        rgba=list(obj.rgba),
        mass=OBJECT_MASS,
        friction=[1.0, 0.01, 0.001],
        condim=4,
    )
