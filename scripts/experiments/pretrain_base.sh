#!/usr/bin/env bash
# Reproduces the one-step base that shipped before the rounds base (base-flat@6000: 70% on 200 reporting scenes;
# docs/experiments/base-policy.md, "The one-step base"). About 6 minutes of collection and under an hour of training
# on 2 cores.
# Outputs go to $NSL_HOME. Every step resumes when run again. `bash scripts/experiments/pretrain_base.sh ship` would
# copy its step-6000 checkpoint into nsl/assets/base in place of the shipped base.
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
PY=${PY:-.venv/bin/python}

if [ "${1:-}" != "ship" ]; then
  # 8,000 scripted base-task episodes on the train objects.
  NSL=$NSL bash scripts/collect_base_data.sh

  # Offline QT-Opt from scratch, mixed 50/25/25, evaluated on 50 test-object episodes every 2,000 steps.
  # The shipped weights are this run's checkpoint at step 6,000 (success peaks there and then declines;
  # docs/experiments/base-policy.md, "What limits the base"). Stop it with Ctrl-C after step 6,000 if you only want those; it resumes when re-run.
  $NSL train --data grasp-base-oracle=0.5 --data grasp-base-noisy=0.25 --data grasp-base-random=0.25 --steps 20000 --eval-every 2000 --eval-scenes 2000 --eval-episodes 50 --patience 100 --crop 2 --name base-flat --net action_dims=0,1,3
  exit 0
fi

# ship: the step-6000 checkpoint, its recipe, and the environment it was trained in.
exec "$PY" scripts/experiments/ship_base.py base-flat 6000
