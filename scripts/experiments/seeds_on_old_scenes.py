"""The `full-seeds` study's three-seed fine-tunes on the old reporting scenes: the middle column of the side-by-side
table in docs/study.md.

Measures, in a workspace where ``nsl study run full-seeds`` has finished (``$NSL_HOME``):

* for every shift of the plan: its 800-episode fine-tunes (training seeds 0, 1, 2) and the shipped base, acting in
  fp32 on the study's former reporting scenes (seed 2000, 200 scenes: those of the single-seed `full` report);
* the mean gain over seeds (fine-tune minus base, each seed paired with the base on the same scenes) with a 95% t
  interval over the seeds, and the pooled paired interval (Newcombe) over all seeds' scenes.

Prints a Markdown table, its last row the mean gain over the shifts (each seed's five-shift mean one sample).  The
evaluations are catalogued; about 7 minutes with one simulator process on this machine while a study ran beside it.

    NSL_HOME=<the full-seeds workspace> python scripts/experiments/seeds_on_old_scenes.py [--study full-seeds]
"""

from __future__ import annotations

import argparse
import statistics

import nsl
from nsl.eval import compare_paired
from nsl.study import load_plan
from nsl.study.units import train_tag


def t_interval(values: list[float]) -> str:
    from nsl.stats import t_interval as t95

    m, half = t95(values) or (statistics.mean(values), float("nan"))
    return f"{m:+.1f} [{m - half:+.1f}, {m + half:+.1f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--study", default="full-seeds", help="the finished study's name (and shipped plan)")
    ap.add_argument("--scenes", type=int, default=nsl.REPORTING_SCENES, help="scene seed (the former reporting)")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    plan = load_plan(args.study)
    f = plan.finetune
    top = f.tiers[-1]
    opts = dict(episodes=args.episodes, seed=args.scenes, workers=args.workers, num_envs=8)
    print(
        f"| shift | base | fine-tuned, mean of seeds {', '.join(map(str, f.seeds))} | gain over seeds [t 95%] "
        "| gain pooled [paired 95%] |"
    )
    print("|---|---|---|---|---|")
    per_seed: list[list[float]] = []
    for shift in plan.shifts:
        base = nsl.evaluate(plan.base, shift=shift, progress=False, source="seeds_on_old_scenes", **opts)
        base_out = base.outcomes[plan.base][shift]
        rates, gains, ft_all, base_all = [], [], [], []
        for seed in f.seeds:
            ref = f"ckpt:{args.study}-{train_tag('ft', shift, top, f.steps, seed)}@latest"
            r = nsl.evaluate(ref, shift=shift, progress=False, source="seeds_on_old_scenes", **opts)
            out = r.outcomes[ref][shift]
            rates.append(100 * sum(out) / len(out))
            gains.append(100 * (sum(out) - sum(base_out)) / len(out))
            ft_all += list(out)
            base_all += list(base_out)
        c = compare_paired(ft_all, base_all, "ft", "base")
        pooled = f"{100 * (c.success_a - c.success_b):+.1f} [{100 * c.ci_low:+.1f}, {100 * c.ci_high:+.1f}]"
        base_rate = 100 * sum(base_out) / len(base_out)
        ft = f"{statistics.mean(rates):.1f}% ({', '.join(f'{x:.0f}' for x in rates)})"
        print(f"| {shift} | {base_rate:.1f}% | {ft} | {t_interval(gains)} | {pooled} |")
        per_seed.append(gains)
    means = [statistics.mean(g[i] for g in per_seed) for i in range(len(f.seeds))]
    print(f"| mean gain | | | {t_interval(means)} | |")


if __name__ == "__main__":
    main()
