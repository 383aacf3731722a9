#!/usr/bin/env bash
# Online rounds as a lever on the fine-tuning plateau (docs/experiments/plateau.md, "Online rounds"): on each shift,
# `nsl online` from the shipped base with the study's protocol (800 grasps a round collected by the current policy
# with 10% random actions, 2,000 steps a round at the fine-tuning recipe, half of every batch the base's scripted
# pre-training data at its weights 0.35 : 0.15 : 0.15, ratio 0.5), ROUNDS rounds, seeds SEEDS. Every round is scored
# on EVAL scenes of seed SCENES (default: 200 selection scenes, seed 3000); with SCENES=51425 EVAL=500 (the final
# reporting scenes, once the number of rounds is chosen on the selection scenes) the last round is also scored on
# the base task on the same scenes. Prints one line per (shift, seed): the success after every round.
# Needs the base-data datasets grasp-base-oracle, grasp-base-noisy, grasp-base-random in $NSL_HOME (the `online`
# or `full` study plan collects them; scripts/collect_base_data.sh too). Not yet run: by the study estimate about 6
# minutes per (shift, seed) for 2 rounds on this 2-core machine with bf16 training.
#
#   NSL_HOME=... SHIFTS="transparent_objects@0.8 offset_gripper@0.25" ROUNDS=2 SEEDS="0" \
#     bash scripts/experiments/online_plateau.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
SHIFTS=${SHIFTS:-"harsh_lighting@2 transparent_objects@0.8 checkerboard_backing@0.4 extend_gripper@2 offset_gripper@0.25"}
ROUNDS=${ROUNDS:-2}
SEEDS=${SEEDS:-0}
SCENES=${SCENES:-3000}
EVAL=${EVAL:-200}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
for s in $SHIFTS; do
  sl=$(echo "$s" | tr '+@_.' '----')
  for seed in $SEEDS; do
    name="onp-$sl-r$ROUNDS-s$seed-e$SCENES"
    $NSL online --shift "$s" --rounds "$ROUNDS" --episodes 800 --steps 2000 --ratio 0.5 --seed "$seed" \
      --base-data grasp-base-oracle=0.35 --base-data grasp-base-noisy=0.15 --base-data grasp-base-random=0.15 \
      --eval-episodes "$EVAL" --eval-scenes "$SCENES" --workers 2 --name "$name" > /dev/null
    line=$(python3 -c "import json,sys; r=json.load(open(sys.argv[1])); print(' '.join(f\"{x['success']:.3f}\" for x in r))" \
      "$HOME_DIR/runs/$name/rounds.json")
    echo "$s seed $seed rounds 0..$ROUNDS: $line"
    if [ "$SCENES" != 3000 ]; then
      $NSL eval --checkpoint "ckpt:$name-r$ROUNDS@latest" --shift base --episodes "$EVAL" --seed "$SCENES" \
        --workers 2 --json | python3 -c "import json,sys; print('  base task after:', json.load(sys.stdin))"
    fi
  done
done
