#!/usr/bin/env bash
# The study's protocol with the base's own pre-training data as the base half, on the reporting scenes: the
# fine-tunes of protocol_mc_finetune.sh (the one recipe: 800 episodes the base collected, 1,000 steps at 25% of
# its rate, --n-step 8 --crop 2, half of every batch from its 44,000 pre-training episodes at their recorded
# weights), three fine-tune seeds per shift, scored on the `full` study's 200 reporting scenes (seed 2000) of the
# shift and of the base task, with the base itself on the same scenes (docs/experiments/plateau.md, "The protocol with
# the base's own data"). The target data is the `full` study's: the same content hashes. Seed 0 is
# protocol_mc_finetune.sh's default variant (mcft; mcft4 for harsh lighting@2), seeds 1 and 2 its variants mcs1
# and mcs2, trained first (each also scored on 400 selection scenes, as protocol_mc_finetune.sh does). Records
# go to $NSL_HOME/protocol-reporting/, and the table is printed last; about 16 minutes on 2 cores when seeds 1
# and 2 are all to train. The base task after every fine-tune is also scored on 1,000 reporting scenes, as the base
# itself is (one paired evaluation of all 16 checkpoints, 9 minutes).
#
#   NSL_HOME=<pretrain_base_rounds.sh's workspace> bash scripts/experiments/protocol_reporting.sh [NAME OPTION...]
#
# With arguments, the same for another fine-tuning recipe: OPTIONS replace "--n-step 8 --crop 2", seed 0 is
# protocol_mc_finetune.sh's variant NAME and seeds 1 and 2 its variants NAMEs1 and NAMEs2 (the options and
# --seed N), and records go to $NSL_HOME/protocol-reporting-NAME/; e.g. `mcc01 --n-step 8 --crop 2 --conservative 0.1`.
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
NAME=${1:-}
[ $# -gt 0 ] && shift
OPTIONS=("$@")
[ ${#OPTIONS[@]} -gt 0 ] || OPTIONS=(--n-step 8 --crop 2)
OUT="$HOME_DIR/protocol-reporting${NAME:+-$NAME}"
TASKS=(harsh_lighting@2 transparent_objects@0.8 checkerboard_backing@0.4 extend_gripper@2 offset_gripper@0.25)
mkdir -p "$OUT"
has() { [ -d "$HOME_DIR/checkpoints/$1" ]; }
runs_of() {  # the three seeds' run names for shift slug $1: seed 0, seed 1, seed 2
  if [ -n "$NAME" ]; then echo "$NAME-$1 ${NAME}s1-$1 ${NAME}s2-$1"; return; fi
  local seed0="mcft-$1"; has "mcft4-$1" && seed0="mcft4-$1"
  echo "$seed0 mcs1-$1 mcs2-$1"
}
for seed in 1 2; do  # finished runs and evaluations are kept, so this resumes
  variant="mcs$seed"; [ -n "$NAME" ] && variant="${NAME}s$seed"
  SHIFTS="${TASKS[*]}" EPISODES=400 NSL="$NSL" bash scripts/experiments/protocol_mc_finetune.sh \
    "$variant" "${OPTIONS[@]}" --seed "$seed"
done
seed0_args=(); seed0_episodes=200; [ -n "$NAME" ] && seed0_args=("$NAME" "${OPTIONS[@]}") && seed0_episodes=400
[ -s "$OUT/base.json" ] || $NSL eval --checkpoint ckpt:rounds-r4@6000 --shift "base,$(IFS=,; echo "${TASKS[*]}")" \
  --episodes 200 --workers 2 --seed 2000 --json > "$OUT/base.json"
for s in "${TASKS[@]}"; do
  sl=$(echo "$s" | tr '+@_' '---')
  read -r seed0 _ _ <<< "$(runs_of "$sl")"
  has "$seed0" || NSL="$NSL" SHIFTS="$s" EPISODES=$seed0_episodes bash scripts/experiments/protocol_mc_finetune.sh \
    "${seed0_args[@]}"
  for run in $(runs_of "$sl"); do
    [ -s "$OUT/$run.json" ] || $NSL eval --checkpoint "ckpt:$run@latest" --shift "$s,base" --episodes 200 --workers 2 \
      --seed 2000 --json > "$OUT/$run.json"
  done
done
# The base task after every fine-tune, on 1,000 reporting scenes with the base itself (paired): base-after-1000.json
refs=ckpt:rounds-r4@6000
for s in "${TASKS[@]}"; do
  for run in $(runs_of "$(echo "$s" | tr '+@_' '---')"); do refs+=",ckpt:$run@latest"; done
done
[ -s "$OUT/base-after-1000.json" ] || { $NSL eval --checkpoint "$refs" --shift base --episodes 1000 --workers 2 \
  --seed 2000 --json > "$OUT/base-after-1000.tmp" && mv "$OUT/base-after-1000.tmp" "$OUT/base-after-1000.json"; }
runs=""  # one line per shift: its slug, then its three seeds' run names
for s in "${TASKS[@]}"; do sl=$(echo "$s" | tr '+@_' '---'); runs+="$sl $(runs_of "$sl")"$'\n'; done
RUNS="$runs" "${PY:-.venv/bin/python}" - "$OUT" <<'PY'
import json, os, sys
from pathlib import Path
out = Path(sys.argv[1])
runs_of = {line.split()[0]: line.split()[1:] for line in os.environ["RUNS"].splitlines() if line}
base = json.loads((out / "base.json").read_text())["results"]
kept_1000 = {ref.split(":")[1].split("@")[0]: 100 * v["results"]["base"]["success_rate"]
             for ref, v in json.loads((out / "base-after-1000.json").read_text())["policies"].items()}
own = kept_1000.pop("rounds-r4")
print("| shift | base policy | fine-tuned, seeds 0 / 1 / 2 | mean gain | base task after, 200 scenes (base: %.1f%%) | "
      "base task after, 1,000 scenes (base: %.1f%%) |" % (100 * base["base"]["success_rate"], own))
print("|---|---|---|---|---|---|")
gains, within, within_1000 = [], 0, 0
for shift, cell in base.items():
    if shift == "base":
        continue
    sl = shift.replace("_", "-").replace("@", "-")
    runs = runs_of[sl]
    res = [json.loads((out / f"{r}.json").read_text())["results"] for r in runs]
    after = [100 * r[shift]["success_rate"] for r in res]
    kept = [100 * r["base"]["success_rate"] for r in res]
    gain = sum(after) / 3 - 100 * cell["success_rate"]
    gains.append(gain)
    within += all(100 * base["base"]["success_rate"] - k <= 10 for k in kept)
    kept2 = [kept_1000[r] for r in runs]
    within_1000 += all(own - k <= 10 for k in kept2)
    print(f"| {shift} | {100 * cell['success_rate']:.1f}% | {' / '.join(f'{a:.1f}' for a in after)}% | {gain:+.1f} | "
          f"{' / '.join(f'{k:.1f}' for k in kept)}% | {' / '.join(f'{k:.1f}' for k in kept2)}% |")
print(f"\nmean gain {sum(gains) / len(gains):+.1f} points; base task within 10 points after every seed's fine-tune on "
      f"{within} of {len(gains)} shifts (200 scenes), on {within_1000} of {len(gains)} (1,000 scenes)")
PY
