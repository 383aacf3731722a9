"""``GraspEnv``: vision-based bin grasping as a Gymnasium environment.

Observation: ``{"image": (H, W, 3) uint8, "state": float32[6]}``.  The image
comes from ``EnvConfig.camera``: by default a camera on the wrist that looks
between the fingers at the floor below them (it moves with the wrist, not
with its yaw), or the fixed over-the-shoulder view of the bin.  The state is
the robot's proprioception: gripper opening in [0, 1], wrist height in
[0, 1], wrist x and y in [-1, 1] (a fraction of the reach), and the sine and
cosine of the wrist yaw, as a real arm reports them from its encoders.
``GraspEnv(obs_type="pixels_agent_pos")`` names them as LeRobot's environments
do (gym-pusht, gym-aloha): ``{"pixels": ..., "agent_pos": ...}``, which
``lerobot.envs.utils.preprocess_observation`` turns into ``observation.image``
and ``observation.state``.

Action (QT-Opt style, each in [-1, 1]): ``(dx, dy, dz, dyaw, close, terminate)``.

Control modes:

* ``auto_descent`` (the default).  The wrist descends by a fixed amount every
  step, so after ``horizon`` steps (8) the finger tips reach grasp height; the
  policy steers x, y and yaw (``dz`` and ``close`` are ignored).  The episode
  ends with a grasp (close, then lift) at the last step, or earlier when
  ``terminate > 0`` (descend straight down and grasp).  This is the
  "height hack" of PyBullet's KukaDiverseObjectEnv and of the simulated
  QT-Opt studies: success depends on where and how the gripper is placed,
  which is visible in the image, so a learner can learn it from a few
  thousand grasps on a CPU.
* ``full``.  The policy also moves z; ``close > 0`` closes the fingers and
  lifts (a grasp attempt, episode ends), ``terminate > 0`` lifts as is.  After
  ``horizon`` steps (20) without either, the episode is truncated.

Reward is sparse: 1 if an object's centre is above ``lift_threshold`` at the
end of the episode, else 0 (also ``info["success"]``).

Each episode compiles its own MjSpec scene (objects, colours, sizes, shift);
that takes a few milliseconds, while the GL context is created once per
environment.  Same seed, same episode, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import gymnasium as gym
import mujoco  # noqa: E402,I001
import numpy as np

from nsl import keys
from nsl.errors import ConfigError
from nsl.keys import ACTION_DIM, STATE_DIM  # noqa: F401  (re-exported by nsl.collectors)

from . import objects as objlib  # noqa: E402
from .render import SceneRenderer  # sets MUJOCO_GL before mujoco is imported
from .scene import (  # noqa: E402
    BIN_HALF,
    CAMERAS,
    FINGER_OPEN,
    START_Z,
    WORKSPACE_HALF,
    WRIST_Z_RANGE,
    ObjectSpec,
    build_spec,
    finger_tip_offset,
)
from .shifts import ShiftSpec, parse_shift  # noqa: E402

ENV_VERSION = "nsl-grasp-v3"  # v2: 6-d gripper state, camera framed on the bin; v3: wrist camera, 7 cm jaw
CONTROL_MODES = ("auto_descent", "full")
# Observation key names: nsl's own (the default) or LeRobot's, as gym-pusht / gym-aloha name them.
OBS_TYPES: dict[str, tuple[str, str]] = {"image_state": ("image", "state"), "pixels_agent_pos": ("pixels", "agent_pos")}


@dataclass(frozen=True)
class EnvConfig:
    """Everything that defines the task; saved with every dataset."""

    shift: str = "base"  # shift spec, e.g. "harsh_lighting" or "harsh_lighting+checkerboard_backing@0.5"
    split: str = "train"  # object split: "train" (folders not ending in 0) or "test"
    image_size: int = 64  # square camera resolution in pixels
    camera: str = (
        "wrist"  # "wrist" (rides on the wrist, looks between the fingers) or "shoulder" (fixed, frames the bin)
    )
    control: str = "auto_descent"  # "auto_descent" or "full" (see module doc)
    horizon: int = 0  # steps per episode; 0 means the mode's default (8 auto_descent, 20 full)
    min_objects: int = 1
    max_objects: int = 5
    object_size: tuple[float, float] = (0.03, 0.055)  # range of an object's middle extent (m)
    move_step: float = 0.03  # metres of x/y (and z in full mode) per unit action
    yaw_step: float = 0.35  # radians of yaw per unit action
    substeps: int = 25  # physics steps per control step near objects (2 ms each)
    settle_steps: int = 80  # physics steps for dropped objects to come to rest before the first frame
    lift_threshold: float = 0.10  # object centre height (m) above the table that counts as lifted
    grasp_clearance: float = 0.002  # finger-tip height above the floor at the bottom of a descent (m)

    def __post_init__(self) -> None:
        if self.control not in CONTROL_MODES:
            raise ConfigError(f"control mode {self.control!r} is unknown; use one of {CONTROL_MODES}")
        if self.camera not in CAMERAS:
            raise ConfigError(f"camera {self.camera!r} is unknown; use one of {CAMERAS}")
        if not isinstance(self.image_size, int) or not 16 <= self.image_size <= 512:
            raise ConfigError(f"image_size {self.image_size!r} is out of range; use 16..512 pixels (64 is standard)")
        if not 1 <= self.min_objects <= self.max_objects <= 5:
            raise ConfigError(
                f"object count range ({self.min_objects}, {self.max_objects}) is invalid; use 1 <= min <= max <= 5"
            )
        if self.horizon < 0 or self.horizon > 20:
            raise ConfigError(f"horizon {self.horizon} is out of range; episodes last at most 20 steps (0 = default)")
        if self.split not in objlib.SPLITS:
            raise ConfigError(f"object split {self.split!r} is not one of {objlib.SPLITS}")
        if self.substeps < 1:
            raise ConfigError(f"substeps {self.substeps} must be at least 1")
        _ = self.shift_spec  # validates the shift name and severity

    @property
    def shift_spec(self) -> ShiftSpec:
        return parse_shift(self.shift)

    @property
    def steps(self) -> int:
        return self.horizon or (8 if self.control == "auto_descent" else 20)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["object_size"] = list(self.object_size)
        d["shift_spec"] = self.shift_spec.to_dict()
        d["env_version"] = ENV_VERSION
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EnvConfig:
        known = {f for f in cls.__dataclass_fields__}
        kw = {k: v for k, v in d.items() if k in known}
        if "object_size" in kw:
            kw["object_size"] = tuple(kw["object_size"])
        return cls(**kw)


def _random_colour(rng: np.random.Generator) -> tuple[float, float, float, float]:
    h, s, v = rng.uniform(0, 1), rng.uniform(0.35, 0.9), rng.uniform(0.35, 0.95)
    i = int(h * 6) % 6
    f = h * 6 - int(h * 6)
    p, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    r, g, b = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)][i]
    return (float(r), float(g), float(b), 1.0)


@dataclass
class _Handles:
    """Indices into the compiled model, looked up once per episode."""

    qpos: dict[str, int] = field(default_factory=dict)
    act: dict[str, int] = field(default_factory=dict)
    object_bodies: list[int] = field(default_factory=list)
    object_qpos: list[int] = field(default_factory=list)
    object_geoms: list[int] = field(default_factory=list)


class GraspEnv(gym.Env):
    """Bin grasping with a parallel-jaw gripper, rendered by MuJoCo."""

    # One frame per control step, at the nominal control rate that datasets record (nsl.keys.FPS).
    metadata = {"render_modes": ["rgb_array"], "render_fps": keys.FPS}

    def __init__(
        self,
        config: EnvConfig | None = None,
        renderer: SceneRenderer | None = None,
        render_mode: str | None = None,
        obs_type: str = "image_state",
        **overrides: Any,
    ):
        if config is not None and overrides:
            raise ConfigError("pass either an EnvConfig or keyword overrides, not both")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(
                f"render_mode {render_mode!r} is not supported; use one of {self.metadata['render_modes']} (or None)"
            )
        if obs_type not in OBS_TYPES:
            raise ConfigError(f"obs_type {obs_type!r} is unknown; use one of {tuple(OBS_TYPES)}")
        self.render_mode = render_mode  # render() returns the camera frame in either case
        self.obs_type = obs_type
        self._image_key, self._state_key = OBS_TYPES[obs_type]
        self.config = config = EnvConfig(**overrides) if config is None else config
        self.shift = config.shift_spec
        n = config.image_size
        self.observation_space = gym.spaces.Dict(
            {
                self._image_key: gym.spaces.Box(0, 255, (n, n, 3), np.uint8),
                self._state_key: gym.spaces.Box(-1.0, 1.0, (STATE_DIM,), np.float32),
            }
        )
        self.action_space = gym.spaces.Box(-1.0, 1.0, (ACTION_DIM,), np.float32)
        if renderer is not None and (renderer.height, renderer.width) != (n, n):
            raise ConfigError(f"shared renderer is {renderer.height}x{renderer.width} but image_size is {n}")
        self._owns_renderer = renderer is None
        self._renderer: SceneRenderer | None = SceneRenderer(n, n) if renderer is None else renderer
        self._object_ids = objlib.object_ids(config.split)
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self._objects: list[ObjectSpec] = []
        self._t = 0
        self._done = True
        self._tip = finger_tip_offset()

    # -- episode construction -------------------------------------------------
    def _sample_objects(self, rng: np.random.Generator) -> list[ObjectSpec]:
        c = self.config
        n = int(rng.integers(c.min_objects, c.max_objects + 1))
        ids = rng.choice(len(self._object_ids), size=n, replace=False)
        spread = BIN_HALF - 0.045
        out: list[ObjectSpec] = []
        placed: list[tuple[float, float, float]] = []  # x, y, radius of objects already placed
        for idx in ids:
            mesh = objlib.load_mesh(self._object_ids[int(idx)])
            size = rng.uniform(*c.object_size)
            scale = objlib.scale_for(mesh, size)
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
                    mesh_id=self._object_ids[int(idx)],
                    scale=(float(scale[0]), float(scale[1]), float(scale[2])),
                    rgba=_random_colour(rng),
                    pos=(float(x), float(y), float(z)),
                    quat=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
                )
            )
        return out

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        rng = self.np_random
        self._objects = self._sample_objects(rng)
        if self._renderer is None:
            raise RuntimeError("reset() called on a closed environment; make a new one")
        if self.model is not None:
            self._renderer.release(self.model)
        spec = build_spec(self._objects, self.shift, self.config.image_size)
        self.model = m = spec.compile()
        self.data = d = mujoco.MjData(m)
        h = self._h = _Handles()
        for j in ("wrist_x", "wrist_y", "wrist_z", "wrist_yaw", "finger_left", "finger_right"):
            h.qpos[j] = int(m.joint(j).qposadr[0])
        for a in ("act_x", "act_y", "act_z", "act_yaw", "act_finger_left", "act_finger_right"):
            h.act[a] = m.actuator(a).id
        h.object_bodies = [m.body(f"object{i}").id for i in range(len(self._objects))]
        h.object_qpos = [int(m.joint(f"object{i}_joint").qposadr[0]) for i in range(len(self._objects))]
        h.object_geoms = [m.geom(f"object{i}").id for i in range(len(self._objects))]
        # Lowest finger point below the wrist in this (possibly shifted) model.
        fl = m.geom("finger_left")
        self._tip_below_wrist = -(float(fl.pos[2]) - float(fl.size[2]))

        # Start pose: wrist high above a random point near the bin centre, fingers open.
        start = np.array(
            [rng.uniform(-0.06, 0.06), rng.uniform(-0.06, 0.06), START_Z, rng.uniform(-math.pi / 2, math.pi / 2)]
        )
        self._target = start.copy()
        self._fingers = FINGER_OPEN
        for j, v in zip(("wrist_x", "wrist_y", "wrist_z", "wrist_yaw"), start):
            d.qpos[h.qpos[j]] = v
        d.qpos[h.qpos["finger_left"]] = d.qpos[h.qpos["finger_right"]] = FINGER_OPEN
        self._apply_ctrl()
        # Let the dropped objects settle in the bin.
        mujoco.mj_step(m, d, self.config.settle_steps)
        self._descent = (start[2] - self._grasp_wrist_z()) / self.config.steps
        self._t = 0
        self._done = False
        return self._observe(), self._info(success=False)

    # -- control ----------------------------------------------------------------
    def _grasp_wrist_z(self) -> float:
        return max(WRIST_Z_RANGE[0], self._tip + self.config.grasp_clearance)

    def _apply_ctrl(self) -> None:
        d, h = self.data, self._h
        assert d is not None  # reset() built the model
        x, y, z, yaw = self._target
        d.ctrl[h.act["act_x"]], d.ctrl[h.act["act_y"]], d.ctrl[h.act["act_z"]] = x, y, z
        d.ctrl[h.act["act_yaw"]] = yaw
        d.ctrl[h.act["act_finger_left"]] = d.ctrl[h.act["act_finger_right"]] = self._fingers

    def _move_to(self, target: np.ndarray, steps: int) -> None:
        """Drive the wrist to ``target`` over ``steps`` physics steps.

        Motion in free space, where no finger can reach any object, is
        kinematic: a stiff position controller tracks it exactly and the
        resting objects are unaffected, so the wrist is placed at the target
        without integrating physics.  Near the objects the actuator targets
        are interpolated and the physics is stepped.
        """
        m, d = self.model, self.data
        assert d is not None  # reset() built the model
        if self._free_space(self._target) and self._free_space(target):
            self._target = target.copy()
            for j, v in zip(("wrist_x", "wrist_y", "wrist_z", "wrist_yaw"), target):
                d.qpos[self._h.qpos[j]] = v
            d.qvel[:] = 0.0
            self._apply_ctrl()
            mujoco.mj_forward(m, d)
            return
        start = self._target.copy()
        chunks = max(1, steps // 5)
        for k in range(1, chunks + 1):
            self._target = start + (target - start) * (k / chunks)
            self._apply_ctrl()
            mujoco.mj_step(m, d, steps // chunks)

    def _free_space(self, pose: np.ndarray) -> bool:
        """True when the finger tips at wrist pose ``pose`` are clear above every object."""
        assert self.model is not None and self.data is not None  # reset() built the model
        tops = self.data.xpos[self._h.object_bodies, 2] + self.model.geom_rbound[self._h.object_geoms]
        return bool(pose[2] - self._tip_below_wrist > tops.max() + 0.02)

    def _grasp_and_lift(self, close: bool = True) -> None:
        m, d = self.model, self.data
        if close:
            for k in range(1, 6):  # close gradually so the object is centred, not flicked out
                self._fingers = FINGER_OPEN * (1 - k / 5)
                self._apply_ctrl()
                mujoco.mj_step(m, d, 14)
            mujoco.mj_step(m, d, 25)
        lift = self._target.copy()
        lift[2] = self._grasp_wrist_z() + 0.14
        self._move_to(lift, 80)
        mujoco.mj_step(m, d, 20)

    def step(self, action: np.ndarray):
        if self._done:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        c = self.config
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(ACTION_DIM), -1.0, 1.0)
        self._t += 1
        target = self._target.copy()
        target[0] = np.clip(target[0] + a[0] * c.move_step, -WORKSPACE_HALF, WORKSPACE_HALF)
        target[1] = np.clip(target[1] + a[1] * c.move_step, -WORKSPACE_HALF, WORKSPACE_HALF)
        target[3] = np.clip(target[3] + a[3] * c.yaw_step, -math.pi, math.pi)
        terminated = truncated = False
        grasp = False
        if c.control == "auto_descent":
            last = self._t >= c.steps or a[5] > 0.0
            target[2] = self._grasp_wrist_z() if last else max(self._grasp_wrist_z(), target[2] - self._descent)
            self._move_to(target, c.substeps * (2 if last else 1))
            if last:
                mujoco.mj_step(self.model, self.data, 15)  # settle at grasp height
                self._grasp_and_lift(close=True)
                terminated = grasp = True
        else:
            target[2] = np.clip(target[2] + a[2] * c.move_step, self._grasp_wrist_z() - 0.01, WRIST_Z_RANGE[1])
            self._move_to(target, c.substeps)
            if a[4] > 0.0 or a[5] > 0.0:
                self._grasp_and_lift(close=a[4] > 0.0)
                terminated = grasp = True
            elif self._t >= c.steps:
                truncated = True
        success = grasp and self._lifted()
        self._done = terminated or truncated
        return self._observe(), float(success), terminated, truncated, self._info(success)

    # -- reading the state ------------------------------------------------------
    def _lifted(self) -> bool:
        assert self.data is not None  # reset() built the model
        heights = self.data.xpos[self._h.object_bodies, 2]
        return bool((heights > self.config.lift_threshold).any())

    def _observe(self) -> dict[str, np.ndarray]:
        return {self._image_key: self.render(), self._state_key: self.gripper_state()}

    def gripper_state(self) -> np.ndarray:
        d, h = self.data, self._h
        if d is None:
            raise RuntimeError("gripper_state() called before reset()")
        opening = 0.5 * (d.qpos[h.qpos["finger_left"]] + d.qpos[h.qpos["finger_right"]]) / FINGER_OPEN
        z0, z1 = WRIST_Z_RANGE
        height = (d.qpos[h.qpos["wrist_z"]] - z0) / (z1 - z0)
        x, y = (d.qpos[h.qpos[j]] / WORKSPACE_HALF for j in ("wrist_x", "wrist_y"))
        yaw = d.qpos[h.qpos["wrist_yaw"]]
        return np.clip(np.array([opening, height, x, y, math.sin(yaw), math.cos(yaw)], dtype=np.float32), -1.0, 1.0)

    def render(self) -> np.ndarray:
        if self._renderer is None:
            raise RuntimeError("render() called on a closed environment")
        return self._renderer.render(self.model, self.data, self.config.camera)

    def _info(self, success: bool) -> dict[str, Any]:
        return {"success": bool(success), "step": self._t, "num_objects": len(self._objects)}

    def privileged_state(self) -> dict[str, np.ndarray]:
        """Ground truth for scripted policies: gripper pose and object poses and shapes."""
        d, h = self.data, self._h
        if d is None:
            raise RuntimeError("privileged_state() called before reset()")
        gripper = np.array([d.qpos[h.qpos[j]] for j in ("wrist_x", "wrist_y", "wrist_z", "wrist_yaw")])
        pos = d.xpos[h.object_bodies].copy()
        mats = d.xmat[h.object_bodies].reshape(-1, 3, 3)
        # Each object's narrowest horizontal direction (where a parallel jaw should close).
        grasp_yaw, width = [], []
        angles = np.linspace(0, math.pi, 36, endpoint=False)
        dirs = np.stack([np.cos(angles), np.sin(angles)], 1)
        for o, R in zip(self._objects, mats):
            v = (objlib.load_mesh(o.mesh_id).vertices * o.scale) @ R.T
            proj = v[:, :2] @ dirs.T
            widths = proj.max(0) - proj.min(0)
            k = int(widths.argmin())
            grasp_yaw.append(angles[k])
            width.append(widths[k])
        return {
            "gripper": gripper,
            "object_pos": pos,
            "object_grasp_yaw": np.array(grasp_yaw),
            "object_width": np.array(width),
            "finger_offset": self._finger_offset(),
        }

    def _finger_offset(self) -> np.ndarray:
        """Offset of the finger mount from the wrist in the hand frame (the offset shift moves it)."""
        assert self.model is not None  # reset() built the model
        return np.array(self.model.body("finger_mount").pos[:2])

    @property
    def objects(self) -> list[ObjectSpec]:
        return list(self._objects)

    def close(self) -> None:
        if self._renderer is not None:
            if self._owns_renderer:
                self._renderer.close()
            elif self.model is not None:
                self._renderer.release(self.model)
            self._renderer = None
