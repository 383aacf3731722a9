"""Extending nsl without touching its source: the example package ``examples/nsl-occluder`` adds a shift, a
policy and a learner through entry points only, and nsl renders, collects, trains and runs a study with them;
what it made records the package, and reading it where the package is missing fails in one line that names it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from nsl.errors import ConfigError, IncompatibleVersionError, UnknownReferenceError
from tests.study.conftest import MICRO_PLAN

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "nsl-occluder"
PACKAGE = {"package": "nsl-occluder", "version": "0.1.0"}
# The micro study plan (base data, a collection, a fine-tune, evaluations) on the plugin's shift
PLAN = MICRO_PLAN.replace("micro", "plugin").replace('["harsh_lighting"]', '["lens_occluder@2"]')


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory):
    """The example package installed with pip (its entry points in a dist-info) into a folder of its own."""
    import shutil

    source = tmp_path_factory.mktemp("src") / EXAMPLE.name  # a copy: a build writes beside the sources
    shutil.copytree(EXAMPLE, source)
    target = tmp_path_factory.mktemp("site")
    cmd = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--target", str(target)]
    subprocess.run([*cmd, str(source)], check=True, capture_output=True, timeout=300)
    return target


def _nsl(home: Path, *argv: str, plugin: Path | None = None) -> subprocess.CompletedProcess:
    paths = [str(ROOT), *([str(plugin)] if plugin else [])]
    env = {**os.environ, "NSL_HOME": str(home), "PYTHONPATH": os.pathsep.join(paths)}
    return subprocess.run(
        [sys.executable, "-m", "nsl", *argv], cwd=home.parent, env=env, capture_output=True, text=True, timeout=1200
    )


@pytest.fixture
def installed(plugin_path, monkeypatch, tmp_path):
    """The example package importable in this process, as after `pip install` (its entry points found), for
    in-process commands; NSL_HOME is ``tmp_path/home``.  Afterwards nsl forgets the package again."""
    from nsl import plugins
    from nsl.collectors import policies, shifts
    from nsl.learners import registry

    for module, registered in ((shifts, "SHIFTS"), (policies, "_REGISTERED"), (registry, "_REGISTERED")):
        monkeypatch.setattr(module, registered, dict(getattr(module, registered)))  # forget the plugin's afterwards
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("NSL_HOME", str(home))
    monkeypatch.syspath_prepend(str(plugin_path))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(ROOT), str(plugin_path)]))  # study unit processes
    plugins._entry_points.cache_clear()
    yield home
    plugins._entry_points.cache_clear()


def test_the_example_plugin_renders_collects_trains_and_runs_a_study(installed, plugin_path, tmp_path, capsys):
    from tests.conftest import run_cli

    home = installed
    assert (
        run_cli("render", "--shift", "base,lens_occluder@2", "--episodes", "2", "--out", str(tmp_path / "g.png")) == 0
    )
    assert (tmp_path / "g.png").stat().st_size > 0

    collect = ["collect", "--shift", "lens_occluder@2", "--policy", "nsl_occluder.centre:0.3", "--episodes", "8"]
    assert run_cli(*collect, "--data", "occluded", "--num-envs", "4", "--workers", "1") == 0
    meta = json.loads(next((home / "datasets" / "occluded").glob("v*/meta/nsl.json")).read_text())
    spec = meta["collections"][-1]["spec"]
    assert spec["env"]["shift_spec"]["shifts"][0]["plugin"] == PACKAGE  # the shift's package and version
    assert spec["policy"]["plugin"] == PACKAGE and spec["policy"]["noise"] == 0.3

    train = ["train", "--data", "occluded", "--init", "ckpt:base", "--batch-size", "8"]
    assert run_cli(*train, "--steps", "3", "--name", "occ") == 0
    bandit = ["--learner", "nsl_occluder.bandit:reward_scale=0.9", "--name", "occ-bandit"]
    assert run_cli(*train, "--steps", "2", *bandit) == 0
    config = json.loads((home / "runs" / "occ-bandit" / "final" / "config.json").read_text())
    assert config["learner"] == {"name": "nsl_occluder.bandit", "plugin": PACKAGE}
    assert config["training"]["learner_options"] == {"reward_scale": 0.9}
    capsys.readouterr()
    pnn = ["--method", "pnn", "--learner", "nsl_occluder.bandit", "--name", "occ-pnn"]
    assert run_cli(*train, "--steps", "2", *pnn) != 0
    assert "learner 'nsl_occluder.bandit' does not support method 'pnn'" in capsys.readouterr().err

    plan = tmp_path / "plugin.toml"
    plan.write_text(PLAN)
    assert run_cli("study", "run", str(plan), "--quiet") == 0
    records = json.loads((home / "studies" / "plugin" / "records.json").read_text())
    assert "lens_occluder@2" in json.dumps(records["finetune"])

    # the plugin uninstalled (a fresh process without it): the dataset it made is refused in one line that names
    # the package
    out = _nsl(home, "dataset", "show", "occluded")
    assert out.returncode != 0
    assert "made with the plugin package nsl-occluder 0.1.0, which is not installed here" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    # and so is the checkpoint its learner trained
    out = _nsl(home, "eval", "--checkpoint", "ckpt:occ-bandit", "--episodes", "1")
    assert out.returncode != 0 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "made with the plugin package nsl-occluder 0.1.0, which is not installed here" in out.stderr


def test_plugin_records_are_checked_by_package_and_major_version(plugin_path, monkeypatch):
    from nsl import plugins

    plugins.require([], "nothing")
    with pytest.raises(UnknownReferenceError, match=r"plugin package nsl-nowhere 1.2, which is not installed here"):
        plugins.require(plugins.recorded({"a": [{"plugin": {"package": "nsl-nowhere", "version": "1.2"}}]}), "d")
    monkeypatch.syspath_prepend(str(plugin_path))
    plugins._entry_points.cache_clear()
    plugins.require([PACKAGE, {**PACKAGE, "version": "0.9"}], "dataset d")  # same major version
    with pytest.raises(IncompatibleVersionError, match=r"nsl-occluder 1.0, but 0.1.0 is installed"):
        plugins.require([{**PACKAGE, "version": "1.0"}], "dataset d")
    assert "lens_occluder" in plugins.names("nsl.shifts") and "nsl_occluder.centre" in plugins.names("nsl.policies")
    assert plugins.names("nsl.learners") == ["nsl_occluder.bandit"]
    plugins._entry_points.cache_clear()


def test_a_shift_and_a_policy_registered_in_a_notebook(monkeypatch):
    from nsl.collectors import ShiftDef, parse_shift, register_policy, register_shift, scripted_policy, shift_names
    from nsl.collectors import shifts as shift_module
    from nsl.collectors.policies import _REGISTERED

    monkeypatch.setattr(shift_module, "SHIFTS", dict(shift_module.SHIFTS))  # forget it afterwards
    monkeypatch.setattr("nsl.collectors.policies._REGISTERED", dict(_REGISTERED))
    dim = ShiftDef("dim_lights", "vision", 1.0, lambda s: {"scale": 1 - 0.5 * s}, lambda spec, p: None, "dimmer")
    register_shift(dim)
    assert "dim_lights" in shift_names()
    d = parse_shift("dim_lights@0.5").to_dict()
    assert d["shifts"][0]["plugin"] == {"package": "__main__", "version": "0"}
    assert parse_shift("harsh_lighting").to_dict()["shifts"][0].keys() == {"name", "severity", "params"}  # built in
    with pytest.raises(ConfigError, match=r"shift name 'harsh_lighting' is taken"):
        register_shift(ShiftDef("harsh_lighting", "vision", 1.0, dim.params, dim.apply, ""))
    with pytest.raises(ConfigError, match=r"severity 2.0 for shift 'dim_lights' is out of range"):
        parse_shift("dim_lights@2")
    register_policy("lab.still", lambda args, **kw: scripted_policy("random"))
    policy = scripted_policy("lab.still")
    assert policy.describe()["plugin"] == {"package": "__main__", "version": "0"}
    with pytest.raises(UnknownReferenceError, match=r"unknown policy 'lab.nothing'"):
        scripted_policy("lab.nothing")
