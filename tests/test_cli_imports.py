"""The CLI answers at once: listing and help never import torch, MuJoCo or lerobot.

Each command runs in a fresh interpreter (an empty ``NSL_HOME``) through
``nsl.cli.main``; the driver then prints the names of all imported modules.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

HEAVY = ("torch", "mujoco", "lerobot")

DRIVER = """
import json, sys
from nsl.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as e:  # --help exits through argparse
    code = e.code
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["catalog", "ls"],
        ["dataset", "ls"],
        ["train", "--help"],
        ["bench", "learner", "--help"],
        ["transfer", "run", "--help"],
        ["curriculum", "--help"],
        ["compare", "--help"],
    ],
)
def test_light_commands_do_not_import_heavy_libraries(argv, tmp_path):
    env = {**os.environ, "NSL_HOME": str(tmp_path / "home")}
    out = subprocess.run([sys.executable, "-c", DRIVER, *argv], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["code"] in (0, None), out.stderr
    assert "nsl.cli" in result["modules"]
    heavy = sorted(m for m in result["modules"] if m.split(".")[0] in HEAVY)
    assert heavy == [], f"nsl {' '.join(argv)} imported {heavy[:5]}"
