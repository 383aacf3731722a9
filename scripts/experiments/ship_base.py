"""Copy a run's checkpoint into nsl/assets/base, where ``ckpt:base`` finds it in any workspace.

Copies the weights and config of step STEP of run RUN in $NSL_HOME, the run's ``command.json`` (the command, code
version and dataset hashes that made it) and the environment version it was trained in.

    python scripts/experiments/ship_base.py RUN STEP [DEST]   (DEST: default nsl/assets/base)
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from nsl import workspace
from nsl.collectors import ENV_VERSION


ASSET = Path(__file__).resolve().parents[2] / "nsl" / "assets" / "base"


def main(run: str, step: int, dst: Path = ASSET) -> None:
    src = workspace.runs_dir() / run / "checkpoints" / f"step-{step:09d}"
    if not (src / "model.safetensors").is_file():
        sys.exit(f"ship_base: {src} has no model.safetensors; train run {run!r} to step {step} in this NSL_HOME first")
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
