"""Does bfloat16 training learn what float32 training learns?  The study's protocol in both precisions.

Measures, in the workspace ``$NSL_HOME``:

* for harsh lighting@2 and offset gripper@0.25: the shipped base collects 800 episodes (epsilon 0.1), and is
  fine-tuned 50/50 with the scripted base data (the default recipe) with three seeds in ``--precision fp32``
  and three in ``--precision bf16``; every fine-tune acts in fp32 on 1,000 selection scenes (seed 3000);
* the shipped base itself acting in fp32 and in bf16 on the base task and both shifts, 1,000 selection scenes.

Prints a Markdown table: each precision's mean success over seeds, and the difference (bf16 - fp32) with a 95%
interval paired on the scenes (seed s in bf16 against seed s in fp32, 3,000 pairs; Newcombe's paired interval, the
seeds' spread printed beside it); and the base acting in each precision, paired on its 1,000 scenes.  Every step
resumes: collections and training runs continue where they stopped.

    NSL_HOME=<a workspace with the scripted base data> python scripts/experiments/precision_equivalence.py

The scripted base data is what ``scripts/collect_base_data.sh`` collects (``make demo`` does it too).
"""

from __future__ import annotations

import argparse
import statistics
import time

import nsl
from nsl.eval import compare_paired

SHIFTS = ("harsh_lighting@2", "offset_gripper@0.25")
# bf16 runs update with fused Adam (learners/qtopt.py); runs named "bf16" in older workspaces used the per-tensor loop
RUN_NAME = {"fp32": "fp32", "bf16": "bf16-fused"}
BASE_MIX = ("grasp-base-oracle=0.27", "grasp-base-noisy=0.115", "grasp-base-random=0.115")


def slug(shift: str) -> str:
    return shift.replace("@", "-").replace("_", "-").replace(".", "")


def over_seeds(bf16: list[float], fp32: list[float]) -> str:
    """Mean of the per-seed differences (seed s in bf16 minus seed s in fp32, points) and its 95% t interval."""
    from nsl.stats import t_interval

    d = [a - b for a, b in zip(bf16, fp32)]
    m, half = t_interval(d) or (statistics.mean(d), float("nan"))
    return f"{m:+.1f} [{m - half:+.1f}, {m + half:+.1f}]"


def paired(bf16: list[bool], fp32: list[bool]) -> str:
    """bf16 - fp32 in points with its 95% paired interval, from outcomes on the same scenes."""
    c = compare_paired(bf16, fp32, "bf16", "fp32")
    return f"{100 * (c.success_a - c.success_b):+.1f} [{100 * c.ci_low:+.1f}, {100 * c.ci_high:+.1f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--episodes", type=int, default=1000, help="evaluation scenes per cell")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    rows = []
    for shift in SHIFTS:
        data = f"prec-{slug(shift)}-by-base"
        nsl.collect(
            shift=shift,
            episodes=800,
            policy="ckpt:base",
            epsilon=0.1,
            data=data,
            seed=5,
            workers=args.workers,
            num_envs=8,
            progress=False,
        )
        rates: dict[str, list[tuple[int, int]]] = {}
        outcomes: dict[str, list[bool]] = {}  # each precision's episodes, seed after seed, scene by scene
        for precision in ("fp32", "bf16"):
            for seed in seeds:
                started = time.perf_counter()
                run = nsl.train(
                    data=[*BASE_MIX, f"{data}=0.5"],
                    init="ckpt:base",
                    seed=seed,
                    precision=precision,
                    name=f"prec-{slug(shift)}-{RUN_NAME[precision]}-s{seed}",
                    progress=False,
                )
                result = nsl.evaluate(
                    run.checkpoint,
                    shift=shift,
                    episodes=args.episodes,
                    seed=nsl.SELECTION_SCENES,
                    workers=args.workers,
                    progress=False,
                    source="precision equivalence",
                )
                r = result.table[run.checkpoint][shift]
                rates.setdefault(precision, []).append((r.successes, r.episodes))
                outcomes.setdefault(precision, []).extend(result.outcomes[run.checkpoint][shift])
                print(f"{shift} {precision} seed {seed}: {r} ({time.perf_counter() - started:.0f} s)", flush=True)
        rows.append((shift, rates, outcomes))
    base = nsl.evaluate(
        "ckpt:base",
        shift="base," + ",".join(SHIFTS),
        episodes=args.episodes,
        seed=nsl.SELECTION_SCENES,
        workers=args.workers,
        progress=False,
    )
    base16 = nsl.evaluate(
        "ckpt:base",
        shift="base," + ",".join(SHIFTS),
        episodes=args.episodes,
        seed=nsl.SELECTION_SCENES,
        workers=args.workers,
        progress=False,
        precision="bf16",
    )
    print(
        "\n| shift | fp32 fine-tunes (seeds) | bf16 fine-tunes (seeds) | bf16 - fp32 [95%, paired scenes] | "
        "the same over seeds [95% t] |"
    )
    print("|---|---|---|---|---|")
    for shift, rates, outcomes in rows:
        cells = {}
        for precision, rs in rates.items():
            per = [100 * s / n for s, n in rs]
            cells[precision] = (sum(s for s, _ in rs) / sum(n for _, n in rs), sum(n for _, n in rs), per)
        (p32, _, s32), (p16, _, s16) = cells["fp32"], cells["bf16"]
        spread = lambda xs: " / ".join(f"{x:.1f}" for x in xs)  # noqa: E731
        print(
            f"| {shift} | {100 * p32:.1f}% ({spread(s32)}; sd {statistics.pstdev(s32):.1f}) | "
            f"{100 * p16:.1f}% ({spread(s16)}; sd {statistics.pstdev(s16):.1f}) | "
            f"{paired(outcomes['bf16'], outcomes['fp32'])} | {over_seeds(s16, s32)} |"
        )
    print("\n| the shipped base on | acting in fp32 | acting in bf16 | bf16 - fp32 [95%] |")
    print("|---|---|---|---|")
    for shift, r32 in base.table["ckpt:base"].items():
        r16 = base16.table["ckpt:base"][shift]
        diff = paired(base16.outcomes["ckpt:base"][shift], base.outcomes["ckpt:base"][shift])
        print(f"| {shift} | {r32} | {r16} | {diff} |")


if __name__ == "__main__":
    main()
