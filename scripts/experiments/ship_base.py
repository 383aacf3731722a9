"""Copy a run's checkpoint into nsl/assets/base, where ``ckpt:base`` finds it in any workspace.

Copies the weights and config of step STEP of run RUN in $NSL_HOME, the run's ``command.json`` (the command, code
version and dataset hashes that made it) and the environment version it was trained in.

Refuses, in one line, a checkpoint or training data whose recorded code version is dirty (``+gSHA.dirty``:
made by uncommitted code, see nsl/version.py), since no commit can reproduce it.

    python scripts/experiments/ship_base.py RUN STEP [DEST]   (DEST: default nsl/assets/base)
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path
from typing import Any

from nsl import workspace
from nsl.collectors import ENV_VERSION

ASSET = Path(__file__).resolve().parents[2] / "nsl" / "assets" / "base"


def is_dirty(code_version: Any) -> bool:
    """True for a code version made from a checkout with uncommitted changes (nsl.version.code_version)."""
    return isinstance(code_version, str) and code_version.endswith(".dirty")


def _data_versions(name: str, version: int) -> list[tuple[str, dict[str, Any]]]:
    """``(ref, manifest)`` of ``name@vVERSION`` and of the versions it appended to (their episodes are in it)."""
    from nsl.datasets import api

    by_hash = {api.open_version(f"{name}@v{v}").hash: f"{name}@v{v}" for v in api.list_versions(name)}
    out = []
    ref: str | None = f"{name}@v{version}"
    seen = set()
    while ref is not None and ref not in seen:
        seen.add(ref)
        manifest = api.open_version(ref).manifest
        out.append((ref, manifest))
        parent = (manifest.get("created") or {}).get("parent")
        ref = by_hash.get(parent) if parent else None
    return out


def refusal(src: Path, command: dict[str, Any]) -> str | None:
    """Why the checkpoint folder ``src`` (made by the run whose ``command.json`` is ``command``) must not ship, or None.

    Refused: a dirty code version in the checkpoint's config or the run's command, a training dataset version
    (or a version it appended to) collected by dirty code, and a training dataset this workspace cannot show.
    """
    from nsl.errors import NslError

    problems = []
    config = json.loads((src / "config.json").read_text())
    if is_dirty(config.get("code_version")):
        problems.append(f"the checkpoint was trained by uncommitted code ({config['code_version']})")
    elif is_dirty(command.get("code_version")):
        problems.append(f"the run's command.json records uncommitted code ({command['code_version']})")
    for d in command.get("data") or []:
        ref = f"{d['dataset']}@v{d['version']}"
        try:
            chain = _data_versions(d["dataset"], int(d["version"]))
        except NslError as e:
            problems.append(f"its training data {ref} cannot be checked here ({e})")
            continue
        if d.get("hash") and chain[0][1].get("hash") != d["hash"]:
            problems.append(
                f"its training data {ref} has hash {str(chain[0][1].get('hash'))[:19]}... here, the run "
                f"recorded {d['hash'][:19]}..."
            )
        for vref, manifest in chain:
            cv = (manifest.get("created") or {}).get("code_version")
            if is_dirty(cv):
                problems.append(f"its training data {vref} was collected by uncommitted code ({cv})")
    if not problems:
        return None
    return (
        f"refusing to ship {src}: "
        + "; ".join(problems)
        + "; commit the code, then collect and train again with the committed code"
    )


def main(run: str, step: int, dst: Path = ASSET) -> None:
    src = workspace.runs_dir() / run / "checkpoints" / f"step-{step:09d}"
    if not (src / "model.safetensors").is_file():
        sys.exit(f"ship_base: {src} has no model.safetensors; train run {run!r} to step {step} in this NSL_HOME first")
    why = refusal(src, json.loads((workspace.runs_dir() / run / "command.json").read_text()))
    if why is not None:
        sys.exit(f"ship_base: {why}")
    dst.mkdir(parents=True, exist_ok=True)
    for name in ("model.safetensors", "config.json"):
        shutil.copyfile(src / name, dst / name)
    shutil.copyfile(workspace.runs_dir() / run / "command.json", dst / "command.json")
    (dst / "env_version.txt").write_text(ENV_VERSION + "\n")
    print(f"shipped {src} to {dst}")


if __name__ == "__main__":
    if len(sys.argv) not in (3, 4) or not sys.argv[2].isdigit():
        sys.exit("usage: python scripts/experiments/ship_base.py RUN STEP [DEST]   (e.g. rounds-r4 6000)")
    main(sys.argv[1], int(sys.argv[2]), *(Path(a) for a in sys.argv[3:]))
