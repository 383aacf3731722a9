#!/usr/bin/env bash
# Which data fine-tunes the shipped base (docs/experiments/plasticity.md, "Plasticity of a base"): the demo's fine-tune
# of ckpt:base (900 steps at 25% of its rate, Monte-Carlo returns as the base was trained; evaluated at steps 300 / 600
# / 900 on 100 reporting scenes of the target shift and of the base task) with two kinds of data:
#
#   own-small  600 base-task and 200 harsh-lighting episodes, both collected by ckpt:base with 10% random actions
#   scripted   the 8,000 scripted base-task episodes (scripts/collect_base_data.sh) at the base's relative weights,
#              and the first 400 of 800 harsh_lighting@2 episodes collected by ckpt:base (seed 5, as the study plans)
#
# (scripts/experiments/plasticity_check.sh measures the third kind: the demo's former scripted oracle:1.0 data.)
# Runs on one thread (OMP_NUM_THREADS=1), as measured; about 10 minutes on a quiet machine. Outputs go to $NSL_HOME.
#
#   bash scripts/experiments/finetune_data_check.sh [own-small|scripted]...   (default: both)
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
export OMP_NUM_THREADS=1
for variant in "${@:-own-small scripted}"; do
  for v in $variant; do
    if [ "$v" = own-small ]; then
      $NSL collect --shift base --episodes 600 --policy ckpt:base --epsilon 0.1 --data own-base --workers 1 --num-envs 4
      $NSL collect --shift harsh_lighting --episodes 200 --policy ckpt:base --epsilon 0.1 --data own-harsh --workers 1 \
        --num-envs 4
      data=(--data own-base=0.5 --data own-harsh=0.5); shift=harsh_lighting
    elif [ "$v" = scripted ]; then
      NSL=$NSL bash scripts/collect_base_data.sh
      $NSL collect --shift harsh_lighting@2 --episodes 800 --policy ckpt:base --epsilon 0.1 --seed 5 \
        --data own-harsh-2 --workers 2 --num-envs 8
      data=(--data grasp-base-oracle=0.26923 --data grasp-base-noisy=0.11538 --data grasp-base-random=0.11538
            --data own-harsh-2:400=0.5); shift=harsh_lighting@2
    else
      echo "unknown variant $v: use own-small or scripted" >&2; exit 2
    fi
    $NSL train "${data[@]}" --init ckpt:base --steps 900 --conservative 0 --name "data-$v" \
      --eval-every 300 --eval-scenes 2000 --eval-episodes 20 --base-episodes 20 --patience 100 --workers 1
    $NSL eval --checkpoint "ckpt:base,ckpt:data-$v@300,ckpt:data-$v@600,ckpt:data-$v@900" --shift "base,$shift" \
      --episodes 100 --workers 1 --seed 2000 --markdown
  done
done
