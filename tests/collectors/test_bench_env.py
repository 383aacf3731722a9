"""`nsl bench env`: nsl's env on each engine against PyBullet's KukaDiverseObjectEnv, in one run (speed itself is
not asserted)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from nsl.bench import env as bench_env
from nsl.cli import main


def test_pybullet_is_timed_beside_mujoco_against_one_reference_timing(monkeypatch):
    # KukaDiverseObjectEnv takes seconds per attempt; its timing is replaced here (the slow test below runs it).
    monkeypatch.setattr(bench_env, "_time_reference", lambda seconds: (0.5, 5))
    out = bench_env.run(SimpleNamespace(seconds=0.2, quick=False, engine="pybullet"))
    assert out["engine"] == "pybullet" and out["nsl_attempts"] >= 2 and out["mujoco_attempts"] >= 2
    assert out["ratio"] == pytest.approx(out["nsl_attempts_per_s"] / 0.5, abs=0.1)
    assert out["mujoco_ratio"] == pytest.approx(out["mujoco_attempts_per_s"] / 0.5, abs=0.1)
    plain = bench_env.run(SimpleNamespace(seconds=0.2, quick=False, engine="mujoco"))
    assert plain["engine"] == "mujoco" and "mujoco_ratio" not in plain  # MuJoCo alone: the ratio is its own


@pytest.mark.slow
def test_bench_env_runs_kuka_diverse_object_env_through_the_cli(capsys):
    assert main(["bench", "env", "--engine", "pybullet", "--seconds", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["reference_attempts"] >= 5 and out["reference_attempts_per_s"] > 0
    assert out["ratio"] > 0 and out["mujoco_ratio"] > 0
