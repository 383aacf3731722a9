#!/usr/bin/env bash
# IQL against QT-Opt on the study's protocol (docs/learners.md, "A second learner: implicit Q-learning"):
#
#   pre-training  each learner from scratch on the 8,000 scripted base-task episodes (seeds BASE_SEEDS, default 0),
#                 with the Monte-Carlo base recipe (--n-step 8, 6,000 steps, rate cosine-decayed, hidden 256, 3 head
#                 layers)
#   target data   each learner's seed-0 base collects 800 episodes (10% random actions) on each of two shifts
#   fine-tuning   that base, fine-tuned by the same learner with the fine-tuning recipe, the 800 episodes mixed
#                 50/50 with the base data, seeds 0-2
#   scoring       every checkpoint on 1,000 selection scenes (seed 3000): bases on the base task and both shifts,
#                 fine-tunes on their shift
#
# Every step resumes when run again; results are JSON files in $NSL_HOME/learners/, which
# `python scripts/experiments/learners_table.py $NSL_HOME/learners` turns into the table. About 25 minutes on 2 cores
# per learner and base seed (float32).
#
#   NSL_HOME=... [LEARNERS="qtopt iql"] [BASE_SEEDS="0"] [SHIFTS="harsh_lighting@2 offset_gripper@0.25"] \
#       bash scripts/experiments/learners_table.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
OUT="$HOME_DIR/learners"
LEARNERS=(${LEARNERS:-qtopt iql})
SHIFTS=(${SHIFTS:-harsh_lighting@2 offset_gripper@0.25})
BASE_SEEDS=(${BASE_SEEDS:-0})
SEEDS=(0 1 2)
SCENES="--episodes 1000 --seed 3000 --workers 2"
RECIPE="--steps 6000 --lr-decay 6000 --n-step 8 --crop 2 --net action_dims=0,1,3 --net hidden=256 --net head_layers=3"
BASE_MIX="--data grasp-base-oracle=0.5 --data grasp-base-noisy=0.25 --data grasp-base-random=0.25"
FT_BASE_MIX="--data grasp-base-oracle=0.25 --data grasp-base-noisy=0.125 --data grasp-base-random=0.125"
mkdir -p "$OUT"

scored() {  # FILE ARGS...: nsl eval ARGS on the selection scenes into FILE (skipped when FILE exists)
  local file=$1; shift
  if [ ! -s "$file" ]; then
    $NSL eval "$@" $SCENES --json > "$file.tmp"
    mv "$file.tmp" "$file"
  fi
}

NSL="$NSL" bash scripts/collect_base_data.sh
for L in "${LEARNERS[@]}"; do
  bases=""
  for s in "${BASE_SEEDS[@]}"; do
    $NSL train --learner "$L" $BASE_MIX $RECIPE --seed "$s" --name "$L-base-s$s"
    bases+="${bases:+,}ckpt:$L-base-s$s@6000"
  done
  scored "$OUT/$L-bases.json" --checkpoint "$bases" --shift "base,$(IFS=,; echo "${SHIFTS[*]}")"
  for S in "${SHIFTS[@]}"; do
    tag="${S%@*}"
    $NSL collect --shift "$S" --episodes 800 --policy "ckpt:$L-base-s0@6000" --epsilon 0.1 --data "$L-$tag" \
      --seed 5 --workers 2 --num-envs 8
    fts=""
    for s in "${SEEDS[@]}"; do
      $NSL train --learner "$L" --init "ckpt:$L-base-s0@6000" --data "$L-$tag:800=0.5" $FT_BASE_MIX \
        --seed "$s" --name "$L-$tag-s$s"
      fts+="${fts:+,}ckpt:$L-$tag-s$s"
    done
    scored "$OUT/$L-$tag.json" --checkpoint "$fts" --shift "$S"
  done
done
