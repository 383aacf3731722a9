#!/usr/bin/env bash
# The 8,000 scripted base-task episodes (train objects) behind the base checkpoints, about 6 minutes on 2 cores:
# oracle:0.5 (78% success), oracle:1.0 (51%), random (11%). Called by the recipes in scripts/experiments/ (reported in
# docs/experiments/base-policy.md, "The shipped base policy"). Outputs go to $NSL_HOME; re-running resumes.
set -euo pipefail
NSL=${NSL:-.venv/bin/nsl}
$NSL collect --shift base --episodes 4000 --policy oracle:0.5 --data grasp-base-oracle --seed 1 --workers 2 --num-envs 8
$NSL collect --shift base --episodes 2000 --policy oracle:1.0 --data grasp-base-noisy --seed 2 --workers 2 --num-envs 8
$NSL collect --shift base --episodes 2000 --policy random --data grasp-base-random --seed 3 --workers 2 --num-envs 8
