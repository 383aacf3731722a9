"""scripts/experiments/ship_base.py refuses, in one line, a base made by uncommitted code.

A real workspace: a synthetic dataset of two versions (v2 appends to v1) and a two-step training run on v2.
The recorded code versions are then set (clean ``0.1.0+g...`` or dirty ``...dirty``), so the test does not
depend on whether this checkout has uncommitted changes.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from tests.conftest import run_cli
from tests.datasets.conftest import SYNTH_SPEC, synth_episode

ROOT = Path(__file__).resolve().parents[1]
CLEAN, DIRTY = "0.1.0+g0123456789ab", "0.1.0+g0123456789ab.dirty"
TINY_NET = ["--net", "image_size=16", "--net", "conv_channels=8,8", "--net", "conv_strides=2,2", "--net", "hidden=16"]


@pytest.fixture(scope="module")
def ship_base():
    spec = importlib.util.spec_from_file_location("ship_base", ROOT / "scripts" / "experiments" / "ship_base.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _set_code_version(path: Path, value: str, *keys: str) -> None:
    data = json.loads(path.read_text())
    node = data
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    path.write_text(json.dumps(data, indent=2))


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """A workspace with ``syn`` v1 and v2 and run ``base-x`` (step 2) trained on ``syn@v2``; built once."""
    home = tmp_path_factory.mktemp("ship_base_home")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NSL_HOME", str(home))
        from nsl.datasets import api

        for start, n in ((0, 3), (3, 2)):
            api.write_dataset(
                "syn",
                [synth_episode(i, 3, success=i % 2 == 0) for i in range(start, start + n)],
                SYNTH_SPEC,
                16,
                n,
                episodes_per_file=2,
            )
        assert (
            run_cli("train", "--data", "syn", "--steps", "2", "--batch-size", "8", "--name", "base-x", *TINY_NET) == 0
        )
    return home


@pytest.fixture
def run(built, monkeypatch):
    """The built workspace as NSL_HOME, every recorded code version set clean; the files that record one."""
    monkeypatch.setenv("NSL_HOME", str(built))
    run_dir = built / "runs" / "base-x"
    files = {
        "config": run_dir / "checkpoints" / "step-000000002" / "config.json",
        "command": run_dir / "command.json",
        "v1": built / "datasets" / "syn" / "v1" / "manifest.json",
        "v2": built / "datasets" / "syn" / "v2" / "manifest.json",
    }
    for key, path in files.items():
        _set_code_version(path, CLEAN, *_field(key))
    assert [d["dataset"] + f"@v{d['version']}" for d in json.loads(files["command"].read_text())["data"]] == ["syn@v2"]
    return files


def _field(key: str) -> tuple[str, ...]:
    """Where a file records its code version: a dataset manifest under "created", the others at the top."""
    return ("created", "code_version") if key.startswith("v") else ("code_version",)


def test_a_clean_base_ships(ship_base, run, tmp_path):
    dst = tmp_path / "asset"
    ship_base.main("base-x", 2, dst)
    assert sorted(p.name for p in dst.iterdir()) == [
        "command.json",
        "config.json",
        "env_version.txt",
        "model.safetensors",
    ]
    assert json.loads((dst / "config.json").read_text())["code_version"] == CLEAN


@pytest.mark.parametrize(
    "which, needle",
    [
        ("config", f"the checkpoint was trained by uncommitted code ({DIRTY})"),
        ("command", f"the run's command.json records uncommitted code ({DIRTY})"),
        ("v2", f"its training data syn@v2 was collected by uncommitted code ({DIRTY})"),
        ("v1", f"its training data syn@v1 was collected by uncommitted code ({DIRTY})"),  # v2 appended to v1
    ],
)
def test_a_dirty_code_version_is_refused_in_one_line(ship_base, run, tmp_path, which, needle):
    _set_code_version(run[which], DIRTY, *_field(which))
    dst = tmp_path / "asset"
    with pytest.raises(SystemExit) as e:
        ship_base.main("base-x", 2, dst)
    message = str(e.value.code)
    assert message.startswith("ship_base: refusing to ship ") and "\n" not in message
    assert needle in message and "commit the code" in message
    assert not dst.exists()  # nothing was copied


def test_data_this_workspace_does_not_hold_is_refused(ship_base, run, tmp_path, monkeypatch):
    import shutil

    home = tmp_path / "copy"
    shutil.copytree(run["v1"].parents[3], home, symlinks=True)
    shutil.rmtree(home / "datasets" / "syn")
    monkeypatch.setenv("NSL_HOME", str(home))
    with pytest.raises(SystemExit) as e:
        ship_base.main("base-x", 2, tmp_path / "asset")
    message = str(e.value.code)
    assert "its training data syn@v2 cannot be checked here" in message and "\n" not in message


def test_is_dirty_reads_nsl_version_strings(ship_base):
    from nsl.version import __version__

    assert ship_base.is_dirty(DIRTY) and not ship_base.is_dirty(CLEAN) and not ship_base.is_dirty(__version__)
    assert not ship_base.is_dirty(None)
