"""The engine as a shift, zero-shot: the shipped base (pre-trained on MuJoCo) on the same scenes of both engines.

Reads, from the workspace's catalog, a checkpoint's evaluations with per-scene outcomes on task pairs that
differ only by the engine: the base task (``base`` against ``engine:pybullet``) and each shift given (``SHIFT``
against ``engine:pybullet+SHIFT``).  Scene ``(seed, i)`` is the same episode on both engines (objects, poses,
colours, start pose), so the outcomes pair up.  Prints each rate with its 95% Wilson interval and the drop,
PyBullet minus MuJoCo, with its paired (Newcombe) interval over scenes.  Evaluations it needs and does not
find are named with the command that makes them, e.g.::

    nsl eval --checkpoint ckpt:base --shift checkerboard_backing@0.4,engine:pybullet+checkerboard_backing@0.4 \\
        --episodes 500 --seed 51425

Usage: ``python scripts/experiments/cross_engine_zero_shot.py [--checkpoint base] [--shift checkerboard_backing@0.4]
[--episodes 500] [--seed 51425]`` (the study ``cross-engine`` evaluates the base task pair itself).
"""

from __future__ import annotations

import argparse

from nsl.catalog import Catalog
from nsl.collectors import parse_shift
from nsl.services.refs import resolve_init
from nsl.stats import newcombe_paired_interval, paired_counts, wilson_interval


def outcomes(cat: Catalog, checkpoint: str, task: str, episodes: int, seed: int) -> list[bool] | None:
    for e in cat.evaluations(checkpoint, task):
        if e.episodes == episodes and e.seed == seed and "outcomes" in e.extra and e.precision == "fp32":
            return [c == "1" for c in e.extra["outcomes"]]
    return None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--checkpoint", default="base")
    p.add_argument("--shift", action="append", default=None, help="a MuJoCo shift to pair with PyBullet's")
    p.add_argument("--episodes", type=int, default=500)
    p.add_argument("--seed", type=int, default=51425)
    args = p.parse_args()
    shifts = ["base", *(args.shift or ["checkerboard_backing@0.4"])]
    print("| task | MuJoCo | PyBullet | PyBullet - MuJoCo (paired) |")
    print("|---|---|---|---|")
    with Catalog() as cat:
        ckpt = resolve_init(cat, f"ckpt:{args.checkpoint}").id
        for shift in shifts:
            pair = [parse_shift(shift).name, parse_shift(shift, engine="pybullet").name]
            found = [outcomes(cat, ckpt, t, args.episodes, args.seed) for t in pair]
            if any(f is None for f in found):
                print(
                    f"| {shift} | missing: nsl eval --checkpoint ckpt:{args.checkpoint} --shift {','.join(pair)} "
                    f"--episodes {args.episodes} --seed {args.seed} | | |"
                )
                continue
            mj, pb = found
            cells = []
            for wins in (mj, pb):
                lo, hi = wilson_interval(sum(wins), len(wins))
                cells.append(f"{100 * sum(wins) / len(wins):.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]")
            counts = paired_counts(pb, mj)
            lo, hi = newcombe_paired_interval(*counts)
            diff = 100 * (sum(pb) - sum(mj)) / len(mj)
            print(f"| {shift} | {cells[0]} | {cells[1]} | {diff:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}] |")


if __name__ == "__main__":
    main()
