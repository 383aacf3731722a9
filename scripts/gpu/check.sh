#!/usr/bin/env bash
# nsl's figures on a GPU machine that has torch and numpy but not nsl's other dependencies (the device tool's
# machine); sized to run in under 9 minutes on an H100 or H200.  What it measures, into $OUT:
#   bench-learner.json   nsl bench learner --device cuda: steps/s of the QT-Opt step, eager and as one CUDA
#                        graph, at batch 64 and 1,024 in fp32 and bf16; transitions/s; the profiler's kernel time
#                        a step, the busy fraction and the kernel-time limit; the matmul peak of each precision
#   bench-eval.json      nsl bench eval --device cuda: CEM acting, one state a call against 64 a call
#   ft-s{0,1,2}.pt       with build/gpu/ from `python scripts/gpu/finetune.py export build/gpu ...` carried: the
#                        recipe's 2,000-step fine-tune of the exported base on the exported data, per seed, with
#                        its wall time (import them here with `scripts/gpu/finetune.py import`)
#   tests.txt            the tests marked cuda (tests/learners/test_device.py), where pytest is installed
# Run from the repository root through the device tool:
#   run(command="bash scripts/gpu/check.sh", carry=["build/gpu"], timeout_s=560)
set -euo pipefail
OUT=${OUT:-/tmp/nsl-gpu}
mkdir -p "$OUT"
PY=${PY:-python3}

# nsl without installing it: its folders are the subpackages that pyproject.toml maps.
PKG=$(mktemp -d)
mkdir "$PKG/nsl"
cp -r nsl/. "$PKG/nsl/"
for d in catalog cluster collectors curriculum datasets eval learners services share study; do
  ln -s "$PWD/$d" "$PKG/nsl/$d"
done
export PYTHONPATH="$PKG${PYTHONPATH:+:$PYTHONPATH}"

(nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv || echo "no nvidia-smi") | tee "$OUT/gpu.txt"
$PY -c "import torch; print('torch', torch.__version__, 'cuda', torch.version.cuda)" | tee -a "$OUT/gpu.txt"

timeout 240 $PY -m nsl bench learner --device cuda --json | tee "$OUT/bench-learner.json"
timeout 60 $PY -m nsl bench eval --device cuda --json | tee "$OUT/bench-eval.json"

if [ -f build/gpu/data.npz ]; then
  for seed in 0 1 2; do
    timeout 60 $PY scripts/gpu/finetune.py train build/gpu --seed "$seed" --device cuda --out "$OUT/ft-s$seed.pt" \
      | tee -a "$OUT/finetune.jsonl"
  done
fi

if $PY -c "import pytest" 2>/dev/null; then
  timeout 60 $PY -m pytest -q -p no:cacheprovider -m cuda tests/learners/test_device.py > "$OUT/tests.txt" 2>&1 || true
fi
echo "done: $(ls "$OUT")"
