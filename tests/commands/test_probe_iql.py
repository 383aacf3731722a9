"""scripts/experiments/probe_iql.py, the implicit Q-learning probe behind a row of docs/experiments/plateau.md: the
warm-up fits V alone and leaves the parent's Q untouched; then Q trains, and the result is a checkpoint that acts."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import torch

from nsl import keys
from nsl.catalog import Catalog
from nsl.learners import load_checkpoint, load_policy
from tests.conftest import run_cli

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "experiments" / "probe_iql.py"


def _run_probe(monkeypatch, *args: str) -> None:
    spec = importlib.util.spec_from_file_location("probe_iql", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    monkeypatch.setattr(sys, "argv", ["probe_iql.py", *args])
    mod.main()


def _weights(path: Path) -> dict[str, torch.Tensor]:
    return load_checkpoint(path).net.state_dict()


def test_iql_probe_warms_up_v_alone_then_trains_q(tmp_path, monkeypatch):
    monkeypatch.setenv("NSL_HOME", str(tmp_path / "home"))
    assert (
        run_cli(
            "collect",
            "--shift",
            "base",
            "--episodes",
            "12",
            "--policy",
            "oracle:0.5",
            "--data",
            "grasp-base",
            "--num-envs",
            "4",
        )
        == 0
    )
    assert (
        run_cli(
            "collect",
            "--shift",
            "harsh_lighting",
            "--episodes",
            "8",
            "--policy",
            "oracle:0.5",
            "--data",
            "grasp-harsh",
            "--num-envs",
            "4",
        )
        == 0
    )
    assert run_cli("train", "--data", "grasp-base", "--steps", "4", "--name", "tiny") == 0
    with Catalog() as cat:
        parent = Path(cat.resolve_checkpoint("ckpt:tiny@latest").path)
    data = ["--init", "ckpt:tiny@latest", "--data", "grasp-base=0.5", "--data", "grasp-harsh=0.5"]

    _run_probe(monkeypatch, *data, "--steps", "0", "--v-warmup", "3", "--out", str(tmp_path / "warm"))
    before, warm = _weights(parent), _weights(tmp_path / "warm")
    assert all(torch.equal(before[k], warm[k]) for k in before)  # only V moved

    _run_probe(monkeypatch, *data, "--steps", "3", "--v-warmup", "1", "--tau", "0.9", "--out", str(tmp_path / "iql"))
    trained = _weights(tmp_path / "iql")
    assert any(not torch.equal(before[k], trained[k]) for k in before)
    config = json.loads((tmp_path / "iql" / "config.json").read_text())
    assert config["data"]["probe"] == "iql" and config["data"]["tau"] == 0.9 and config["step"] == 3
    assert config["training"]["n_step"] == 1
    policy = load_policy(tmp_path / "iql")  # it acts: a CEM policy over the trained Q
    obs = {"image": np.zeros((2, 64, 64, 3), np.uint8), "state": np.zeros((2, keys.STATE_DIM), np.float32)}
    actions = policy(obs, rngs=[np.random.default_rng(i) for i in range(2)])
    assert actions.shape == (2, 6) and np.isfinite(actions).all()
