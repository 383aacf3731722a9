"""The task on PyBullet (``EnvConfig.engine="pybullet"``): the same episodes as MuJoCo's, deterministic, graspable."""

from __future__ import annotations

import hashlib
from dataclasses import astuple

import numpy as np
import pytest

from nsl.collectors import ENGINES, EnvConfig, GraspEnv, make_envs, parse_shift, run_episodes, scripted_policy
from nsl.errors import ConfigError

PYBULLET = EnvConfig(engine="pybullet")


def _digest(episodes) -> str:
    h = hashlib.sha256()
    for e in episodes:
        for a in (e.images, e.states, e.actions, e.rewards, np.array([e.success, e.terminated, e.truncated])):
            h.update(a.tobytes())
    return h.hexdigest()


def test_same_seed_same_bits_in_any_batch():
    policy = scripted_policy("oracle:0.5")
    one = _digest(run_episodes(make_envs(PYBULLET, 1), policy, range(3), seed=42))
    again = _digest(run_episodes(make_envs(PYBULLET, 1), policy, range(3), seed=42))
    batched = _digest(run_episodes(make_envs(PYBULLET, 2), policy, range(3), seed=42))  # other envs' histories
    assert one == again == batched
    assert _digest(run_episodes(make_envs(PYBULLET, 1), policy, range(3), seed=43)) != one


def test_spaces_info_and_privileged_state_are_mujocos():
    envs = {engine: GraspEnv(EnvConfig(engine=engine)) for engine in ENGINES}
    try:
        first = {e: env.reset(seed=3) for e, env in envs.items()}
        mj, pb = envs["mujoco"], envs["pybullet"]
        assert pb.observation_space == mj.observation_space and pb.action_space == mj.action_space
        (obs_m, info_m), (obs_p, info_p) = first["mujoco"], first["pybullet"]
        assert info_p == info_m
        for k in obs_m:
            assert obs_p[k].shape == obs_m[k].shape and obs_p[k].dtype == obs_m[k].dtype
        assert pb.observation_space.contains(obs_p)
        # The same start: wrist pose, open fingers (MuJoCo's settling moves the gripper by a hair).
        assert obs_p["state"] == pytest.approx(obs_m["state"], abs=1e-3)
        priv_m, priv_p = mj.privileged_state(), pb.privileged_state()
        assert priv_p.keys() == priv_m.keys()
        for k in priv_m:
            assert priv_p[k].shape == priv_m[k].shape, k
        # Objects settle where they were dropped, on either engine.
        assert np.abs(priv_p["object_pos"][:, :2] - priv_m["object_pos"][:, :2]).max() < 0.02
        obs, reward, term, trunc, info = pb.step(np.zeros(6, np.float32))
        assert info.keys() == {"success", "step", "num_objects"} and info["step"] == 1 and not (term or trunc)
    finally:
        for env in envs.values():
            env.close()


@pytest.mark.parametrize("split", ["train", "test"])
def test_an_episode_has_the_same_objects_on_both_engines(split):
    envs = [GraspEnv(EnvConfig(engine=engine, split=split)) for engine in ENGINES]
    try:
        for seed in range(4):
            mj, pb = (env.reset(seed=seed) and env.objects for env in envs)
            assert [astuple(o) for o in pb] == [astuple(o) for o in mj]  # mesh ids, sizes, colours, poses
    finally:
        for env in envs:
            env.close()


def test_the_wrist_camera_sees_what_mujocos_sees():
    """The same camera pose and field of view: the same layout of bin, objects and fingers in the frame."""
    frames = []
    for engine in ENGINES:
        env = GraspEnv(EnvConfig(engine=engine, image_size=32))
        frames.append(env.reset(seed=3)[0]["image"].astype(np.float64).mean(axis=2))
        env.close()
    a, b = (f - f.mean() for f in frames)
    assert float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum())) > 0.8  # pixel correlation


def test_the_oracle_grasps_most_scenes():
    eps = list(run_episodes(make_envs(PYBULLET, 1), scripted_policy("oracle"), range(10), seed=0))
    assert sum(e.success for e in eps) >= 7  # 93% over 200 scenes (scripts/experiments/engine_rates.py)
    for e in eps:
        assert e.rewards.sum() == float(e.success) and e.terminated and not e.truncated


def test_full_control_and_the_shoulder_camera_run():
    env = GraspEnv(EnvConfig(engine="pybullet", control="full", camera="shoulder", image_size=32))
    obs, _ = env.reset(seed=1)
    assert obs["image"].shape == (32, 32, 3) and obs["image"].std() > 5
    steps = 0
    term = trunc = False
    while not (term or trunc):
        obs, r, term, trunc, info = env.step(np.array([0, 0, -1, 0, -1, -1], np.float32))
        steps += 1
    assert trunc and not term and steps == 20 and info["step"] == 20
    env.close()


def test_unknown_engine_fails_in_one_line_listing_the_engines():
    with pytest.raises(ConfigError, match=r"^engine 'bullet' is unknown; use one of mujoco, pybullet$"):
        EnvConfig(engine="bullet")
    with pytest.raises(ConfigError, match=r"^engine 'bullet' in shift 'engine:bullet' is unknown; use one of"):
        EnvConfig(shift="engine:bullet")
    with pytest.raises(ConfigError, match=r"names two engines"):
        EnvConfig(shift="engine:pybullet+engine:mujoco")
    with pytest.raises(ConfigError, match=r"^shift 'engine:mujoco' is on engine 'mujoco', but engine 'pybullet'"):
        parse_shift("engine:mujoco", engine="pybullet")
    config = EnvConfig(shift="harsh_lighting+engine:pybullet")  # the engine moves to its field
    assert (config.engine, config.shift, config.shift_spec.name) == (
        "pybullet",
        "harsh_lighting",
        "engine:pybullet+harsh_lighting",
    )


def test_a_shift_without_a_pybullet_apply_fails_in_one_line(monkeypatch):
    from nsl.collectors import ShiftDef, register_shift
    from nsl.collectors import shifts as shift_module

    monkeypatch.setattr(shift_module, "SHIFTS", dict(shift_module.SHIFTS))  # forget it afterwards
    register_shift(ShiftDef("dim_lights", "vision", 1.0, lambda s: {"scale": s}, lambda spec, p: None, "dimmer"))
    EnvConfig(shift="dim_lights")  # MuJoCo's apply is there
    with pytest.raises(ConfigError) as e:
        EnvConfig(engine="pybullet", shift="harsh_lighting@2+dim_lights")
    message = str(e.value)
    assert "\n" not in message and "'dim_lights'" in message and "'pybullet'" in message
    assert "engine_applies" in message  # what to add


def _first_frames(shift: str, seeds=range(2), image_size: int = 32, camera: str = "wrist") -> dict[str, np.ndarray]:
    frames = {}
    for engine in ENGINES:
        env = GraspEnv(EnvConfig(engine=engine, shift=shift, image_size=image_size, camera=camera))
        frames[engine] = np.stack([env.reset(seed=s)[0]["image"] for s in seeds]).astype(np.float64)
        env.close()
    return frames


@pytest.mark.parametrize("shift", ["harsh_lighting", "checkerboard_backing", "transparent_objects"])
def test_the_visual_shifts_change_pybullets_frames_as_they_change_mujocos(shift):
    base, shifted = _first_frames("base"), _first_frames(shift)
    change = {e: shifted[e] - base[e] for e in ENGINES}
    for engine in ENGINES:
        assert np.abs(change[engine]).mean() > 1.0, engine  # the shift shows
    a, b = (change[e].mean(axis=-1).ravel() for e in ENGINES)
    a, b = a - a.mean(), b - b.mean()
    assert float(a @ b / np.sqrt((a @ a) * (b @ b))) > 0.4  # ... in the same places, the same way (0.55-0.8 here)


def test_the_gripper_shifts_move_pybullets_fingers_as_mujocos():
    for shift, check in (("extend_gripper@2", "tip"), ("offset_gripper@0.5", "offset")):
        envs = {e: GraspEnv(EnvConfig(engine=e, shift=shift)) for e in ENGINES}
        base = {e: GraspEnv(EnvConfig(engine=e)) for e in ENGINES}
        try:
            for env in (*envs.values(), *base.values()):
                env.reset(seed=0)
            if check == "tip":  # 2 cm longer fingers reach 2 cm further below the wrist on both engines
                for e in ENGINES:
                    grown = envs[e]._sim.tip_below_wrist - base[e]._sim.tip_below_wrist
                    assert grown == pytest.approx(0.02, abs=1e-6), e
            else:  # the fingers 5 cm to the side of the controlled wrist, as the oracle is told
                offsets = [envs[e].privileged_state()["finger_offset"] for e in ENGINES]
                assert offsets[0] == pytest.approx([0.0, 0.05], abs=1e-6) and offsets[1] == pytest.approx(offsets[0])
        finally:
            for env in (*envs.values(), *base.values()):
                env.close()
    # The shoulder camera sees the offset bracket and the moved fingers.
    frames = {s: _first_frames(s, seeds=[0], camera="shoulder")["pybullet"] for s in ("base", "offset_gripper")}
    assert np.abs(frames["offset_gripper"] - frames["base"]).mean() > 1.0


def test_shifts_compose_on_pybullet():
    frames = {s: _first_frames(s, seeds=[0])["pybullet"] for s in ("base", "harsh_lighting", "checkerboard_backing")}
    both = _first_frames("checkerboard_backing+harsh_lighting", seeds=[0])["pybullet"]
    for alone in ("harsh_lighting", "checkerboard_backing"):
        assert np.abs(both - frames[alone]).mean() > 3.0  # the other shift shows on top of each one


def test_the_engine_is_recorded_only_when_it_is_not_mujoco():
    assert "engine" not in EnvConfig().to_dict()  # datasets made before the option keep their hashes
    d = EnvConfig(engine="pybullet").to_dict()
    assert d["engine"] == "pybullet" and EnvConfig.from_dict(d).engine == "pybullet"
    old = EnvConfig().to_dict()
    assert EnvConfig.from_dict(old).engine == "mujoco"  # a dataset made before reads as mujoco


def test_a_shared_mujoco_renderer_is_refused_on_pybullet():
    from nsl.collectors.render import SceneRenderer

    renderer = SceneRenderer(64, 64)
    try:
        with pytest.raises(ConfigError, match="renderer=None"):
            GraspEnv(PYBULLET, renderer=renderer)
    finally:
        renderer.close()


def test_a_pybullet_that_fails_to_start_or_a_mesh_it_cannot_load_fails_in_one_line(monkeypatch):
    import pybullet
    from pybullet_utils import bullet_client

    from nsl.collectors import objects
    from nsl.errors import EnvironmentSetupError

    real_mesh = objects.load_mesh

    def empty_mesh(object_id):  # a mesh with no vertices: PyBullet itself refuses its shapes
        mesh = real_mesh(object_id)
        return type(mesh)(mesh.name, mesh.vertices[:0], mesh.faces[:0], mesh.extents)

    monkeypatch.setattr(objects, "load_mesh", empty_mesh)
    env = GraspEnv(PYBULLET)
    with pytest.raises(EnvironmentSetupError) as e:
        env.reset(seed=0)
    env.close()
    assert "\n" not in str(e.value) and "could not load object mesh" in str(e.value) and "reinstall" in str(e.value)

    def refuse(*args, **kwargs):  # the library's boundary: a client that cannot connect
        raise pybullet.error("cannot connect to the physics server")

    monkeypatch.setattr(bullet_client, "BulletClient", refuse)
    with pytest.raises(EnvironmentSetupError, match=r"^PyBullet failed to start in DIRECT mode .*reinstall"):
        GraspEnv(PYBULLET)
