#!/usr/bin/env bash
# The main job, run by `make demo`: the whole nsl pipeline at demo scale (about 8 minutes on 2 cores).
# Outputs go to $NSL_HOME (make sets NSL_HOME=.nsl-demo in the repo); run it again and every step resumes.
set -euo pipefail
NSL=${NSL:-.venv/bin/nsl}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
OUT="$HOME_DIR/demo"
mkdir -p "$OUT"
W=2

echo "== 1. The task and its five shifts (one row per shift, like Fig. 5.2)"
$NSL render --shift all --episodes 4 --out "$OUT/gallery.png"

echo "== 2. Scripted policies on every shift (test objects, 100 episodes each, 95% Wilson intervals)"
$NSL eval --policy random,oracle:0.5,oracle --shift all --episodes 100 --workers $W --markdown | tee "$OUT/scripted.md"

echo "== 3. Base-task data, and harsh-lighting data that the base policy collects itself (the study's protocol)"
NSL=$NSL bash scripts/collect_base_data.sh   # the 8,000 scripted episodes of the base's pre-training data
$NSL collect --shift harsh_lighting@2 --episodes 800 --policy ckpt:base --epsilon 0.1 --data demo-harsh \
  --workers $W --num-envs 8
$NSL dataset tiers demo-harsh --sizes 100,200,400,800

echo "== 4. Pre-train a Q-function offline on the base data (short, to show the command; the shipped base is next)"
$NSL train --data grasp-base-oracle --steps 1000 --n-step 8 --name demo-base

echo "== 5. Fine-tune the shipped base policy (ckpt:base) on its harsh-lighting data, 50/50 with base data"
echo "      (the fine-tuning recipe: 2,000 steps at 25% of the base's rate, conservative term 0.1)"
$NSL train --data grasp-base-oracle=0.27 --data grasp-base-noisy=0.115 --data grasp-base-random=0.115 \
  --data demo-harsh=0.5 --init ckpt:base --name demo-harsh \
  --eval-every 500 --eval-episodes 20 --base-episodes 20 --patience 2 --workers $W

echo "== 6. Evaluate the base and the fine-tuned checkpoints on the same scenes (paired)"
$NSL eval --checkpoint ckpt:base,ckpt:demo-harsh@best --shift base,harsh_lighting@2 --episodes 100 --workers $W

echo "== 7. A two-stage continual run from the base policy: harsh lighting, then transparent objects"
$NSL continual --sequence harsh_lighting@2,transparent_objects@0.8 --init ckpt:base --base-data grasp-base-oracle \
  --episodes 200 --steps 300 --eval-episodes 30 --workers $W --name demo-continual

echo "== 8. Lineage of the last continual stage, and reports"
$NSL catalog lineage ckpt:demo-continual-s2-transparent-objects-0.8@latest | tee "$OUT/lineage.txt"
$NSL report demo-harsh
$NSL report demo-continual
echo "demo outputs: $OUT, $HOME_DIR/runs/demo-harsh/report, $HOME_DIR/runs/demo-continual/report"
