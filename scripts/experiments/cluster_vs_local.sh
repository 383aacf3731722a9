#!/usr/bin/env bash
# Measures the wall time of one study plan run locally with `--workers 2` and then on Ray on this machine
# (`--cluster ray`, every unit a Ray task holding one CPU), back to back, each in a fresh workspace, and checks
# that the two reports' records are equal.  Prints both times and their ratio (docs/scale.md).
#
#   bash scripts/experiments/cluster_vs_local.sh [PLAN]      # PLAN (a name or a TOML path) defaults to small
#
# On a machine whose MuJoCo collects the base-task data with other hashes than the shipped base records, give a
# copy of the plan with `verify = false` under [base_data] (docs/study.md).
set -euo pipefail
PLAN=${1:-small}
NSL=${NSL:-nsl}
PY=${PY:-python}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
run() {  # NAME ARGS...: one run in its own workspace; prints its seconds
    local name=$1; shift
    local start end
    start=$(date +%s.%N)
    if ! NSL_HOME="$WORK/$name" $NSL study run "$PLAN" --quiet "$@" > "$WORK/$name.log" 2>&1; then
        echo "the $name run failed:" >&2
        tail -5 "$WORK/$name.log" >&2
        return 1
    fi
    end=$(date +%s.%N)
    echo "$end - $start" | bc
}
local_s=$(run local --workers 2) || exit 1
ray_s=$(run ray --cluster ray --unit-cpus 1) || exit 1
same=$($PY - "$WORK" "$PLAN" <<'PY'
import json, sys
from pathlib import Path
work, plan = Path(sys.argv[1]), sys.argv[2]
def records(name):
    folder = next((work / name / "studies").iterdir())
    r = json.loads((folder / "records.json").read_text())
    return {k: r.get(k) for k in ("base_policy", "finetune", "continual", "curves", "early_stop")}
print("equal" if records("local") == records("ray") else "DIFFERENT")
PY
)
printf 'plan %s: --workers 2 %.0f s; --cluster ray %.0f s; ratio %.3f; report records %s\n' \
    "$PLAN" "$local_s" "$ray_s" "$(echo "$ray_s / $local_s" | bc -l)" "$same"
