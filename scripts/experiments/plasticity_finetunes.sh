#!/usr/bin/env bash
# The fine-tunes and measurements of docs/experiments/plasticity.md, "Why fine-tuning fails on some shifts: a
# diagnosis".
# The study's protocol from ckpt:base (800 target episodes collected by the base with epsilon 0.1; 1500 steps
# mixed 50/50 with the base's pre-training data), its control without target data, and the remedies tried on
# offset_gripper@0.25; each evaluated on 200 selection scenes (seed 3000, test objects) of its shift and of the
# base task; then plasticity_diagnose.py on the parent and the fine-tunes. About 75 minutes on 2 idle cores
# (each fine-tune 2-3 minutes when the machine is idle); outputs go to $NSL_HOME, a finished step is not redone.
#
#   NSL="python -m nsl" bash scripts/experiments/plasticity_finetunes.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
PY=${PY:-python}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
OUT="$HOME_DIR/plasticity"
mkdir -p "$OUT"
BASE="--data grasp-base-oracle=0.25 --data grasp-base-noisy=0.125 --data grasp-base-random=0.125"

bash scripts/collect_base_data.sh
collect() { [ -d "$HOME_DIR/datasets/$2" ] || $NSL collect --shift "$1" --policy ckpt:base --epsilon 0.1 \
  --episodes 800 --workers 2 --data "$2"; }
collect offset_gripper@0.25 tgt-offset25
collect transparent_objects@0.6 tgt-transp60
collect harsh_lighting tgt-harsh

evaluate() {  # CKPT SHIFTS NAME
  [ -f "$OUT/$3.json" ] || $NSL eval --checkpoint "$1" --shift "$2" --episodes 200 --workers 2 --seed 3000 --json \
    > "$OUT/$3.json"
}
finetune() {  # NAME TARGET_DATA SHIFT [nsl train options]
  local name=$1 data=$2 shift_spec=$3
  shift 3
  $NSL train --init ckpt:base --steps 1500 --conservative 0 $BASE --data "$data=0.5" --name "$name" "$@"
  evaluate "ckpt:$name@latest" "$shift_spec,base" "$name"
}

evaluate ckpt:base offset_gripper@0.25,transparent_objects@0.6,harsh_lighting,base base
# the study's protocol
finetune ft-offset25 tgt-offset25 offset_gripper@0.25
finetune ft-transp60 tgt-transp60 transparent_objects@0.6
finetune ft-harsh tgt-harsh harsh_lighting
# the control: the same fine-tune with the base's data only (no target data)
$NSL train --init ckpt:base --steps 1500 --conservative 0 --data grasp-base-oracle=0.5 --data grasp-base-noisy=0.25 \
  --data grasp-base-random=0.25 --name ft-baseonly
evaluate ckpt:ft-baseonly@latest offset_gripper@0.25,transparent_objects@0.6,harsh_lighting,base ft-baseonly
# remedies on the offset gripper
finetune ft-offset25-lr100 tgt-offset25 offset_gripper@0.25 --lr 3e-4
finetune ft-offset25-n8 tgt-offset25 offset_gripper@0.25 --n-step 8
finetune ft-offset25-cons tgt-offset25 offset_gripper@0.25 --conservative 0.3
finetune ft-offset25-sp tgt-offset25 offset_gripper@0.25 --shrink-perturb 0.8,0.01
# a second seed of the protocol and of the conservative fine-tune
finetune ft-offset25-s1 tgt-offset25 offset_gripper@0.25 --seed 1
finetune ft-offset25-cons-s1 tgt-offset25 offset_gripper@0.25 --conservative 0.3 --seed 1
# the conservative fine-tune on the other shifts, and its control without target data
finetune ft-transp60-cons tgt-transp60 transparent_objects@0.6 --conservative 0.3
$NSL train --init ckpt:base --steps 1500 --conservative 0 --data grasp-base-oracle=0.5 --data grasp-base-noisy=0.25 \
  --data grasp-base-random=0.25 --name ft-baseonly-cons --conservative 0.3
evaluate ckpt:ft-baseonly-cons@latest offset_gripper@0.25,transparent_objects@0.6,base ft-baseonly-cons

# the measurements
$PY scripts/experiments/plasticity_diagnose.py --checkpoint ckpt:base --checkpoint ckpt:ft-offset25@latest \
  --checkpoint ckpt:ft-offset25-lr100@latest --checkpoint ckpt:ft-offset25-n8@latest \
  --checkpoint ckpt:ft-baseonly@latest --data grasp-base-oracle:400 --data tgt-offset25 --transitions 1000 \
  --out "$OUT/diag-offset25.json"
$PY scripts/experiments/plasticity_diagnose.py --checkpoint ckpt:base --checkpoint ckpt:ft-offset25-cons@latest \
  --checkpoint ckpt:ft-offset25-sp@latest --data grasp-base-oracle:400 --data tgt-offset25 --transitions 1000 \
  --out "$OUT/diag-offset25-remedies.json"
$PY scripts/experiments/plasticity_diagnose.py --checkpoint ckpt:base --checkpoint ckpt:ft-transp60@latest \
  --checkpoint ckpt:ft-baseonly@latest --data grasp-base-oracle:400 --data tgt-transp60 --transitions 1000 \
  --out "$OUT/diag-transp60.json"
$PY scripts/experiments/plasticity_diagnose.py --checkpoint ckpt:base --checkpoint ckpt:ft-harsh@latest \
  --data grasp-base-oracle:400 --data tgt-harsh --transitions 1000 --out "$OUT/diag-harsh.json"
# paired comparisons (McNemar)
$NSL eval --checkpoint ckpt:ft-offset25@latest,ckpt:ft-baseonly@latest --shift offset_gripper@0.25,base \
  --episodes 200 --workers 2 --seed 3000
$NSL eval --checkpoint ckpt:ft-offset25-cons@latest,ckpt:ft-offset25@latest --shift offset_gripper@0.25,base \
  --episodes 200 --workers 2 --seed 3000
$NSL eval --checkpoint ckpt:ft-offset25-cons@latest,ckpt:ft-baseonly-cons@latest --shift offset_gripper@0.25 \
  --episodes 200 --workers 2 --seed 3000
