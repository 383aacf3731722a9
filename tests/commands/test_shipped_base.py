"""The base checkpoint that ships in ``nsl/assets/base``: it loads, resolves as ``ckpt:base``, records how it
was made, and (slow) grasps as well as the README says while every shift hurts it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import nsl
from nsl.catalog import Catalog
from nsl.collectors import ENV_VERSION
from nsl.learners import load_checkpoint
from tests.conftest import recorded_calls, run_cli

ASSET = Path(nsl.__file__).parent / "assets" / "base"
README = Path(__file__).resolve().parents[2] / "README.md"
SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "experiments" / "pretrain_base_rounds.sh"


def test_shipped_base_loads_and_records_its_recipe(tmp_path):
    ckpt = load_checkpoint(ASSET)
    cfg = ckpt.config
    assert cfg["method"] == "scratch" and cfg["parent"] is None
    sources = cfg["data"]["sources"]
    assert sum(s["episodes"] for s in sources) <= 50_000  # the project's data budget
    assert all(s["ref"].startswith(("grasp-base-", "grasp-rounds-")) for s in sources)
    assert 0 < cfg["step"] <= cfg["training"]["steps"]
    command = json.loads((ASSET / "command.json").read_text())
    # The reproduce script runs exactly the recorded training command (run with a recording stand-in for nsl).
    calls = recorded_calls(SCRIPT, tmp_path, SEEDS="0")
    assert command["argv"][1:] in calls
    assert command["data"] and all(d["hash"].startswith("sha256:") for d in command["data"])
    assert ENV_VERSION in (ASSET / "env_version.txt").read_text()


def test_ckpt_base_falls_back_to_the_shipped_checkpoint_and_is_catalogued(capsys):
    assert run_cli("eval", "--checkpoint", "ckpt:base", "--episodes", "4", "--batch-size", "4", "--json") == 0
    out = json.loads(capsys.readouterr().out)
    assert out["results"]["base"]["episodes"] == 4
    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:base")
    assert entry.name == "base"
    assert (Path(entry.path) / "model.safetensors").read_bytes() == (ASSET / "model.safetensors").read_bytes()


@pytest.mark.slow
def test_shipped_base_grasps_well_and_every_shift_hurts(capsys):
    """What the README states: about 70% on 200 unseen test scenes (below the project's 80% target), and each
    shift at least 15 points lower (the project's bar for a shift)."""
    assert run_cli("eval", "--checkpoint", "ckpt:base", "--shift", "all", "--episodes", "200", "--workers", "2",
                   "--seed", "2000", "--json") == 0
    results = json.loads(capsys.readouterr().out)["results"]
    base = results["base"]["success_rate"]
    assert base >= 0.64, results  # README: 70% [64-76] with these seeds
    for shift, r in results.items():
        if shift != "base":
            assert r["success_rate"] <= base - 0.15 + 1e-9, (shift, r, base)


@pytest.mark.slow
def test_shipped_base_fine_tunes_to_harsh_lighting(capsys):
    """The demo's main effect, which a new base must keep (docs/experiments.md, "Plasticity of a base"): 300
    steps of the study's fine-tune on the demo's data lift harsh-lighting success from 13% to 60% on these scenes."""
    for shift, name in (("base", "demo-base"), ("harsh_lighting", "demo-harsh")):
        assert run_cli("collect", "--shift", shift, "--episodes", "600" if shift == "base" else "100",
                       "--policy", "oracle:1.0", "--data", name, "--workers", "2", "--batch-size", "4") == 0
    assert run_cli("train", "--data", "demo-base=0.5", "--data", "demo-harsh=0.5", "--init", "ckpt:base",
                   "--steps", "300", "--name", "plastic") == 0
    capsys.readouterr()
    assert run_cli("eval", "--checkpoint", "ckpt:base,ckpt:plastic", "--shift", "harsh_lighting", "--episodes", "100",
                   "--workers", "2", "--seed", "2000", "--json") == 0
    out = json.loads(capsys.readouterr().out)
    before, after = (out["policies"][k]["results"]["harsh_lighting"]["success_rate"] for k in ("ckpt:base", "ckpt:plastic"))
    assert after >= before + 0.30, out["policies"]
    assert out["paired"]["harsh_lighting"]["p_value"] < 0.01
