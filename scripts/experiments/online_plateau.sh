#!/usr/bin/env bash
# Online rounds as a lever on the fine-tuning plateau (docs/experiments/plateau.md, "Online rounds"). On each shift,
# `nsl online` from the shipped base with the `online` study plan's protocol: 800 grasps a round collected by the
# current policy with 10% random actions, STEPS (500) gradient steps a round on everything collected so far, half of
# every batch the base's scripted pre-training data at its weights 0.35 : 0.15 : 0.15 (ratio 0.5), training in CPU
# bfloat16 where the CPU has it (--precision auto, as the study plans), ROUNDS rounds, training seeds SEEDS (round i
# collects with scene seed SEED + i, so seeds 10 apart never share scenes).
#
#   select (default)  every round is scored on EVAL (200) selection scenes of seed 3000; prints one line per
#                     (shift, seed): the success after rounds 0..ROUNDS. Choose the round on their mean.
#   REPORT=R          scores round R of every run on EVAL (500) final reporting scenes of seed 51425, on the shift
#                     and on the base task, in fp32 like the study's tables, into RUN/report-rR-eEVAL.json.
# scripts/experiments/online_plateau_table.py prints both tables from the runs' files.
# Needs the base-data datasets grasp-base-oracle, grasp-base-noisy, grasp-base-random in $NSL_HOME (the `online`
# or `full` study plan collects them; scripts/collect_base_data.sh too).
#
#   NSL_HOME=... SEEDS="0 10 20" ROUNDS=3 bash scripts/experiments/online_plateau.sh              # 15 runs
#   NSL_HOME=... SEEDS="0 10 20" ROUNDS=3 REPORT=3 EVAL=500 bash scripts/experiments/online_plateau.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
PY=${PY:-.venv/bin/python}
SHIFTS=${SHIFTS:-"harsh_lighting@2 transparent_objects@0.8 checkerboard_backing@0.4 extend_gripper@2 offset_gripper@0.25"}
ROUNDS=${ROUNDS:-3}
STEPS=${STEPS:-500}
SEEDS=${SEEDS:-0}
REPORT=${REPORT:-}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
if [ -n "$REPORT" ]; then  # the base itself on the same scenes, for the paired comparison
  out="$HOME_DIR/runs/onp-base-report-e${EVAL:-500}.json"
  if [ ! -s "$out" ]; then
    mkdir -p "$HOME_DIR/runs"
    $NSL eval --checkpoint ckpt:base --shift "base,${SHIFTS// /,}" --episodes "${EVAL:-500}" --seed 51425 --workers 2 \
      --json > "$out.tmp"
    mv "$out.tmp" "$out"
  fi
fi
for seed in $SEEDS; do
  for s in $SHIFTS; do
    name="onp-$(echo "$s" | tr '+@_.' '----')-r$ROUNDS-k$STEPS-auto-s$seed"
    rounds="$HOME_DIR/runs/$name/rounds.json"
    if [ -z "$REPORT" ]; then
      $NSL online --shift "$s" --rounds "$ROUNDS" --episodes 800 --steps "$STEPS" --ratio 0.5 --seed "$seed" \
        --precision auto \
        --base-data grasp-base-oracle=0.35 --base-data grasp-base-noisy=0.15 --base-data grasp-base-random=0.15 \
        --eval-episodes "${EVAL:-200}" --eval-scenes 3000 --workers 2 --name "$name" > /dev/null
      line=$($PY -c "import json,sys; print(' '.join(f\"{r['success']:.3f}\" for r in json.load(open(sys.argv[1]))))" "$rounds")
      echo "$s seed $seed, rounds 0..$ROUNDS on selection scenes: $line"
    else
      out="$HOME_DIR/runs/$name/report-r$REPORT-e${EVAL:-500}.json"
      if [ ! -s "$out" ]; then
        ckpt=$($PY -c "import json,sys; print(json.load(open(sys.argv[1]))[int(sys.argv[2])]['checkpoint'])" "$rounds" "$REPORT")
        $NSL eval --checkpoint "$ckpt" --shift "$s,base" --episodes "${EVAL:-500}" --seed 51425 --workers 2 --json > "$out.tmp"
        mv "$out.tmp" "$out"
      fi
      echo "$s seed $seed round $REPORT: $(cat "$out")"
    fi
  done
done
