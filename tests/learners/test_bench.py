"""`nsl bench learner` runs end to end through the real CLI (speed itself is not asserted here)."""

from __future__ import annotations

import json

import pytest

from nsl.cli import main


def test_bench_learner_prints_both_rates(capsys):
    code = main(["bench", "learner", "--json", "--quick", "--steps", "1", "--baseline-steps", "1", "--threads", "1"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["steps_per_s"] > 0 and out["baseline_steps_per_s"] > 0 and out["reuse_loop_steps_per_s"] > 0
    assert out["speedup"] == pytest.approx(out["steps_per_s"] / out["baseline_steps_per_s"], rel=0.02)
    assert out["batch"] == 64 and out["image_size"] == 64 and out["cem"] == "64/6/2"
