#!/usr/bin/env bash
# The main job, run by `make demo`: look at the task, then measure the scripted policies on every shift.
# Outputs go to $NSL_HOME/demo (make sets NSL_HOME=.nsl-demo in the repo).
set -euo pipefail
NSL=${NSL:-.venv/bin/nsl}
OUT="${NSL_HOME:-$HOME/.nsl}/demo"
mkdir -p "$OUT"

echo "== 1. The task and its five shifts (one row per shift, like Fig. 5.2)"
$NSL render --shift all --episodes 4 --out "$OUT/gallery.png"

echo "== 2. Scripted policies on every shift (test objects, 100 episodes each, 95% Wilson intervals)"
$NSL eval --policy random,oracle:0.5,oracle --shift all --episodes 100 --workers 2 --markdown | tee "$OUT/scripted.md"

echo "demo outputs in $OUT"
