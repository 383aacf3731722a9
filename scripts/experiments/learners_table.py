"""The table of docs/learners.md, "IQL against QT-Opt": reads the `nsl eval --json` files that
`scripts/experiments/learners_table.sh` leaves in $NSL_HOME/learners and prints a Markdown table.

For each learner: its base (each pre-training seed) on the base task and on each shift, and its fine-tunes on
each shift (800 episodes, seeds 0-2): the mean over seeds with a 95% t interval, then the seeds' own rates.
The last rows give the difference of the fine-tunes' seed means, IQL minus QT-Opt, with a Welch t interval.
Every cell is 1,000 selection scenes (seed 3000).

    python scripts/experiments/learners_table.py $NSL_HOME/learners [--learners qtopt iql]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from nsl.stats import t_interval, welch_interval


def rates(path: Path) -> dict[str, dict[str, float]]:
    """``{policy ref: {shift: success rate}}`` of one `nsl eval --json` file."""
    d = json.loads(path.read_text())
    per = d["policies"] if "policies" in d else {d["policy"]: {"results": d["results"]}}
    return {ref: {s: r["success_rate"] for s, r in v["results"].items()} for ref, v in per.items()}


def mean_t(values: list[float]) -> tuple[float, float]:
    got = t_interval(values)
    return (values[0], float("nan")) if got is None else got


def welch(a: list[float], b: list[float]) -> tuple[float, float]:
    """Difference of means b - a with a 95% Welch t half-width."""
    return welch_interval(a, b)


def pct(m: float, half: float | None = None) -> str:
    return f"{100 * m:.1f}" + ("" if half is None or math.isnan(half) else f" ± {100 * half:.1f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path)
    p.add_argument("--learners", nargs="+", default=["qtopt", "iql"])
    args = p.parse_args()
    bases = {lrn: rates(args.folder / f"{lrn}-bases.json") for lrn in args.learners}
    shifts = [s for s in next(iter(next(iter(bases.values())).values())) if s != "base"]
    print(f"| learner | base task (base) | {' | '.join(f'{s} (base)' for s in shifts)} | "
          f"{' | '.join(f'{s} (fine-tuned, 3 seeds)' for s in shifts)} |")  # fmt: skip
    print("|---" * (2 + 2 * len(shifts)) + "|")
    tuned: dict[str, dict[str, list[float]]] = {}
    for lrn in args.learners:
        tuned[lrn] = {}
        for s in shifts:
            tag = s.split("@")[0]
            per = rates(args.folder / f"{lrn}-{tag}.json")
            tuned[lrn][s] = [r[s] for _, r in sorted(per.items())]
        base_cells = [" / ".join(pct(r[s]) for _, r in sorted(bases[lrn].items())) for s in ["base", *shifts]]
        ft_cells = [f"{pct(*mean_t(tuned[lrn][s]))} ({', '.join(pct(v) for v in tuned[lrn][s])})" for s in shifts]
        print(f"| {lrn} | {' | '.join(base_cells)} | {' | '.join(ft_cells)} |")
    if len(args.learners) == 2:
        a, b = args.learners
        diffs = [pct(*welch(tuned[a][s], tuned[b][s])) for s in shifts]
        blank = " | ".join("" for _ in range(1 + len(shifts)))
        print(f"| {b} - {a} | {blank} | {' | '.join(diffs)} |")


if __name__ == "__main__":
    main()
