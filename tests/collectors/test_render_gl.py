"""Every command that renders works in a plain shell: no MUJOCO_GL set, as after `pip install nsl`.

MuJoCo reads ``MUJOCO_GL`` once, when it is first imported; the shifts import it at module level, so
``nsl.collectors`` must choose the backend (default egl) before that.  Each command runs in its own
process (the backend cannot change once mujoco is loaded) with ``MUJOCO_GL`` and ``PYOPENGL_PLATFORM``
removed from the environment, and must exit 0 and write its output.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
BASE = ["collect", "--shift", "base", "--episodes", "4", "--policy", "oracle:0.5", "--data", "gl-base"]


def plain_env(home: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    return {**env, "NSL_HOME": str(home), "PYTHONPATH": str(ROOT), **extra}


def nsl(home: Path, *argv: str, **extra: str) -> subprocess.CompletedProcess:
    r = subprocess.run(
        [sys.executable, "-m", "nsl", *argv],
        cwd=ROOT,
        env=plain_env(home, **extra),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, f"nsl {' '.join(argv)} failed:\n{r.stderr[-3000:]}"
    assert "Traceback" not in r.stderr and "OpenGL platform library" not in r.stderr, r.stderr[-3000:]
    return r


# (setup commands, the command, what it must write: a path under NSL_HOME, or the PNG for `render`)
CASES = {
    "render-all": (
        [],
        ["render", "--shift", "all", "--episodes", "2", "--scale", "1", "--out", "{home}/g.png"],
        "g.png",
    ),
    "render-test-split": (
        [],
        [
            "render",
            "--shift",
            "harsh_lighting@2+checkerboard_backing",
            "--episodes",
            "1",
            "--image-size",
            "32",
            "--split",
            "test",
            "--out",
            "{home}/one.png",
        ],
        "one.png",
    ),
    "collect-2-workers": ([], [*BASE, "--workers", "2"], "datasets/gl-base/v1/manifest.json"),
    "eval-checkpoint": (
        [],
        ["eval", "--checkpoint", "ckpt:base", "--shift", "harsh_lighting", "--episodes", "2", "--json"],
        "catalog.sqlite",
    ),
    "train-with-eval": (
        [BASE],
        [
            "train",
            "--data",
            "gl-base",
            "--steps",
            "2",
            "--eval-every",
            "1",
            "--eval-episodes",
            "2",
            "--net",
            "hidden=16",
            "--name",
            "glt",
        ],
        "runs/glt/eval.jsonl",
    ),
    "continual": (
        [BASE],
        [
            "continual",
            "--sequence",
            "harsh_lighting",
            "--init",
            "ckpt:base",
            "--base-data",
            "gl-base",
            "--episodes",
            "4",
            "--steps",
            "2",
            "--eval-episodes",
            "2",
            "--name",
            "glc",
        ],
        "runs/glc/matrix.json",
    ),
    "efficiency": (
        [BASE],
        [
            "efficiency",
            "--data",
            "gl-base",
            "--sizes",
            "2,4",
            "--init",
            "ckpt:base",
            "--base-data",
            "gl-base",
            "--steps",
            "2",
            "--eval-episodes",
            "2",
            "--name",
            "eff",
        ],
        "runs/eff/tiers.json",
    ),
}


@pytest.fixture(scope="module")
def base_home(tmp_path_factory):
    """A workspace holding the small base collection (collected in a plain shell), copied by the cases that need it."""
    home = tmp_path_factory.mktemp("gl") / "home"
    nsl(home, *BASE)
    return home


@pytest.mark.parametrize("case", list(CASES))
def test_rendering_command_needs_no_mujoco_gl(case, tmp_path, base_home):
    import shutil

    setup, argv, output = CASES[case]
    home = tmp_path / "home"
    if setup:
        assert setup == [BASE]
        shutil.copytree(base_home, home)
    r = nsl(home, *(a.format(home=home) for a in argv))
    out = home / output
    assert out.is_file() and out.stat().st_size > 0, f"{out} missing after `nsl {' '.join(argv)}`:\n{r.stdout}"
    if out.suffix == ".png":
        rows = 6 if "all" in argv else 1
        size = 64 if "--image-size" not in argv else int(argv[argv.index("--image-size") + 1])
        assert Image.open(out).height == rows * size * int(argv[argv.index("--scale") + 1] if "--scale" in argv else 3)
    if case == "eval-checkpoint":
        assert json.loads(r.stdout)["results"]["harsh_lighting"]["episodes"] == 2


def test_doctor_renders_with_the_default_backend(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "nsl.commands._doctor"],
        cwd=ROOT,
        env=plain_env(tmp_path),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert "MUJOCO_GL=egl" in r.stdout


PROBE = (
    "import os, nsl.collectors; print(os.environ['MUJOCO_GL']); "
    "import mujoco; from mujoco import gl_context; print(gl_context.GLContext.__module__)"
)


def test_importing_the_package_chooses_egl_before_mujoco(tmp_path):
    r = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=ROOT, env=plain_env(tmp_path), capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["egl", "mujoco.egl"]


def test_a_backend_the_user_set_is_kept(tmp_path):
    """MUJOCO_GL=osmesa stays osmesa (mujoco then loads its OSMesa context, or fails if OSMesa is missing)."""
    probe = "import os, nsl.collectors; print(os.environ['MUJOCO_GL'], os.environ.get('PYOPENGL_PLATFORM'))"
    r = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=ROOT,
        env=plain_env(tmp_path, MUJOCO_GL="osmesa"),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["osmesa", "None"]
