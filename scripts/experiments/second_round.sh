#!/usr/bin/env bash
# What caps a fine-tune with Monte-Carlo returns: one round of data allows one step of policy improvement.
# For each shift, the recipe's fine-tune (protocol_mc_finetune.sh's seed-0 run, VARIANT) collects 800 more episodes
# in the shift with 10% random actions, as the base did (protocol-round2-SHIFT, seed 6); then the base is fine-tuned
# again with the recipe on both target sets (0.25 each, the base half unchanged) and scored on the same 400 selection
# scenes (seed 3000) of the shift and of the base task. Outside the study's protocol, which lets only the base
# collect: it tests whether the target data's own policy, not the learner, sets the plateau
# (docs/experiments/plateau.md, "Where the fine-tunes plateau"). Records go to $NSL_HOME/protocol-round2/; about 2.5
# minutes per shift.
#
#   NSL_HOME=<pretrain_base_rounds.sh's workspace> [SHIFTS="harsh_lighting@2 offset_gripper@0.25"] [VARIANT=mcft4] \
#       bash scripts/experiments/second_round.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
OUT="${NSL_HOME:-$HOME/.nsl}/protocol-round2"
mkdir -p "$OUT"
source scripts/experiments/rounds_base_half.sh  # $BASE
for s in ${SHIFTS:-harsh_lighting@2 offset_gripper@0.25}; do
  sl=$(echo "$s" | tr '+@_' '---')
  first="${VARIANT:-mcft4}-$sl"
  [ -d "${NSL_HOME:-$HOME/.nsl}/checkpoints/$first" ] || first="mcft-$sl"
  $NSL collect --shift "$s" --episodes 800 --policy "ckpt:$first@latest" --epsilon 0.1 --data "protocol-round2-$sl" \
    --seed 6 --workers 2 --num-envs 8
  $NSL train --init ckpt:rounds-r4@6000 --steps 1000 --conservative 0 $BASE --data "protocol-rounds-$sl-by-base:800=0.25" \
    --data "protocol-round2-$sl=0.25" --checkpoint-every 500 --n-step 8 --crop 2 --name "round2-$sl"
  [ -s "$OUT/$sl.json" ] || $NSL eval --checkpoint "ckpt:round2-$sl@latest" --shift "$s,base" --episodes 400 \
    --workers 2 --seed 3000 --json > "$OUT/$sl.json"
done
