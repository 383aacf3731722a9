"""Calibrate the shifts' severities to the source study's drops (Table 5.1).

Measures a checkpoint's success on the base task and on each shift at a grid of severities, on
selection scenes (``--seed 3000``; choose there, report on the reporting scenes), and picks for
each shift the severity whose drop (base-task success minus shift success, in points) is closest
to the study's drop, among those that cost at least 10 points and lie within 15 points of it.

Usage (in the workspace that holds the checkpoint; writes JSON and prints a Markdown table):

    python scripts/experiments/calibrate_shifts.py --checkpoint ckpt:base --episodes 400 \
        --out calibration.json

Every evaluation is an ordinary ``nsl eval`` and lands in the catalog (source "calibration").
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import nsl
from nsl.study.reference import STUDY_DROPS

GRID = {
    "harsh_lighting": (2.0, 1.5, 1.0, 0.75, 0.5),
    "checkerboard_backing": (1.0, 0.6, 0.4, 0.25),
    "transparent_objects": (1.0, 0.8, 0.6, 0.45),
    "extend_gripper": (1.0, 1.5, 2.0, 2.5, 3.0),
    "offset_gripper": (0.5, 0.35, 0.25, 0.15),
}


def choose(base: float, rates: dict[float, float], study_drop: float) -> float | None:
    """The severity whose drop is closest to the study's, among drops >= 10 within 15 points of it."""
    ok = {
        s: 100 * (base - r)
        for s, r in rates.items()
        if 100 * (base - r) >= 10 and abs(100 * (base - r) - study_drop) <= 15
    }
    return min(ok, key=lambda s: (abs(ok[s] - study_drop), s)) if ok else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="ckpt:base")
    ap.add_argument("--episodes", type=int, default=400)
    ap.add_argument("--seed", type=int, default=3000, help="scene seed (selection scenes)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("calibration.json"))
    ap.add_argument("--only", nargs="*", choices=sorted(GRID), help="measure only these shifts")
    ap.add_argument(
        "--severities",
        type=lambda t: tuple(float(x) for x in t.split(",")),
        help="with one --only shift: measure these severities (comma-separated) instead of its grid",
    )
    args = ap.parse_args()
    grid = {k: v for k, v in GRID.items() if not args.only or k in args.only}
    if args.severities:
        if len(grid) != 1:
            ap.error("--severities needs exactly one shift in --only")
        grid = {k: args.severities for k in grid}

    specs = ["base"] + [f"{name}@{s:g}" for name, g in grid.items() for s in g]
    res = nsl.evaluate(
        args.checkpoint,
        shift=",".join(specs),
        episodes=args.episodes,
        seed=args.seed,
        workers=args.workers,
        source="calibration",
        progress=False,
    )
    table = {str(k): v for k, v in res.table[args.checkpoint].items()}
    rate = {spec: table[spec].success_rate for spec in table}
    base = next(r for spec, r in rate.items() if spec in ("base", ""))
    out = {"checkpoint": args.checkpoint, "episodes": args.episodes, "seed": args.seed, "base": base, "shifts": {}}
    print(f"base task: {100 * base:.1f}% on {args.episodes} scenes (seed {args.seed})\n")
    print("| shift | severity | success | drop | study's drop | chosen |")
    print("|---|---|---|---|---|---|")
    for name, g in grid.items():
        rates = {s: rate[f"{name}@{s:g}" if s != 1.0 else name] for s in g}
        pick = choose(base, rates, STUDY_DROPS[name])
        out["shifts"][name] = {
            "rates": {str(s): r for s, r in rates.items()},
            "study_drop": STUDY_DROPS[name],
            "chosen": pick,
        }
        for s, r in rates.items():
            print(
                f"| {name} | {s:g} | {100 * r:.1f}% | {100 * (base - r):+.1f} | {STUDY_DROPS[name]} | "
                f"{'**yes**' if s == pick else ''} |"
            )
    args.out.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
