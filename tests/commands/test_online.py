"""`nsl online`: rounds of collection by the current policy and fine-tuning on everything collected so far; a run
killed with SIGKILL mid-round resumes and ends with the numbers of an uninterrupted run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from nsl.errors import ConfigError
from nsl.learners.precision import resolve_precision
from nsl.services.online import round_mix

ROOT = Path(__file__).resolve().parents[2]
ARGS = ["online", "--shift", "harsh_lighting@2", "--rounds", "2", "--episodes", "6", "--steps", "6",
        "--eval-episodes", "4", "--base-data", "grasp-base", "--ratio", "0.5", "--precision", "auto",
        "--name", "on"]  # fmt: skip


THREADS = 2  # torch threads of both runs: the float sums (and so the checkpoint ids) depend on the count


def _nsl(home: Path, *argv: str, wait: bool = True):
    env = {**os.environ, "NSL_HOME": str(home), "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": str(THREADS)}
    cmd = [sys.executable, "-m", "nsl", *argv]
    if not wait:
        return subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)


def _in_process(home: Path, monkeypatch, *argv: str) -> None:
    import torch

    from tests.conftest import run_cli

    monkeypatch.setenv("NSL_HOME", str(home))
    threads = torch.get_num_threads()
    torch.set_num_threads(THREADS)
    try:
        assert run_cli(*argv) == 0, argv
    finally:
        torch.set_num_threads(threads)


def _home(tmp_path: Path, name: str, monkeypatch) -> Path:
    home = tmp_path / name
    home.mkdir()
    _in_process(home, monkeypatch, "collect", "--shift", "base", "--episodes", "8", "--policy", "oracle:0.5",
                "--data", "grasp-base", "--num-envs", "4")  # fmt: skip
    return home


@pytest.mark.precision  # --precision auto: bf16 or fp32 by the CPU
def test_online_rounds_resume_after_sigkill_mid_round_with_identical_numbers(tmp_path, monkeypatch):
    """The uninterrupted run in this process, the killed one in a process of its own, resumed by the same command."""
    whole = _home(tmp_path, "whole", monkeypatch)
    _in_process(whole, monkeypatch, *ARGS)
    rows = json.loads((whole / "runs" / "on" / "rounds.json").read_text())
    assert [(r["round"], r["grasps"], r["episodes"]) for r in rows] == [(0, 0, 4), (1, 6, 4), (2, 12, 4)]
    assert len({r["checkpoint"] for r in rows}) == 3  # each round a new checkpoint
    # Round 2 trained on both rounds' data (a quarter of each batch each) and the base data, from round 1.
    config = json.loads((whole / "runs" / "on-r2" / "final" / "config.json").read_text())
    sources = {s["ref"].split("@")[0]: s["weight"] for s in config["data"]["sources"]}
    assert sources == {"grasp-base": 0.5, "on-r1": 0.25, "on-r2": 0.25}
    assert config["parent"]["id"] == rows[1]["checkpoint"].removeprefix("ckpt:")
    # every round trains at --precision; fp32, the default, is left out of the config (see TrainConfig.to_dict)
    assert config["training"].get("precision", "fp32") == resolve_precision("auto")

    killed = _home(tmp_path, "killed", monkeypatch)
    proc = _nsl(killed, *ARGS, wait=False)
    marker = killed / "runs" / "on-r2" / "run.json"  # round 2's training has started
    deadline = time.monotonic() + 600
    while not marker.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before round 2's training; nothing was killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=60)
    assert not (killed / "runs" / "on-r2" / "final").exists()
    out = _nsl(killed, *ARGS)
    assert out.returncode == 0, out.stderr[-2000:]
    again = json.loads((killed / "runs" / "on" / "rounds.json").read_text())
    assert again == rows  # the same successes, intervals and checkpoint ids (content hashes of the weights)


def test_online_rounds_mix_and_bad_settings():
    mix = round_mix([("grasp-base-oracle", 0.35), ("grasp-base-random", 0.15)], [("on-r1", 800), ("on-r2", 400)], 0.44)
    weights = {m.split("=")[0]: float(m.split("=")[1]) for m in mix}
    assert weights == pytest.approx(
        {
            "grasp-base-oracle": 0.56 * 0.7,
            "grasp-base-random": 0.56 * 0.3,
            "on-r1:800": 0.44 * 2 / 3,
            "on-r2:400": 0.44 / 3,
        }
    )
    assert round_mix([("b", 1.0)], [("on-r1", 10)], 1.0) == ["on-r1:10=1.0"]

    from nsl.services.online import check
    from nsl.services.options import OnlineConfig

    for bad, message in [
        ({"shift": "base"}, "is the base task; name the target shift"),
        ({"shift": "harsh_lighting", "ratio": 0.0}, "--ratio 0.0 is the target data's share of each batch"),
        ({"shift": "harsh_lighting", "rounds": 0}, "--rounds 0 must be at least 1"),
        ({"shift": "harsh_lighting", "method": "pnn"}, r"online rounds start with ft \(all parameters\) or new_head"),
    ]:
        with pytest.raises(ConfigError, match=message):
            check(OnlineConfig(**bad))
    # The engine is a target like a shift: alone it is PyBullet's base task; with --engine it joins the shift's name.
    check(OnlineConfig(shift="engine:pybullet"))
    assert OnlineConfig(shift="harsh_lighting@2", engine="pybullet").target == "engine:pybullet+harsh_lighting@2"
    assert OnlineConfig(shift="harsh_lighting@2+engine:pybullet").target == "engine:pybullet+harsh_lighting@2"
    with pytest.raises(ConfigError, match="is the base task"):
        check(OnlineConfig(shift="base", engine="mujoco"))
