"""The Python API: docs/python.md's worked example runs as written, through ``import nsl`` only."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _example() -> str:
    text = (ROOT / "docs" / "python.md").read_text()
    block = re.search(r"<!-- example: start -->\s*```python\n(.*?)```\s*<!-- example: end -->", text, re.S)
    assert block, "docs/python.md has no marked example"
    return block.group(1)


def test_the_documented_example_runs_end_to_end(tmp_path, monkeypatch):
    code = _example()
    assert "nsl.commands" not in code and "nsl.services" not in code  # the public API only
    monkeypatch.setenv("NSL_HOME", str(tmp_path / "home"))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    lines = out.stdout.splitlines()  # the example's prints, among the services' own "wrote ..." lines
    assert any(line.startswith("grasp-base@v1 sha256:") and line.endswith("grasp-harsh@v1") for line in lines)
    assert any(re.match(r"ckpt:harsh-demo@6 [0-9a-f]{12} chosen: ", line) for line in lines), out.stdout
    assert any(line.startswith("ckpt:base-demo@8 ") and "%" in line for line in lines)
    assert any("McNemar" in line or "p =" in line or "p=" in line for line in lines), out.stdout
    report = Path(lines[-1])
    assert report.name == "report.md" and report.is_file() and "harsh" in report.read_text().lower()


def test_import_nsl_is_cheap_and_lists_the_api():
    code = (
        "import sys, nsl; heavy = [m for m in ('torch', 'mujoco', 'numpy', 'nsl.api') if m in sys.modules]; "
        "print(heavy); print(sorted(n for n in dir(nsl) if n in ('collect', 'train', 'evaluate')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.splitlines() == ["[]", "['collect', 'evaluate', 'train']"]


def test_settings_are_checked_in_one_line(tmp_path, monkeypatch):
    import pytest

    import nsl
    from nsl.errors import ConfigError

    monkeypatch.setenv("NSL_HOME", str(tmp_path))
    with pytest.raises(ConfigError, match="no setting stepz; the settings are .*steps"):
        nsl.train(data=["x"], name="y", stepz=3)
    with pytest.raises(ConfigError, match="--steps is required for pre-training"):
        nsl.train(data=["x"], name="y")
    opts = nsl.TrainOptions(data=("a=0.5", "b=0.5"), name="n")
    with pytest.raises(ConfigError, match="takes a TrainOptions, not CollectConfig"):
        nsl.train(nsl.CollectConfig(shift="base", episodes=1, policy="random", data="d"))
    assert opts.batch_size == 64 and opts.eval_scenes == nsl.SELECTION_SCENES


def test_every_api_name_resolves():
    import nsl
    import nsl.api

    assert [n for n in nsl._API if not hasattr(nsl.api, n)] == []
    assert sorted(nsl.api.__all__) == sorted(nsl._API)


def test_a_run_made_before_a_setting_existed_resumes_at_its_default(tmp_path, monkeypatch):
    import json
    from dataclasses import asdict, replace

    import pytest

    from nsl.errors import ConfigError
    from nsl.services.options import OnlineConfig
    from nsl.services.refs import open_run

    monkeypatch.setenv("NSL_HOME", str(tmp_path))
    config = OnlineConfig(shift="harsh_lighting@2")
    run_dir = open_run("old", config)
    old = {k: v for k, v in asdict(config).items() if k != "num_envs"}  # written before --num-envs existed
    (run_dir / "config.json").write_text(json.dumps(old))
    assert open_run("old", config) == run_dir
    (run_dir / "config.json").write_text(json.dumps(old))
    with pytest.raises(ConfigError, match="exists with a different configuration"):
        open_run("old", replace(config, num_envs=4))
