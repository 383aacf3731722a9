"""The base task on both engines: scripted policies' success rates on the same scenes, and what a reset costs.

Measures, for the engines MuJoCo and PyBullet (``EnvConfig.engine``), on the base task's first 200 scenes of
collection seed 0 (train split, auto-descent control: the scenes ``nsl collect --shift base --seed 0`` makes):

* the success rate of the scripted ``oracle`` (no noise) and of ``random``, with 95% Wilson intervals;
* the paired difference of the oracle's outcomes between the engines on the same scenes (Newcombe);
* the mean wall-clock cost of ``GraspEnv.reset`` (building the episode's world and settling its objects, and
  the first frame) over 50 resets, and of a whole oracle episode.

No workspace is written.  About 3 minutes with one simulator process on this machine (both cores shared with
a study): ``nice -n 19 .venv/bin/python scripts/experiments/engine_rates.py [--scenes 200]``.
"""

from __future__ import annotations

import argparse
import functools
import time

from nsl.collectors import EnvConfig, GraspEnv, collect_episodes, episode_seeds, scripted_policy
from nsl.stats import newcombe_paired_interval, paired_counts, wilson_interval

ENGINES = ("mujoco", "pybullet")


def outcomes(engine: str, policy: str, scenes: int) -> tuple[list[bool], float]:
    start = time.perf_counter()
    eps = collect_episodes(EnvConfig(engine=engine), functools.partial(scripted_policy, policy), range(scenes), seed=0)
    wins = [e.success for e in eps]
    return wins, (time.perf_counter() - start) / scenes


def reset_cost(engine: str, resets: int = 50) -> float:
    env = GraspEnv(EnvConfig(engine=engine))
    env.reset(seed=episode_seeds(0, 0)[0])  # the first reset also starts the engine and parses meshes
    start = time.perf_counter()
    for i in range(1, resets + 1):
        env.reset(seed=episode_seeds(0, i)[0])
    env.close()
    return (time.perf_counter() - start) / resets


def rate(wins: list[bool]) -> str:
    lo, hi = wilson_interval(sum(wins), len(wins))
    return f"{sum(wins) / len(wins):.1%} [{lo:.1%}, {hi:.1%}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=200)
    args = ap.parse_args()
    rows, oracle = [], {}
    for engine in ENGINES:
        cost = reset_cost(engine)
        o, per_episode = outcomes(engine, "oracle", args.scenes)
        r, _ = outcomes(engine, "random", args.scenes)
        oracle[engine] = o
        rows.append(f"| {engine} | {rate(o)} | {rate(r)} | {1000 * cost:.0f} ms | {1000 * per_episode:.0f} ms |")
    print(f"base task, {args.scenes} scenes of collection seed 0 (train split)\n")
    print("| engine | oracle | random | reset | oracle episode |")
    print("|---|---|---|---|---|")
    print("\n".join(rows))
    both, only_a, only_b, neither = paired_counts(oracle["pybullet"], oracle["mujoco"])
    lo, hi = newcombe_paired_interval(both, only_a, only_b, neither)
    print(
        f"\noracle, PyBullet minus MuJoCo on the same scenes: {(only_a - only_b) / args.scenes:+.1%} "
        f"[{lo:+.1%}, {hi:+.1%}] (both succeed {both}, PyBullet only {only_a}, MuJoCo only {only_b}, neither {neither})"
    )


if __name__ == "__main__":
    main()
