"""The online-rounds plateau tables from `online_plateau.sh`'s runs (docs/experiments/plateau.md).

Selection: each shift's success after rounds 0..ROUNDS on the selection scenes (seed 3000), per seed and their
mean, and the mean over the shifts, on which the number of rounds is chosen.  With --report R: round R of every run
on the final reporting scenes (seed 51425) against the base on the same scenes, on the shift and on the base task.
A fine-tuned cell is the seed mean with its 95% Student-t interval, then the Wilson interval of the seeds' pooled
scenes.  A shift counts as reaching the base when its seed mean is inside or above the Wilson interval of the base's
base-task success; the base task is kept when its seed mean after is within 3 points of the base's.

    NSL_HOME=... python scripts/experiments/online_plateau_table.py --seeds 0 10 20 --rounds 3 [--report 3]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from nsl.curriculum.matrix import t_interval
from nsl.stats import wilson_interval

SHIFTS = ["harsh_lighting@2", "transparent_objects@0.8", "checkerboard_backing@0.4", "extend_gripper@2",
          "offset_gripper@0.25"]  # fmt: skip


def run_name(shift: str, rounds: int, steps: int, seed: int) -> str:
    slug = shift.translate(str.maketrans("+@_.", "----"))
    return f"onp-{slug}-r{rounds}-k{steps}-auto-s{seed}"


def cell(counts: list[tuple[int, int]]) -> str:
    rates = [100 * k / n for k, n in counts]
    mean = sum(rates) / len(rates)
    ci = t_interval(rates)
    lo, hi = wilson_interval(sum(k for k, _ in counts), sum(n for _, n in counts))
    spread = f" ±{(ci[1] - ci[0]) / 2:.0f}" if ci else ""
    return f"{mean:.0f}%{spread} (pooled [{100 * lo:.0f}-{100 * hi:.0f}])"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--home", type=Path, default=Path(os.environ.get("NSL_HOME", Path.home() / ".nsl")))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 10, 20])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--report", type=int, help="the chosen round, scored on the final reporting scenes")
    ap.add_argument("--episodes", type=int, default=500, help="reporting scenes per cell")
    a = ap.parse_args()
    runs = a.home / "runs"

    print("| shift | " + " | ".join(f"round {i} ({800 * i} grasps)" for i in range(a.rounds + 1)) + " |")
    print("|---" * (a.rounds + 2) + "|")
    totals: list[list[float]] = [[] for _ in range(a.rounds + 1)]
    for shift in SHIFTS:
        per_seed = []
        for seed in a.seeds:
            path = runs / run_name(shift, a.rounds, a.steps, seed) / "rounds.json"
            if path.exists():
                per_seed.append([100 * r["success"] for r in json.loads(path.read_text())])
        done = [s for s in per_seed if len(s) == a.rounds + 1]
        if not done:
            continue
        cells = []
        for i in range(a.rounds + 1):
            vals = [s[i] for s in done]
            totals[i].append(sum(vals) / len(vals))
            cells.append(f"{sum(vals) / len(vals):.1f}% ({' / '.join(f'{v:.1f}' for v in vals)})")
        print(f"| {shift} | " + " | ".join(cells) + " |")
    if totals[0]:
        print(f"| mean over {len(totals[0])} shifts | " + " | ".join(f"{sum(t) / len(t):.1f}%" for t in totals) + " |")

    if a.report is None:
        return
    base = json.loads((runs / f"onp-base-report-e{a.episodes}.json").read_text())["results"]
    b = base["base"]
    b_lo, b_hi = wilson_interval(b["successes"], b["episodes"])
    b_rate = 100 * b["success_rate"]
    print(f"\nbase on the base task: {b_rate:.0f}% [{100 * b_lo:.0f}-{100 * b_hi:.0f}] on {b['episodes']} scenes\n")
    print(f"| shift | base policy on the shift | online, round {a.report} ({800 * a.report} grasps; "
          f"{len(a.seeds)} seeds) | reaches the base's base task | base task after | kept (within 3) |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    reached = kept = 0
    for shift in SHIFTS:
        got = []
        for seed in a.seeds:
            path = runs / run_name(shift, a.rounds, a.steps, seed) / f"report-r{a.report}-e{a.episodes}.json"
            if path.exists():
                got.append(json.loads(path.read_text())["results"])
        if not got:
            continue
        on = [(r[shift]["successes"], r[shift]["episodes"]) for r in got]
        after = [(r["base"]["successes"], r["base"]["episodes"]) for r in got]
        mean_on = sum(100 * k / n for k, n in on) / len(on)
        mean_after = sum(100 * k / n for k, n in after) / len(after)
        ok_on, ok_after = mean_on >= 100 * b_lo, mean_after >= b_rate - 3
        reached += ok_on
        kept += ok_after
        yes = {True: "yes", False: "no"}
        before = f"{100 * base[shift]['success_rate']:.0f}%"
        print(f"| {shift} | {before} | {cell(on)} | {yes[ok_on]} ({mean_on - b_rate:+.0f}) | {cell(after)} "
              f"| {yes[ok_after]} |")  # fmt: skip
    print(f"\n{reached} of 5 shifts reach the base's base-task interval; the base task is kept on {kept} of 5.")


if __name__ == "__main__":
    main()
