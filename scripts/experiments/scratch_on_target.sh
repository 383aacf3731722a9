#!/usr/bin/env bash
# What the fine-tuning data can support: a policy trained from scratch, with the shipped base's own recipe
# (pretrain_base_rounds.sh: Monte-Carlo returns, 6,000 steps, rate cosine-decayed, the wider head), on the same
# batch a fine-tune sees: half the base's 44,000 pre-training episodes at their recorded weights, half the 800
# episodes the base collected in the shift (protocol_mc_finetune.sh's data). If it scores no better on the shift
# than the fine-tune, the data, not the base's plasticity, caps the fine-tune (docs/experiments/plateau.md, "Where the
# fine-tunes plateau"). Each run is evaluated on EPISODES (default 400) selection scenes (seed 3000) of its shift and
# of the base task; records go to $NSL_HOME/protocol-scratch/SHIFT.json. About 6 minutes per shift on 2 cores.
#
#   NSL_HOME=<pretrain_base_rounds.sh's workspace> bash scripts/experiments/scratch_on_target.sh [SHIFT ...]
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
OUT="${NSL_HOME:-$HOME/.nsl}/protocol-scratch"
mkdir -p "$OUT"
MC="--steps 6000 --lr-decay 6000 --n-step 8 --crop 2 --net action_dims=0,1,3 --net hidden=256 --net head_layers=3"
source scripts/experiments/rounds_base_half.sh  # $BASE
SHIFTS=("$@")
[ ${#SHIFTS[@]} -gt 0 ] || SHIFTS=(harsh_lighting@2 offset_gripper@0.25)
for s in "${SHIFTS[@]}"; do
  sl=$(echo "$s" | tr '+@_' '---')
  $NSL train $BASE --data "protocol-rounds-$sl-by-base:800=0.5" $MC --name "scratch-$sl"
  [ -s "$OUT/$sl.json" ] || $NSL eval --checkpoint "ckpt:scratch-$sl@6000" --shift "$s,base" \
    --episodes "${EPISODES:-400}" --workers 2 --seed 3000 --json > "$OUT/$sl.json"
done
