#!/usr/bin/env bash
# A base trained on more rounds of learned-policy data, within the larger budget of 50,000 base-task episodes and
# 2.5 hours of collection and training (docs/experiments/rounds.md, "More and larger rounds"). It extends the 80% recipe
# (pretrain_base_iterated.sh: 10,000 episodes, rounds of 667) to rounds of thousands of episodes:
#
#   round 0   the 8,000 scripted episodes; Monte-Carlo QT-Opt on them                     -> rounds-r0
#   round i   rounds-r(i-1) collects ROUND_i episodes with 10% random actions (seed 10+i) -> grasp-rounds-i,
#             then a policy is trained from scratch on the scripted data and rounds 1..i  -> rounds-ri
#   final     the same training on everything, one run per seed in SEEDS                  -> rounds-final-sS
#
# Every training is the 80% recipe's: Monte-Carlo returns (--n-step 8), 6,000 steps with the rate cosine-decayed
# to 5%, the wider head (hidden 256, 3 layers); the scripted sets take 0.35 / 0.15 / 0.15 of each batch and the
# learned rounds together 0.35, each in proportion to its size. The last round's policy is trained once more per
# seed as the final base (the round's own run is seed 0, so it is reused).
#
# Each step resumes when run again (datasets and finished runs are kept). The wall time of every step is appended
# to $NSL_HOME/rounds-times.tsv; the final command scores every seed on 1,000 selection scenes (seed 3000).
#
#   NSL_HOME=... [ROUNDS="4000 8000 12000 12000"] [SEEDS="0 1 2"] bash scripts/experiments/pretrain_base_rounds.sh
#   NSL_HOME=... bash scripts/experiments/pretrain_base_rounds.sh ship   # copy rounds-r4@6000 into nsl/assets/base
#
# The shipped base (ckpt:base) is seed 0's rounds-r4@6000, chosen on the selection scenes; its command, code version
# and dataset hashes are in nsl/assets/base/command.json.
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
if [ "${1:-}" = ship ]; then
  exec "${PY:-.venv/bin/python}" scripts/experiments/ship_base.py rounds-r4 6000
fi
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
ROUNDS=(${ROUNDS:-4000 8000 12000 12000})
SEEDS=(${SEEDS:-0 1 2})
MC="--steps 6000 --lr-decay 6000 --n-step 8 --crop 2 --net action_dims=0,1,3 --net hidden=256 --net head_layers=3"
SCRIPTED="--data grasp-base-oracle=0.35 --data grasp-base-noisy=0.15 --data grasp-base-random=0.15"
TIMES="$HOME_DIR/rounds-times.tsv"
mkdir -p "$HOME_DIR"

timed() {  # LABEL CMD...: run, and append "label seconds" to the times file
  local label=$1; shift
  local t0; t0=$(date +%s)
  "$@"
  echo -e "$label\t$(( $(date +%s) - t0 ))" >> "$TIMES"
}

learned_mix() {  # I: --data flags of rounds 1..I, sharing 0.35 in proportion to their sizes
  local i total=0 flags=""
  for ((i = 1; i <= $1; i++)); do total=$((total + ROUNDS[i - 1])); done
  for ((i = 1; i <= $1; i++)); do
    flags+=" --data grasp-rounds-$i:${ROUNDS[i - 1]}=$(python3 -c "print(round(0.35 * ${ROUNDS[i - 1]} / $total, 4))")"
  done
  echo "$flags"
}

[ -f "$TIMES" ] || echo -e "step\tseconds" > "$TIMES"
timed scripted env NSL="$NSL" bash scripts/collect_base_data.sh
timed train-r0 $NSL train --data grasp-base-oracle=0.5 --data grasp-base-noisy=0.25 --data grasp-base-random=0.25 \
  $MC --name rounds-r0
n=${#ROUNDS[@]}
for ((i = 1; i <= n; i++)); do
  timed "collect-r$i" $NSL collect --shift base --episodes "${ROUNDS[i - 1]}" --policy "ckpt:rounds-r$((i - 1))@6000" \
    --epsilon 0.1 --data "grasp-rounds-$i" --seed $((10 + i)) --workers 2 --num-envs 8
  timed "train-r$i" $NSL train $SCRIPTED $(learned_mix $i) $MC --name "rounds-r$i"
done
for s in "${SEEDS[@]}"; do
  [ "$s" = 0 ] && continue  # seed 0 of the final training is the last round's run
  timed "final-s$s" $NSL train $SCRIPTED $(learned_mix $n) $MC --seed "$s" --name "rounds-r$n-s$s"
done
refs="ckpt:rounds-r$n@6000"
for s in "${SEEDS[@]}"; do [ "$s" = 0 ] || refs+=",ckpt:rounds-r$n-s$s@6000"; done
$NSL eval --checkpoint "$refs" --episodes 1000 --workers 2 --seed 3000 --json > "$HOME_DIR/rounds-selection.json"
