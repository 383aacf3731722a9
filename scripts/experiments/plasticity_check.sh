#!/usr/bin/env bash
# Measures how far the demo's fine-tuning moves a base checkpoint on harsh lighting (reported in
# docs/experiments/plasticity.md, "Plasticity of a base"). For each checkpoint ref given, it runs the demo's step-5
# fine-tune (demo-base=0.5 + demo-harsh=0.5, 900 steps at 25% of the parent's rate) without stopping early,
# then evaluates the parent and steps 300 / 600 / 900 on 100 test scenes (seed 2000) of harsh
# lighting and of the base task. About 2 minutes per checkpoint on 2 cores; outputs go to
# $NSL_HOME; a finished fine-tune is not repeated.
#
#   bash scripts/experiments/plasticity_check.sh ckpt:base [ckpt:OTHER@STEP ...]
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
[ $# -ge 1 ] || { echo "usage: $0 CKPT_REF [CKPT_REF ...]  (e.g. ckpt:base)" >&2; exit 2; }

# The demo's two datasets (the same commands as scripts/demo.sh, so the same content hashes; a finished
# collection is not repeated, an interrupted one resumes).
$NSL collect --shift base --episodes 600 --policy oracle:1.0 --data demo-base --workers 2 --num-envs 4
$NSL collect --shift harsh_lighting --episodes 100 --policy oracle:1.0 --data demo-harsh --workers 2 --num-envs 4

for ref in "$@"; do
  # ckpt:NAME@STEP -> plast-NAME-STEP (a valid checkpoint name)
  name="plast-$(echo "${ref#ckpt:}" | tr '@' '-')"
  # --eval-every registers steps 300 / 600 / 900 in the catalog; --patience 100 never stops early.
  $NSL train --data demo-base=0.5 --data demo-harsh=0.5 --init "$ref" --steps 900 --conservative 0 --name "$name" \
    --eval-every 300 --eval-scenes 2000 --eval-episodes 10 --base-episodes 10 --patience 100 --workers 2
  $NSL eval --checkpoint "$ref,ckpt:$name@300,ckpt:$name@600,ckpt:$name@900" \
    --shift harsh_lighting,base --episodes 100 --workers 2 --seed 2000 --markdown \
    | tee "$HOME_DIR/$name.md"
done
