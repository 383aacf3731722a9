"""Where evaluation's time goes, and what one CEM search costs in float32 and in bfloat16.

Measures, in one process (one worker, 8 environments in lock-step, test objects, the shipped base):

* the share of an evaluation's wall time spent in the policy (``CEMPolicy.greedy``), in the simulator
  (``GraspEnv.step``, physics and rendering) and elsewhere, under ``cProfile``, for fp32 and bf16 acting;
* one state's CEM search (the trunk once, the head on 64 candidates twice) at batch 1, as the policy runs it:
  float32, bfloat16 autocast (what ``--precision bf16`` does), and a bfloat16 copy of the weights.

The first bounds what faster arithmetic in the policy can give an evaluation (Amdahl's law); the second says
whether bfloat16 is faster at batch 1 at all.  About a minute:

    MUJOCO_GL=egl .venv/bin/python scripts/experiments/eval_time_split.py
"""

from __future__ import annotations

import argparse
import copy
import cProfile
import functools
import pstats
import time

import numpy as np
import torch

from nsl import workspace
from nsl.collectors import EnvConfig, collect_episodes
from nsl.learners import load_policy
from nsl.learners.augment import to_float


def split(precision: str, episodes: int) -> dict[str, float]:
    make_policy = functools.partial(load_policy, str(workspace.shipped_base_dir()), precision=precision)
    profile = cProfile.Profile()
    started = time.perf_counter()
    profile.enable()
    for _ in collect_episodes(EnvConfig(split="test"), make_policy, range(episodes), seed=7, workers=1, batch=8):
        pass
    profile.disable()
    wall = time.perf_counter() - started
    stats = pstats.Stats(profile).stats  # type: ignore[attr-defined]  # pstats keeps its table here
    cumulative = {"/".join(path.split("/")[-2:]) + f":{name}": v[3] for (path, _, name), v in stats.items()}
    policy = cumulative.get("learners/policy.py:greedy", 0.0)
    env = cumulative.get("collectors/env.py:step", 0.0)
    return {"wall": wall, "policy": policy, "env": env, "episodes_per_s": episodes / wall}


def cem_call_ms(repeats: int = 200) -> dict[str, float]:
    policy = load_policy(str(workspace.shipped_base_dir()))
    net = policy.net
    net16 = copy.deepcopy(net).to(torch.bfloat16)
    pixels = np.random.default_rng(0).integers(0, 256, (1, 64, 64, 3), dtype=np.uint8)
    image, state = to_float(torch.from_numpy(pixels)), torch.zeros(1, net.cfg.state_dim)
    candidates = torch.rand(1, 64, len(net.cfg.action_dims)) * 2 - 1

    def search(network, image, state, candidates):  # CEM's work for one state: the trunk once, the head twice
        ctx = network.encode(image, state)
        network.score(ctx, candidates)
        return network.score(ctx, candidates).float()

    def fp32():
        return search(net, image, state, candidates)

    def autocast_bf16():
        with torch.autocast("cpu", dtype=torch.bfloat16):
            return search(net, image, state, candidates)

    def weights_bf16():
        return search(net16, image.to(torch.bfloat16), state.to(torch.bfloat16), candidates.to(torch.bfloat16))

    out = {}
    with torch.inference_mode():
        for _ in range(2):  # the second round is the one kept: warm caches, both orders seen
            for f in (fp32, autocast_bf16, weights_bf16):
                f()
                t = time.perf_counter()
                for _ in range(repeats):
                    f()
                out[f.__name__] = (time.perf_counter() - t) / repeats * 1e3
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=96)
    args = ap.parse_args()
    for precision in ("fp32", "bf16"):
        s = split(precision, args.episodes)
        rest = s["wall"] - s["policy"] - s["env"]
        print(
            f"{precision}: {s['episodes_per_s']:.1f} episodes/s; policy {100 * s['policy'] / s['wall']:.0f}%, "
            f"simulator {100 * s['env'] / s['wall']:.0f}%, other {100 * rest / s['wall']:.0f}% "
            f"(bound on the speed-up of an infinitely fast policy: {s['wall'] / (s['wall'] - s['policy']):.2f}x)"
        )
    for name, ms in cem_call_ms().items():
        print(f"one state's encode + 2 x 64 candidates, batch 1, {name}: {ms:.2f} ms")


if __name__ == "__main__":
    main()
