"""The task as a registered Gymnasium environment: ``gymnasium.make("nsl/Grasp-v3", shift=...)``."""

from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import nsl.collectors
from nsl.collectors import ENV_VERSION, GYM_ID, SHIFT_NAMES, GraspEnv
from nsl.errors import ConfigError

TASKS = list(SHIFT_NAMES)  # the base task and the five shifts


def test_gym_id_matches_the_environment_version():
    assert GYM_ID == "nsl/Grasp-" + ENV_VERSION.rsplit("-", 1)[1]
    assert len(TASKS) == 6 and TASKS[0] == "base"


def test_registration_does_not_import_mujoco():
    code = (
        "import sys, gymnasium, nsl.collectors\n"
        f"assert {GYM_ID!r} in gymnasium.registry\n"
        "print(sorted(m for m in ('mujoco', 'torch') if m in sys.modules))\n"
        f"env = gymnasium.make({GYM_ID!r}, shift='offset_gripper', render_mode='rgb_array')\n"
        "assert 'mujoco' in sys.modules and env.unwrapped.config.shift == 'offset_gripper'"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_make_imports_nsl_collectors_itself():
    code = (
        "import gymnasium\n"
        f"env = gymnasium.make('nsl.collectors:{GYM_ID}', shift='transparent_objects')\n"
        "obs, _ = env.reset(seed=1)\n"
        "print(env.spec.id, env.unwrapped.config.shift, obs['image'].shape)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [GYM_ID, "transparent_objects", "(64,", "64,", "3)"]


@pytest.mark.parametrize("shift", TASKS)
def test_env_checker_passes(shift):
    env = gymnasium.make(GYM_ID, shift=shift, render_mode="rgb_array")
    try:
        assert isinstance(env.unwrapped, GraspEnv) and env.unwrapped.config.shift == shift
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # the checker reports problems as warnings: any one fails the test
            check_env(env.unwrapped, skip_render_check=False)
        obs, _ = env.reset(seed=3)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.shape == env.observation_space["image"].shape
        np.testing.assert_array_equal(frame, obs["image"])
    finally:
        env.close()


def test_unsupported_render_mode_is_refused():
    with pytest.raises(ConfigError, match="render_mode 'human'"):
        GraspEnv(render_mode="human")
    assert nsl.collectors.GYM_ID in gymnasium.registry


def test_lerobot_observation_keys_through_gym_make_and_preprocess_observation():
    from lerobot.envs.utils import preprocess_observation

    env = gymnasium.make(GYM_ID, obs_type="pixels_agent_pos")
    try:
        assert set(env.observation_space.spaces) == {"pixels", "agent_pos"}
        obs, _ = env.reset(seed=5)
        assert set(obs) == {"pixels", "agent_pos"} and env.observation_space.contains(obs)
        batched = {k: np.stack([v, v]) for k, v in obs.items()}  # as LeRobot's vector envs give it
        for given, n in ((obs, 1), (batched, 2)):
            out = preprocess_observation(given)
            assert set(out) == {"observation.image", "observation.state"}
            assert out["observation.image"].shape == (n, 3, 64, 64) and out["observation.state"].shape == (n, 6)
        np.testing.assert_allclose(out["observation.image"][0].permute(1, 2, 0).numpy() * 255, obs["pixels"])
        np.testing.assert_array_equal(out["observation.state"][0].numpy(), obs["agent_pos"])
    finally:
        env.close()
    plain = GraspEnv()  # the default keeps nsl's keys, with the same content
    try:
        nsl_obs, _ = plain.reset(seed=5)
        assert set(nsl_obs) == {"image", "state"}
        np.testing.assert_array_equal(nsl_obs["image"], obs["pixels"])
    finally:
        plain.close()
    with pytest.raises(ConfigError, match="obs_type 'rgb'"):
        GraspEnv(obs_type="rgb")
