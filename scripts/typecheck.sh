#!/usr/bin/env bash
# Type-check nsl with mypy: the core modules, the service layer (services/) and the collectors, datasets,
# learners, eval and catalog folders.  Settings come from [tool.mypy] in pyproject.toml.
#
# Why a symlink tree: the import package `nsl` is assembled from nsl/ and folders at the repo root
# (collectors/ -> nsl.collectors, ...; see [tool.setuptools.package-dir]).  The editable install finds
# them with an import hook that mypy cannot follow, so this script links them into one `nsl/` package in a
# temporary directory and runs mypy there.
#
# Usage: bash scripts/typecheck.sh    (PY: the Python with mypy installed; default .venv/bin/python)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="${PY:-$ROOT/.venv/bin/python}"
if [[ "$PY" == */* && "$PY" != /* ]]; then PY="$PWD/$PY"; fi  # a relative path, from the caller's directory

TREE="$(mktemp -d)"
trap 'rm -rf "$TREE"' EXIT

mkdir "$TREE/nsl"
for f in "$ROOT"/nsl/*; do  # the core, the API and the command line's folders
    ln -s "$f" "$TREE/nsl/"
done
for d in collectors datasets learners eval catalog services share cluster study curriculum; do
    ln -s "$ROOT/$d" "$TREE/nsl/$d"
done

cd "$TREE"
"$PY" -m mypy --config-file "$ROOT/pyproject.toml" \
    nsl/services nsl/collectors nsl/datasets nsl/learners nsl/eval nsl/catalog \
    nsl/errors.py nsl/keys.py nsl/workspace.py nsl/version.py nsl/refs.py nsl/scenes.py nsl/stats.py \
    nsl/checkpoint_format.py nsl/api.py
