#!/usr/bin/env bash
# Whether this tree's CPU training step gives the same weights, bit for bit, as the step at another commit.
# Trains the same 30-step run (default network, batch 64, conservative term 0.1, lagged copy every 7 steps, one
# thread, synthetic transitions) with both trees and prints the SHA-256 of each run's final weights and its last
# metrics row.  Used to check that adding `--device` left the CPU path as it was (docs/benchmarks.md).
#   bash scripts/experiments/cpu_step_against_commit.sh bad7c6e
set -euo pipefail
COMMIT=${1:?give the commit to compare with, e.g. bad7c6e}
PY=${PY:-.venv/bin/python}
WORK=$(mktemp -d)
trap 'git worktree remove --force "$WORK/tree" >/dev/null 2>&1 || true; rm -rf "$WORK"' EXIT
git worktree add --detach -q "$WORK/tree" "$COMMIT"
cat > "$WORK/run.py" <<'PYEOF'
import hashlib, tempfile
import torch
import nsl
from nsl.learners import NetConfig, TrainConfig, load_checkpoint, synthetic_sampler, train
torch.set_num_threads(1)
cfg = TrainConfig(steps=30, seed=3, conservative=0.1, log_every=10, checkpoint_every=30, lag_period=7)
with tempfile.TemporaryDirectory() as d:
    r = train(cfg, synthetic_sampler(256, 1, 64), d, net=NetConfig(), progress=False)
    sd = load_checkpoint(r.checkpoint).net.state_dict()
    digest = hashlib.sha256(b"".join(v.numpy().tobytes() for v in sd.values())).hexdigest()
print(nsl.__file__, digest, {k: round(v, 7) for k, v in r.metrics.items() if not k.startswith("charts/")})
PYEOF
for tree in "$WORK/tree" "$PWD"; do
  PKG=$(mktemp -d -p "$WORK")
  mkdir "$PKG/nsl" && cp -r "$tree/nsl/." "$PKG/nsl/"
  for d in catalog cluster collectors curriculum datasets eval learners services share study; do
    ln -s "$tree/$d" "$PKG/nsl/$d"
  done
  (cd "$WORK" && PYTHONPATH="$PKG" "$OLDPWD/$PY" run.py)
done
