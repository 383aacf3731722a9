#!/usr/bin/env bash
# The main job, run by `make demo`: the whole nsl pipeline at demo scale (about 10 minutes on 2 cores).
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

echo "== 3. Collect a base dataset and a small harsh-lighting target dataset (versioned LeRobot v3.0 datasets)"
$NSL collect --shift base --episodes 600 --policy oracle:1.0 --data demo-base --workers $W --batch-size 4
$NSL collect --shift harsh_lighting --episodes 100 --policy oracle:1.0 --data demo-harsh --workers $W --batch-size 4
$NSL dataset tiers demo-harsh --sizes 25,50,100

echo "== 4. Pre-train a Q-function offline on the base data (short, to show the command; the shipped base is next)"
$NSL train --data demo-base --steps 1000 --name demo-base

echo "== 5. Fine-tune the shipped base policy (ckpt:base) on harsh lighting, 50/50 with base data, early stopping"
$NSL train --data demo-base=0.5 --data demo-harsh=0.5 --init ckpt:base --steps 900 --name demo-harsh \
  --eval-every 300 --eval-episodes 20 --base-episodes 20 --patience 2 --workers $W

echo "== 6. Evaluate the base and the fine-tuned checkpoints on the same scenes (paired)"
$NSL eval --checkpoint ckpt:base,ckpt:demo-harsh@best --shift base,harsh_lighting --episodes 50 --workers $W

echo "== 7. A two-stage continual run from the base policy: harsh lighting, then transparent objects"
$NSL continual --sequence harsh_lighting,transparent_objects --init ckpt:base --base-data demo-base \
  --episodes 60 --steps 300 --eval-episodes 30 --workers $W --name demo-continual

echo "== 8. Lineage of the last continual stage, and reports"
$NSL catalog lineage ckpt:demo-continual-s2-transparent-objects@latest | tee "$OUT/lineage.txt"
$NSL report demo-harsh
$NSL report demo-continual
echo "demo outputs: $OUT, $HOME_DIR/runs/demo-harsh/report, $HOME_DIR/runs/demo-continual/report"
