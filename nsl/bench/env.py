"""``nsl bench env``: grasp attempts per second, nsl vs PyBullet's KukaDiverseObjectEnv.

The environments run in this process, one after the other, on the same
machine state: 64x64 images, 5 objects, random actions, no early termination
(every attempt runs its full 8 steps and ends in a grasp).  ``--engine
pybullet`` times nsl's env on PyBullet and on MuJoCo beside the reference, so
both ratios come from one run.
"""

from __future__ import annotations

import os
import sys
import time
import types
import warnings

HELP = "grasp attempts/s of nsl's env vs PyBullet's KukaDiverseObjectEnv (target ratio >= 20)"
ENGINES = ("mujoco", "pybullet")  # nsl.collectors.ENGINES (that package loads gymnasium)


def add_arguments(p) -> None:
    p.add_argument(
        "--seconds",
        type=float,
        default=None,
        help="time budget for the reference env (default 60, quick 25); nsl gets a quarter of it per engine",
    )
    p.add_argument(
        "--engine",
        choices=ENGINES,
        default=ENGINES[0],
        help="nsl's engine to time against the reference (target ratio: 20 on mujoco, 5 on pybullet); "
        "pybullet also times mujoco in the same run",
    )


def load_kuka_diverse_object_env():
    """Import PyBullet's KukaDiverseObjectEnv without running ``pybullet_envs/__init__``.

    The package ``__init__`` registers dozens of gym environments and fails with
    current gym; the module itself only needs legacy ``gym`` and
    ``pkg_resources`` (the ``bench`` extra installs both).  Empty package
    modules pointing at the real folders let Python import the module file
    unchanged.
    """
    import importlib.util

    import pybullet_data  # noqa: F401  (the package ships pybullet_envs beside it)

    spec = importlib.util.find_spec("pybullet")
    site = os.path.dirname(spec.origin)
    for name, sub in (("pybullet_envs", "pybullet_envs"), ("pybullet_envs.bullet", "pybullet_envs/bullet")):
        if name not in sys.modules:
            pkg = types.ModuleType(name)
            pkg.__path__ = [os.path.join(site, sub)]
            sys.modules[name] = pkg
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            module = importlib.import_module("pybullet_envs.bullet.kuka_diverse_object_gym_env")
        except ImportError as e:
            from nsl.errors import EnvironmentSetupError

            raise EnvironmentSetupError(
                f"cannot import PyBullet's KukaDiverseObjectEnv ({e}); install the bench extra: "
                "pip install -e '.[bench]'"
            ) from None
    return module.KukaDiverseObjectEnv


def _time_reference(seconds: float, seed: int = 0) -> tuple[float, int]:
    import contextlib

    import numpy as np

    with warnings.catch_warnings(), contextlib.redirect_stdout(sys.stderr):  # it prints to stdout
        warnings.simplefilter("ignore")
        cls = load_kuka_diverse_object_env()
        env = cls(renders=False, isDiscrete=False, width=64, height=64, numObjects=5, maxSteps=8)
    env.seed(seed)
    rng = np.random.default_rng(seed)
    with contextlib.redirect_stdout(sys.stderr):
        env.reset()  # warm-up, as for nsl
    attempts = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds or attempts < 5:
        with contextlib.redirect_stdout(sys.stderr):
            env.reset()
        done = False
        while not done:
            _, _, done, _ = env.step(rng.uniform(-1, 1, env.action_space.shape[0]))
        attempts += 1
    dt = time.perf_counter() - t0
    env.close() if hasattr(env, "close") else None
    return attempts / dt, attempts


def _time_nsl(seconds: float, seed: int = 0, engine: str = ENGINES[0]) -> tuple[float, int]:
    import numpy as np

    from nsl.collectors import EnvConfig, GraspEnv

    env = GraspEnv(EnvConfig(min_objects=5, max_objects=5, image_size=64, engine=engine))
    env.reset(seed=seed)  # warm-up: GL context or PyBullet client, shader compilation, mesh parsing
    rng = np.random.default_rng(seed)
    attempts = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds or attempts < 2:
        env.reset(seed=seed + attempts)
        done = False
        while not done:
            a = rng.uniform(-1, 1, 6)
            a[5] = -1.0  # never terminate early: every attempt runs all steps
            _, _, term, trunc, _ = env.step(a)
            done = term or trunc
        attempts += 1
    dt = time.perf_counter() - t0
    env.close()
    return attempts / dt, attempts


def run(args) -> dict:
    seconds = args.seconds or (25.0 if args.quick else 60.0)
    engine = getattr(args, "engine", ENGINES[0])
    timed = {e: _time_nsl(seconds / 4, engine=e) for e in dict.fromkeys((engine, ENGINES[0]))}
    ref_rate, ref_n = _time_reference(seconds)
    nsl_rate, nsl_n = timed[engine]
    out = {
        "engine": engine,
        "nsl_attempts_per_s": round(nsl_rate, 2),
        "reference_attempts_per_s": round(ref_rate, 3),
        "ratio": round(nsl_rate / ref_rate, 1),
        "nsl_attempts": nsl_n,
        "reference_attempts": ref_n,
        "image_size": 64,
        "objects": 5,
        "reference": "pybullet_envs.bullet.kuka_diverse_object_gym_env.KukaDiverseObjectEnv",
    }
    if engine != ENGINES[0]:  # MuJoCo's ratio beside it, from the same run
        mj_rate, mj_n = timed[ENGINES[0]]
        out |= {"mujoco_attempts_per_s": round(mj_rate, 2), "mujoco_ratio": round(mj_rate / ref_rate, 1)}
        out |= {"mujoco_attempts": mj_n}
    return out
