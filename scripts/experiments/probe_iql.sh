#!/usr/bin/env bash
# The study's fine-tune with implicit Q-learning's targets (probe_iql.py) on the recipe's data: the base's 44,000
# pre-training episodes as the base half and the 800 episodes the base collected in each shift, 1,000 steps after
# a 300-step V warm-up; each result scored on the 400 selection scenes (seed 3000) of the shift and of the base task,
# as protocol_mc_finetune.sh's variants are (docs/experiments/plateau.md, "Where the fine-tunes plateau"). Results go to
# $NSL_HOME/protocol-iql/SHIFT-tauTAU.txt; about 3 minutes per shift and expectile on 2 cores.
#
#   NSL_HOME=<pretrain_base_rounds.sh's workspace> [TAUS="0.8"] [SHIFTS="harsh_lighting@2 offset_gripper@0.25"] \
#       bash scripts/experiments/probe_iql.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=${PY:-.venv/bin/python}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
OUT="$HOME_DIR/protocol-iql"
mkdir -p "$OUT"
source scripts/experiments/rounds_base_half.sh  # $BASE
for tau in ${TAUS:-0.8}; do
  for s in ${SHIFTS:-harsh_lighting@2 offset_gripper@0.25}; do
    sl=$(echo "$s" | tr '+@_' '---')
    dir="$OUT/runs/$sl-tau$tau"
    [ -f "$dir/config.json" ] || "$PY" scripts/experiments/probe_iql.py --init ckpt:rounds-r4@6000 $BASE \
      --data "protocol-rounds-$sl-by-base:800=0.5" --tau "$tau" --out "$dir"
    rec="$OUT/$sl-tau$tau.txt"
    [ -s "$rec" ] || { for task in "$s" base; do
        "$PY" scripts/experiments/probe_policies.py cem --shift "$task" --episodes 400 --seed 3000 --workers 2 "$dir"
      done > "$rec.tmp" && mv "$rec.tmp" "$rec"; }
    cat "$rec"
  done
done
