"""Simulated bin grasping: environment, shifts, scripted policies, collection.

Public surface (import these from ``nsl.collectors``; other folders must not
reach into the modules)::

    EnvConfig, GraspEnv, ENV_VERSION            # the task
    ENGINES                                     # EnvConfig.engine: mujoco (default) or pybullet
    SHIFT_NAMES, ShiftSpec, parse_shift, parse_shift_list   # the shift suite
    ShiftDef, register_shift, shift_names       # plugin shifts (also nsl.shifts entry points)
    STUDY_SEVERITIES, STUDY_SHIFTS              # the five at the severities calibrated to ckpt:base
    Policy, scripted_policy, register_policy    # random, oracle[:NOISE], plugins' PACKAGE.NAME[:ARGS]
    Episode, episode_seeds, run_episodes, make_envs, collect_episodes
    render_gallery                              # `nsl render`
    object_frames, object_classes, ObjectFrames # labelled frames of the train objects (supervised features)
    POSE_LABELS                                 # and their poses relative to the camera
    GYM_ID                                      # gymnasium.make(GYM_ID, shift="harsh_lighting")

The names are loaded on first use (a module-level ``__getattr__``), so
``import nsl.collectors`` does not import MuJoCo; it does choose the OpenGL
backend (``MUJOCO_GL``, default ``egl``; a value the user set is kept), which
MuJoCo reads when it is first imported (:mod:`.gl`).  Importing it registers the
task with Gymnasium as ``nsl/Grasp-v3`` through a string entry point; MuJoCo
is imported when ``gymnasium.make`` builds the environment.  (Gymnasium 1.x
has no plugin entry points; without an import, write
``gymnasium.make("nsl.collectors:nsl/Grasp-v3", ...)``, which imports it.)
"""

from __future__ import annotations

import importlib

from .gl import choose_backend

choose_backend()  # before any module of this package imports mujoco

GYM_ID = "nsl/Grasp-v3"  # the version matches ENV_VERSION ("nsl-grasp-v3"; tests/collectors/test_gym.py checks it)

_EXPORTS = {
    "env": ("ACTION_DIM", "CONTROL_MODES", "ENV_VERSION", "STATE_DIM", "EnvConfig", "GraspEnv"),
    "gallery": ("render_gallery",),
    "labelled_frames": ("POSE_LABELS", "ObjectFrames", "object_classes", "object_frames"),
    "parallel": ("collect_episodes",),
    "policies": ("Policy", "register_policy", "scripted_policy"),
    "rollout": ("Episode", "episode_seeds", "make_envs", "run_episodes"),
    "world": ("ENGINES",),
    "shifts": (
        "SHIFT_NAMES",
        "SHIFTS",
        "STUDY_SEVERITIES",
        "STUDY_SHIFTS",
        "ShiftDef",
        "ShiftSpec",
        "register_shift",
        "shift_names",
        "parse_shift",
        "parse_shift_list",
    ),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = ["GYM_ID", *_WHERE]


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later lookups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


def _register_gym() -> None:
    """Make ``gymnasium.make("nsl/Grasp-v3", shift=..., render_mode="rgb_array")`` build a GraspEnv."""
    try:
        import gymnasium
    except ImportError:  # gymnasium is a dependency; without it there is nothing to register with
        return
    if GYM_ID not in gymnasium.registry:
        gymnasium.register(id=GYM_ID, entry_point=f"{__name__}.env:GraspEnv", disable_env_checker=False)


_register_gym()
