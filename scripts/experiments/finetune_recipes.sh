#!/usr/bin/env bash
# One fine-tuning recipe for every shift: the study's protocol against conservative variants, on the five
# shifts at the severities the `full` study plan calibrated (docs/experiments/open-questions.md: not yet run).
# Runs in a workspace that holds a finished `nsl study run full` (its 800-episode collections by the base and
# the base's re-collected pre-training data). Each recipe fine-tunes ckpt:base for 1,000 steps (as the plan),
# 50/50 with the base data, on each shift's 800 episodes; every checkpoint (the study's own protocol runs too)
# is evaluated on 200 selection scenes (seed 3000, test objects) of its shift and of the base task. About
# 15 minutes on 2 idle cores; results go to $NSL_HOME/recipes/*.json, a finished step is not redone.
#
#   NSL_HOME=... NSL="python -m nsl" bash scripts/experiments/finetune_recipes.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
OUT="$HOME_DIR/recipes"
mkdir -p "$OUT"
BASE="--data grasp-base-oracle=0.25 --data grasp-base-noisy=0.125 --data grasp-base-random=0.125"
SHIFTS="harsh_lighting transparent_objects@0.8 checkerboard_backing@0.6 extend_gripper@2.5 offset_gripper@0.35"
slug() { echo "$1" | tr '+@_' '---'; }

evaluate() {  # CKPT SHIFTS NAME
  [ -f "$OUT/$3.json" ] || $NSL eval --checkpoint "$1" --shift "$2" --episodes 200 --workers 2 --seed 3000 --json \
    > "$OUT/$3.json" 2>> "$OUT/progress.log"
}
RECIPES=("cons01 --conservative 0.1" "cons03 --conservative 0.3")
for s in $SHIFTS; do  # the fine-tunes (a finished run is resumed at its last step, i.e. not trained again)
  sl=$(slug "$s")
  for recipe in "${RECIPES[@]}"; do
    set -- $recipe
    name="$1-$sl"; shift
    $NSL train --init ckpt:base --steps 1000 --conservative 0 $BASE --data "full-$sl-by-base=0.5" --name "$name" "$@" \
      2>> "$OUT/progress.log"
  done
done
evaluate ckpt:base "$(echo $SHIFTS | tr ' ' ','),base" base
for s in $SHIFTS; do  # the evaluations; the study's own protocol run as the full study trained it
  sl=$(slug "$s")
  evaluate "ckpt:full-ft-$sl-n800-k1000-s0@latest" "$s,base" "protocol-$sl"
  for recipe in "${RECIPES[@]}"; do
    set -- $recipe
    evaluate "ckpt:$1-$sl@latest" "$s,base" "$1-$sl"
  done
done
python3 scripts/experiments/recipes_table.py "$OUT"
