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

Engines (``EnvConfig.engine``): ``mujoco`` (the default) or ``pybullet``.  The
episode (objects, colours, sizes, poses, the wrist's start) is drawn from the
seed by :mod:`.world`, the same on both; this module is the task written once
for both (control, reward, observation), over an engine's few operations
(:mod:`.sim_mujoco`, :mod:`.sim_pybullet`).  On MuJoCo each episode compiles its
own MjSpec scene (objects, colours, sizes, shift), which takes a few
milliseconds, while the GL context is created once per environment.  Same
seed, same episode, bit for bit, on either engine.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from nsl import keys
from nsl.errors import ConfigError
from nsl.keys import ACTION_DIM, STATE_DIM  # noqa: F401  (re-exported by nsl.collectors)

from . import objects as objlib
from .shifts import ShiftSpec, parse_shift
from .world import (
    CAMERAS,
    ENGINES,
    FINGER_OPEN,
    WORKSPACE_HALF,
    WRIST_Z_RANGE,
    ObjectSpec,
    draw_episode,
    finger_tip_offset,
)

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
    engine: str = ENGINES[0]  # the physics engine and renderer: "mujoco" or "pybullet"

    def __post_init__(self) -> None:
        if self.engine not in ENGINES:
            raise ConfigError(f"engine {self.engine!r} is unknown; use one of {', '.join(ENGINES)}")
        named = parse_shift(self.shift)  # a shift may name its engine (engine:pybullet+...): it moves to `engine`
        if named.engine != ENGINES[0]:
            if self.engine not in (ENGINES[0], named.engine):
                raise ConfigError(
                    f"shift {self.shift!r} is on engine {named.engine!r}, but engine is {self.engine!r}; give one"
                )
            object.__setattr__(self, "engine", named.engine)
            object.__setattr__(self, "shift", named.shifts_name)
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
        self.shift_spec.require_engine(self.engine)  # validates the shift names and severities, and their engine

    @property
    def shift_spec(self) -> ShiftSpec:
        """The shifts on this config's engine (its name is the task's: ``engine:pybullet+...`` off MuJoCo)."""
        return parse_shift(self.shift, engine=self.engine)

    @property
    def steps(self) -> int:
        return self.horizon or (8 if self.control == "auto_descent" else 20)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["object_size"] = list(self.object_size)
        d["shift_spec"] = self.shift_spec.to_dict()
        d["env_version"] = ENV_VERSION
        if d["engine"] == ENGINES[0]:
            del d["engine"]  # absent means mujoco: configs (and dataset hashes) made before the option hold
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EnvConfig:
        known = {f for f in cls.__dataclass_fields__}
        kw = {k: v for k, v in d.items() if k in known}
        if "object_size" in kw:
            kw["object_size"] = tuple(kw["object_size"])
        return cls(**kw)


class GraspEnv(gym.Env):
    """Bin grasping with a parallel-jaw gripper, simulated and rendered by MuJoCo or PyBullet."""

    # One frame per control step, at the nominal control rate that datasets record (nsl.keys.FPS).
    metadata = {"render_modes": ["rgb_array"], "render_fps": keys.FPS}

    def __init__(
        self,
        config: EnvConfig | None = None,
        renderer: Any = None,
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
        self._sim = _make_sim(config, renderer)
        self._object_ids = objlib.object_ids(config.split)
        self._objects: list[ObjectSpec] = []
        self._t = 0
        self._done = True
        self._tip = finger_tip_offset()
        self._target: np.ndarray = np.zeros(4)
        self._fingers = FINGER_OPEN
        self._tip_below_wrist = self._tip

    @property
    def engine(self) -> str:
        return self.config.engine

    @property
    def model(self) -> Any:
        """MuJoCo's compiled model of this episode (None on other engines, or before reset())."""
        return getattr(self._sim, "model", None)

    @property
    def data(self) -> Any:
        """MuJoCo's ``MjData`` of this episode (None on other engines, or before reset())."""
        return getattr(self._sim, "data", None)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        c = self.config
        episode = draw_episode(self.np_random, self._object_ids, (c.min_objects, c.max_objects), c.object_size)
        self._objects = list(episode.objects)
        sim = self._sim
        sim.build(episode, self.shift)
        self._tip_below_wrist = sim.tip_below_wrist
        # Start pose: wrist high above a random point near the bin centre, fingers open.
        start = np.array(episode.start)
        self._target = start.copy()
        self._fingers = FINGER_OPEN
        sim.set_joints(start, FINGER_OPEN)
        sim.set_targets(self._target, self._fingers)
        sim.step(c.settle_steps)  # let the dropped objects settle in the bin
        self._descent = (start[2] - self._grasp_wrist_z()) / c.steps
        self._t = 0
        self._done = False
        return self._observe(), self._info(success=False)

    # -- control ----------------------------------------------------------------
    def _grasp_wrist_z(self) -> float:
        return max(WRIST_Z_RANGE[0], self._tip + self.config.grasp_clearance)

    def _move_to(self, target: np.ndarray, steps: int) -> None:
        """Drive the wrist to ``target`` over ``steps`` physics steps.

        Motion in free space, where no finger can reach any object, is
        kinematic: a stiff position controller tracks it exactly and the
        resting objects are unaffected, so the wrist is placed at the target
        without integrating physics.  Near the objects the actuator targets
        are interpolated and the physics is stepped.
        """
        sim = self._sim
        if self._free_space(self._target) and self._free_space(target):
            self._target = target.copy()
            sim.place(self._target, self._fingers)
            return
        start = self._target.copy()
        chunks = max(1, steps // 5)
        for k in range(1, chunks + 1):
            self._target = start + (target - start) * (k / chunks)
            sim.set_targets(self._target, self._fingers)
            sim.step(steps // chunks)

    def _free_space(self, pose: np.ndarray) -> bool:
        """True when the finger tips at wrist pose ``pose`` are clear above every object."""
        return bool(pose[2] - self._tip_below_wrist > self._sim.object_tops().max() + 0.02)

    def _grasp_and_lift(self, close: bool = True) -> None:
        sim = self._sim
        if close:
            for k in range(1, 6):  # close gradually so the object is centred, not flicked out
                self._fingers = FINGER_OPEN * (1 - k / 5)
                sim.set_targets(self._target, self._fingers)
                sim.step(14)
            sim.step(25)
        lift = self._target.copy()
        lift[2] = self._grasp_wrist_z() + 0.14
        self._move_to(lift, 80)
        sim.step(20)

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
                self._sim.step(15)  # settle at grasp height
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
        heights = self._sim.object_poses()[0][:, 2]
        return bool((heights > self.config.lift_threshold).any())

    def _observe(self) -> dict[str, np.ndarray]:
        return {self._image_key: self.render(), self._state_key: self.gripper_state()}

    def gripper_state(self) -> np.ndarray:
        if not self._objects:
            raise RuntimeError("gripper_state() called before reset()")
        x, y, z, yaw, left, right = self._sim.joints()
        opening = 0.5 * (left + right) / FINGER_OPEN
        z0, z1 = WRIST_Z_RANGE
        height = (z - z0) / (z1 - z0)
        x, y = x / WORKSPACE_HALF, y / WORKSPACE_HALF
        return np.clip(np.array([opening, height, x, y, math.sin(yaw), math.cos(yaw)], dtype=np.float32), -1.0, 1.0)

    def render(self) -> np.ndarray:
        return self._sim.render(self.config.camera)

    def _info(self, success: bool) -> dict[str, Any]:
        return {"success": bool(success), "step": self._t, "num_objects": len(self._objects)}

    def privileged_state(self) -> dict[str, np.ndarray]:
        """Ground truth for scripted policies: gripper pose and object poses and shapes."""
        if not self._objects:
            raise RuntimeError("privileged_state() called before reset()")
        gripper = self._sim.joints()[:4]
        pos, mats = self._sim.object_poses()
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
            "finger_offset": self._sim.finger_offset(),
        }

    @property
    def objects(self) -> list[ObjectSpec]:
        return list(self._objects)

    def close(self) -> None:
        self._sim.close()


def _make_sim(config: EnvConfig, renderer: Any) -> Any:
    """The engine's simulator; ``renderer`` (a MuJoCo ``SceneRenderer``) shares one GL context among environments."""
    if config.engine == "mujoco":
        from .sim_mujoco import MujocoSim

        n = config.image_size
        if renderer is not None and (renderer.height, renderer.width) != (n, n):
            raise ConfigError(f"shared renderer is {renderer.height}x{renderer.width} but image_size is {n}")
        return MujocoSim(n, renderer)
    if renderer is not None:
        raise ConfigError(f"a shared renderer draws MuJoCo scenes; pass renderer=None with engine {config.engine!r}")
    from .sim_pybullet import PybulletSim

    return PybulletSim(config.image_size)
