"""The headline study's fine-tunes by target collection and training seed, from its committed records.

Reads ``docs/study-headline/records.json`` (``nsl study report headline`` writes it) and prints, for each
shift, the base policy's success and each 800-episode fine-tune's, on the shift and on the
base task, grouped by target collection (seed 5: the plan's collection; 97573: the second), on the 500 final
reporting scenes (seed 51425).  The intervals are in the report itself (``nsl.stats``' hierarchical bootstrap).

Usage: ``python scripts/experiments/headline_collections.py [RECORDS]``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

RECORDS = Path(__file__).resolve().parents[2] / "docs" / "study-headline" / "records.json"


def rate(cell: dict) -> float:
    return 100.0 * cell["successes"] / cell["episodes"]


def main() -> None:
    rec = json.loads(Path(sys.argv[1] if len(sys.argv) > 1 else RECORDS).read_text())
    first = str(rec["plan"]["collect"]["seed"])
    print("| shift | task | base policy | collection | seeds' success | mean |")
    print("|---|---|---|---|---|---|")
    for shift, f in rec["finetune"].items():
        for task, suffix, base in (("shift", "", rec["base_policy"].get(shift)), ("base task", "_base", None)):
            groups = {first: f["tiers" + suffix].get("800") or [], **f["collections" + suffix]}
            if not all(c for c in groups[first]) or not groups[first]:
                continue  # not measured yet
            base_cell = base if task == "shift" else rec["base_policy"].get("base")
            for coll, cells in groups.items():
                seeds = [rate(c) for c in cells if c]
                if not seeds:
                    continue
                base_text = f"{rate(base_cell):.1f}%" if base_cell else "-"
                values = ", ".join(f"{v:.1f}" for v in seeds)
                print(f"| {shift} | {task} | {base_text} | {coll} | {values} | {sum(seeds) / len(seeds):.1f}% |")


if __name__ == "__main__":
    main()
