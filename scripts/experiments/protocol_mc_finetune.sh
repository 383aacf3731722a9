#!/usr/bin/env bash
# The study's protocol on the rounds base (scripts/experiments/protocol_rounds.toml) with one change to the
# fine-tune: Monte-Carlo returns and the base's own crop (--n-step 8 --crop 2), as the base was trained, instead of
# nsl train's one-step default (docs/experiments/fine-tuning.md, "Fine-tuning the rounds base"). Same data (the 800
# episodes the study plan's run collected per shift, the base's 44,000 pre-training episodes at half their recorded
# weights), same steps and rate; each fine-tune is evaluated on 200 selection scenes (seed 3000) of its shift and of the
# base task. Runs in the workspace of pretrain_base_rounds.sh after `nsl study run
# scripts/experiments/protocol_rounds.toml`. About 1.5 minutes per shift on 2 cores; evaluation records go to
# $NSL_HOME/protocol-mc/*.json.
#
#   bash scripts/experiments/protocol_mc_finetune.sh [NAME OPTION...]
#
# With arguments, NAME names the variant (runs NAME-SHIFT, records in $NSL_HOME/protocol-NAME/) and the options
# replace "--n-step 8 --crop 2" (a later --steps overrides the 1,000 steps), e.g. `mcn8 --n-step 8` for Monte-Carlo
# returns at the default crop. SHIFTS="harsh_lighting offset_gripper@0.25" restricts a variant to some shifts (a
# shift's data must exist: protocol-rounds-SHIFT-by-base), EPISODES=400 evaluates on more scenes (default 200), and
# BASE_HALF=scripted makes the base half the 8,000 scripted episodes alone, at their relative pre-training weights
# (what a fresh workspace can collect again; the study plans use it). BASE_HALF=own makes it the scripted episodes
# at half their weight and 8,000 base-task episodes collected by the base itself with 10% random actions
# (grasp-base-own, collected first if missing), as the rounds mixed scripted and learned-policy data. EPSILON=0.3
# replaces each shift's data with 800 episodes the base collects with that chance of a random action per step
# (protocol-eps0.3-SHIFT-by-base, collected first, seed 5) instead of the study's 10%; TARGET_EPISODES=1600 collects
# that many instead of the protocol's 800 (protocol-eps0.1-n1600-SHIFT-by-base, the same seed as the study's 800).
# NOISE=0.3 adds Gaussian noise of that std to every action of the collection (nsl collect --action-noise;
# protocol-epsE-noise0.3-SHIFT-by-base, seed 5): local exploration near the base's own actions; EPSILON=0 NOISE=0.3
# explores with that noise alone.
# INIT=ckpt:OTHER fine-tunes another parent on the same data (the base still collects it).
# SHIFTS=base is a null fine-tune: the target half is the first 800 of those 8,000 base-task episodes the base
# collected, and only the base task is scored.
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
VARIANT=${1:-mcft}
[ $# -gt 0 ] && shift
OPTIONS=("$@")
[ ${#OPTIONS[@]} -gt 0 ] || OPTIONS=(--n-step 8 --crop 2)
OUT="${NSL_HOME:-$HOME/.nsl}/protocol-$([ "$VARIANT" = mcft ] && echo mc || echo "$VARIANT")"
mkdir -p "$OUT"
source scripts/experiments/rounds_base_half.sh  # $BASE
[ "${BASE_HALF:-}" = scripted ] && BASE="--data grasp-base-oracle=0.26923 --data grasp-base-noisy=0.11538
      --data grasp-base-random=0.11538"
own_base_task() {  # 8,000 base-task episodes the base collects itself (resumes, or does nothing, when they exist)
  $NSL collect --shift base --episodes 8000 --policy ckpt:rounds-r4@6000 --epsilon 0.1 --data grasp-base-own --seed 20 \
    --workers 2 --num-envs 8
}
if [ "${BASE_HALF:-}" = own ]; then
  own_base_task
  BASE="--data grasp-base-oracle=0.175 --data grasp-base-noisy=0.075 --data grasp-base-random=0.075
        --data grasp-base-own=0.175"
fi
for s in ${SHIFTS:-harsh_lighting transparent_objects@0.8 checkerboard_backing@0.4 extend_gripper@2 offset_gripper@0.25}; do
  sl=$(echo "$s" | tr '+@_' '---')
  target="protocol-rounds-$sl-by-base:800"
  evals="$s,base"
  if [ "$s" = base ]; then  # a null fine-tune: the target half is 800 base-task episodes the base collected
    own_base_task
    target="grasp-base-own:800"
    evals=base
  fi
  if [ -n "${EPSILON:-}${TARGET_EPISODES:-}${NOISE:-}" ] && [ "$s" != base ]; then
    n=${TARGET_EPISODES:-800}
    target="protocol-eps${EPSILON:-0.1}${NOISE:+-noise$NOISE}-$sl-by-base"
    [ "$n" = 800 ] || target="protocol-eps${EPSILON:-0.1}${NOISE:+-noise$NOISE}-n$n-$sl-by-base"
    $NSL collect --shift "$s" --episodes "$n" --policy ckpt:rounds-r4@6000 --epsilon "${EPSILON:-0.1}" \
      ${NOISE:+--action-noise $NOISE} --data "$target" --seed 5 --workers 2 --num-envs 8
  fi
  $NSL train --init "${INIT:-ckpt:rounds-r4@6000}" --steps 1000 --conservative 0 $BASE --data "$target=0.5" \
    --checkpoint-every 500 "${OPTIONS[@]}" --name "$VARIANT-$sl"
  [ -s "$OUT/$sl.json" ] || $NSL eval --checkpoint "ckpt:$VARIANT-$sl@latest" --shift "$evals" --episodes "${EPISODES:-200}" \
    --workers 2 --seed 3000 --json > "$OUT/$sl.json"
done
