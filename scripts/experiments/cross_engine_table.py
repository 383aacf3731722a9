"""The cross-engine experiment's numbers, from the records of the study ``cross-engine``.

Reads ``docs/study-cross-engine/records.json`` (``nsl study report cross-engine`` writes it; every run's
per-scene outcomes on the 500 final reporting scenes, seed 51425) and prints, with intervals from
``nsl.stats`` (each over scenes and the 3 training seeds; one target collection, held fixed):

* each run's success on PyBullet's base task (``engine:pybullet``) and on MuJoCo's (``base``);
* the fine-tunes' gain over the base on PyBullet, and their change on MuJoCo (hierarchical paired bootstrap);
* fine-tuning minus scratch on each engine (``hierarchical_difference``, both sides 3 seeds).

Usage: ``python scripts/experiments/cross_engine_table.py [RECORDS]``; it takes a second or two.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from nsl.stats import hierarchical_difference, hierarchical_gain

RECORDS = Path(__file__).resolve().parents[2] / "docs" / "study-cross-engine" / "records.json"
TASKS = {"engine:pybullet": "PyBullet base task", "base": "MuJoCo base task"}


def bits(cell: dict) -> np.ndarray:
    return np.array([c == "1" for c in cell["outcomes"]], dtype=float)


def main() -> None:
    rec = json.loads(Path(sys.argv[1] if len(sys.argv) > 1 else RECORDS).read_text())
    f = rec["finetune"]["engine:pybullet"]
    runs = {
        task: {
            "base policy": bits(rec["base_policy"][task])[None, None],
            "fine-tune (800)": np.stack([bits(c) for c in (f["tiers"] if task != "base" else f["tiers_base"])["800"]])[
                None
            ],
            "scratch (800)": np.stack(
                [bits(c) for c in (f["baselines"] if task != "base" else f["baselines_base"])["scratch"]]
            )[None],
        }
        for task in TASKS
    }
    print("| task | policy | seeds' success | mean |")
    print("|---|---|---|---|")
    for task, by in runs.items():
        for who, o in by.items():
            seeds = ", ".join(f"{100 * r:.1f}" for r in o.mean(axis=2)[0])
            print(f"| {TASKS[task]} | {who} | {seeds} | {100 * o.mean():.1f}% |")
    print()
    print("| task | comparison | points [95%] | variance: seeds, scenes |")
    print("|---|---|---|---|")
    for task, by in runs.items():
        ft, scratch, base = by["fine-tune (800)"], by["scratch (800)"], by["base policy"][0, 0]
        for label, g in (
            ("fine-tune - base policy", hierarchical_gain(ft, base)),
            ("fine-tune - scratch", hierarchical_difference(ft, scratch)),
        ):
            shares = f"{100 * g.shares['seeds']:.0f}%, {100 * g.shares['scenes']:.0f}%"
            points = f"{100 * g.mean:+.1f} [{100 * g.low:+.1f}, {100 * g.high:+.1f}]"
            print(f"| {TASKS[task]} | {label} | {points} | {shares} |")


if __name__ == "__main__":
    main()
