#!/usr/bin/env bash
# The study's protocol with early stopping chosen on selection scenes (docs/experiments/plateau.md, "Early stopping from
# the shipped base"). The fine-tunes are protocol_reporting.sh's (the one recipe, seeds 0 / 1 / 2, the base's 44,000
# pre-training episodes as the base half), run again with an evaluation every 250 steps on 200 selection scenes
# (--eval-scenes 3000) of the shift and of the base task; patience 4 lets every run reach step 1,000. Two rules pick a
# step from each curve (step 0 is the base itself):
#   best    the highest success on the shift (nsl train's early stopping, ckpt:NAME@best);
#   guard   the same among the steps whose base-task success is within 5 points of the base's on those scenes.
# Each chosen step is then scored on the `full` study's reporting scenes (seed 2000): 200 on the shift, 1,000 on the
# base task. Records go to $NSL_HOME/protocol-early-stop/; the table is printed last. About 45 minutes on 2 cores.
#
#   NSL_HOME=<pretrain_base_rounds.sh's workspace> bash scripts/experiments/protocol_early_stop.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
PY=${PY:-.venv/bin/python}
HOME_DIR="${NSL_HOME:-$HOME/.nsl}"
OUT="$HOME_DIR/protocol-early-stop"
TASKS=(${SHIFTS:-harsh_lighting@2 transparent_objects@0.8 checkerboard_backing@0.4 extend_gripper@2 offset_gripper@0.25})
source scripts/experiments/rounds_base_half.sh  # $BASE
mkdir -p "$OUT"
choose() {  # RUN RULE -> the chosen step (0 = the base)
  "$PY" - "$HOME_DIR/runs/$1/curve.csv" "$2" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
base0 = float(rows[0]["base_success"])
ok = [r for r in rows if sys.argv[2] == "best" or float(r["base_success"]) >= base0 - 0.05]
print(max(ok, key=lambda r: (float(r["target_success"]), -int(r["step"])))["step"])
PY
}
score() {  # REF SHIFT: the reporting scenes, 200 on the shift and 1,000 on the base task -> $OUT/REF.json
  local key; key=$(echo "$1" | tr ':@' '--')
  [ -s "$OUT/$key.json" ] && return 0
  $NSL eval --checkpoint "$1" --shift "$2" --episodes 200 --workers 2 --seed 2000 --json > "$OUT/$key.shift.tmp"
  $NSL eval --checkpoint "$1" --shift base --episodes 1000 --workers 2 --seed 2000 --json > "$OUT/$key.base.tmp"
  "$PY" -c "import json, sys; a, b, o = sys.argv[1:]; r = json.load(open(a)); r['results'].update(json.load(open(b))['results'])
json.dump(r, open(o + '.tmp', 'w'))" "$OUT/$key.shift.tmp" "$OUT/$key.base.tmp" "$OUT/$key.json"
  mv "$OUT/$key.json.tmp" "$OUT/$key.json" && rm "$OUT/$key.shift.tmp" "$OUT/$key.base.tmp"
}
score ckpt:rounds-r4@6000 "$(IFS=,; echo "${TASKS[*]}")"
for s in "${TASKS[@]}"; do
  sl=$(echo "$s" | tr '+@_' '---')
  for seed in 0 1 2; do
    run="es-s$seed-$sl"
    [ -f "$HOME_DIR/runs/$run/early_stop.json" ] && [ "$(tail -1 "$HOME_DIR/runs/$run/curve.csv" | cut -d, -f1)" = 1000 ] ||
      $NSL train --init ckpt:rounds-r4@6000 --steps 1000 --conservative 0 $BASE --data "protocol-rounds-$sl-by-base:800=0.5" \
        --n-step 8 --crop 2 --seed "$seed" --checkpoint-every 250 --eval-every 250 --eval-episodes 200 \
        --base-episodes 200 --eval-scenes 3000 --patience 4 --workers 2 --name "$run"
    for rule in best guard; do
      step=$(choose "$run" "$rule")
      ref="ckpt:$run@$step"; [ "$step" = 0 ] && ref="ckpt:rounds-r4@6000"
      echo "$ref" > "$OUT/$run.$rule"
      score "$ref" "$s"
    done
  done
done
"$PY" - "$OUT" "$HOME_DIR" "${TASKS[@]}" <<'PY'
import json, sys
from pathlib import Path
out, home, tasks = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3:]
def res(ref):
    return json.loads((out / (ref.replace(":", "-").replace("@", "-") + ".json")).read_text())["results"]
parent = "ckpt:rounds-r4@6000"
for rule in ("best", "guard"):
    print(f"\nrule {rule}: | shift | base policy | chosen steps | fine-tuned, seeds 0 / 1 / 2 | mean gain | base task after (1,000 scenes) |")
    gains, within = [], 0
    for s in tasks:
        sl = s.replace("_", "-").replace("@", "-")
        refs = [(out / f"es-s{seed}-{sl}.{rule}").read_text().strip() for seed in (0, 1, 2)]
        before, base_own = res(parent)[s]["success_rate"], res(parent)["base"]["success_rate"]
        after = [res(r)[s]["success_rate"] for r in refs]
        kept = [res(r)["base"]["success_rate"] for r in refs]
        gains.append(100 * (sum(after) / 3 - before))
        within += all(base_own - k <= 0.10 for k in kept)
        steps = " / ".join("0" if r == parent else r.rsplit("@", 1)[1] for r in refs)
        print(f"| {s} | {100 * before:.1f}% | {steps} | {' / '.join(f'{100 * a:.1f}' for a in after)}% | "
              f"{gains[-1]:+.1f} | {' / '.join(f'{100 * k:.1f}' for k in kept)}% (base {100 * base_own:.1f}%) |")
    print(f"mean gain {sum(gains) / len(gains):+.1f}; base task within 10 points after every seed on {within} of {len(gains)}")
PY
