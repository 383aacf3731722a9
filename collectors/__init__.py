"""Simulated bin grasping: environment, shifts, scripted policies, collection.

Public surface (import these from ``nsl.collectors``; other folders must not
reach into the modules)::

    EnvConfig, GraspEnv, ENV_VERSION            # the task
    SHIFT_NAMES, ShiftSpec, parse_shift, parse_shift_list   # the shift suite
    Policy, scripted_policy                     # random, oracle[:NOISE]
    Episode, episode_seeds, run_episodes, make_envs, collect_episodes
    render_gallery                              # `nsl render`
"""

from .env import ACTION_DIM, CONTROL_MODES, ENV_VERSION, STATE_DIM, EnvConfig, GraspEnv
from .gallery import render_gallery
from .parallel import collect_episodes
from .policies import Policy, scripted_policy
from .rollout import Episode, episode_seeds, make_envs, run_episodes
from .shifts import SHIFT_NAMES, SHIFTS, ShiftSpec, parse_shift, parse_shift_list

__all__ = [
    "ACTION_DIM", "CONTROL_MODES", "ENV_VERSION", "STATE_DIM", "EnvConfig", "GraspEnv", "render_gallery",
    "collect_episodes", "Policy", "scripted_policy", "Episode", "episode_seeds", "make_envs", "run_episodes",
    "SHIFT_NAMES", "SHIFTS", "ShiftSpec", "parse_shift", "parse_shift_list",
]
