"""Measure what a study unit costs on this machine: run a one-shift cost plan with `nsl study run` and print
the seconds of each unit from its status file, per 100 training steps (each method), per 50 evaluation
episodes and per 100 collected episodes (scripted and checkpoint policies).

    python scripts/study_unit_costs.py [--home DIR] [--steps 100] [--episodes 50] [--collect 100]

The study's plans state their cost estimates from these figures (study/estimate.py holds them).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

PLAN = """
name = "costs"
base = "ckpt:base"
shifts = ["harsh_lighting"]
checkpoint_every = 500
continual = false
curves = false
early_stop = false

[base_data]
source = "plan"

[[base_data.datasets]]
name = "costs-base-oracle"
policy = "oracle:0.5"
seed = 1
episodes = {base}

[collect]
episodes = {collect}
epsilon = 0.1
seed = 5

[eval]
episodes = {episodes}
seed = 2000

[finetune]
tiers = [{collect}]
steps = {steps}
seeds = [0]
baselines = ["scratch", "new_head", "pnn", "ft_pnn"]
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--home", type=Path, default=None, help="workspace (default: a new temporary folder)")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--episodes", type=int, default=50, help="evaluation episodes per unit")
    ap.add_argument("--collect", type=int, default=100, help="episodes the base policy collects")
    ap.add_argument("--base", type=int, default=200, help="scripted base-task episodes")
    args = ap.parse_args()
    home = args.home or Path(tempfile.mkdtemp(prefix="nsl-costs-"))
    plan = home / "costs.toml"
    home.mkdir(parents=True, exist_ok=True)
    plan.write_text(PLAN.format(steps=args.steps, episodes=args.episodes, collect=args.collect, base=args.base))
    env = {**os.environ, "NSL_HOME": str(home)}
    subprocess.run([sys.executable, "-m", "nsl", "study", "run", str(plan), "--quiet"], env=env, check=True)
    status = json.loads((home / "studies" / "costs" / "status.json").read_text())
    units = {n: u["seconds"] for n, u in status["units"].items()}
    out = {
        "load_average": os.getloadavg(),
        "cpus": os.cpu_count(),
        "steps": args.steps,
        "eval_episodes": args.episodes,
        "collect_episodes": args.collect,
        "base_episodes": args.base,
        "units": units,
    }
    print(json.dumps(out, indent=2, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
