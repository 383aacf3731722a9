"""The table of scripts/experiments/finetune_recipes.sh: each fine-tuning recipe's success on every calibrated shift
and on the base task, against the base checkpoint, from the evaluation records it wrote to $NSL_HOME/recipes.

For each recipe row: success on the shift it was fine-tuned on (gain over the base checkpoint in points), the base
task after that fine-tune, the average gain over the shifts, and how many fine-tunes keep the base task within 10
points of the base checkpoint's own (the base-policy bar) or at it (the study's "reached the base's own
success").  Every cell is one fine-tune (seed 0) on 200 selection scenes (seed 3000).

    python scripts/experiments/recipes_table.py $NSL_HOME/recipes
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

SHIFTS = [
    "harsh_lighting",
    "transparent_objects@0.8",
    "checkerboard_backing@0.6",
    "extend_gripper@2.5",
    "offset_gripper@0.35",
]


def slug(shift: str) -> str:
    return shift.replace("+", "-").replace("@", "-").replace("_", "-")


def rate(path: Path, shift: str) -> float | None:
    if not path.is_file() or not path.stat().st_size:
        return None
    return 100 * json.loads(path.read_text())["results"][shift]["success_rate"]


def main(folder: Path) -> None:
    base = {s: rate(folder / "base.json", s) for s in [*SHIFTS, "base"]}
    print(
        "| recipe | " + " | ".join(f"{s}: shift / base task" for s in SHIFTS) + " | mean gain | base task "
        "within 10 / at the base's |"
    )
    print("|---|" + "---|" * (len(SHIFTS) + 2))
    print("| base checkpoint | " + " | ".join(f"{base[s]:.1f} / {base['base']:.1f}" for s in SHIFTS) + " | - | - |")
    for recipe in ("protocol", "cons01", "cons03"):
        cells, gains, within, at = [], [], 0, 0
        for s in SHIFTS:
            path = folder / f"{recipe}-{slug(s)}.json"
            shift, task = rate(path, s), rate(path, "base")
            if shift is None:
                cells.append("n/a")
                continue
            gains.append(shift - base[s])
            within += task >= base["base"] - 10
            at += task >= base["base"]
            cells.append(f"{shift:.1f} ({shift - base[s]:+.1f}) / {task:.1f}")
        mean = f"{sum(gains) / len(gains):+.1f}" if gains else "n/a"
        print(f"| {recipe} | " + " | ".join(cells) + f" | {mean} | {within} / {at} of {len(gains)} |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
