"""`nsl bench learner` runs end to end through the real CLI (speed itself is not asserted here)."""

from __future__ import annotations

import json

import pytest

from nsl.cli import main


@pytest.mark.precision  # with bfloat16 the bench also times the bf16 step
def test_bench_learner_reports_rates_flops_and_peak(capsys):
    import torch

    threads = torch.get_num_threads()
    code = main(["bench", "learner", "--json", "--quick", "--steps", "1", "--baseline-steps", "1", "--threads", "1"])
    assert code == 0
    assert torch.get_num_threads() == threads  # --threads applies to the bench only
    out = json.loads(capsys.readouterr().out)
    assert out["steps_per_s"] > 0 and out["baseline_steps_per_s"] > 0 and out["reuse_steps_per_s"] > 0
    assert out["speedup"] == pytest.approx(out["steps_per_s"] / out["baseline_steps_per_s"], rel=0.02)
    assert out["batch"] == 64 and out["image_size"] == 64 and out["cem"] == "64/6/2" and out["threads"] == 1
    # Work per step: the trunk on 64 + 64 images (forward, backward) is already above 0.1 GFLOP; the plain
    # step runs the trunk on every one of the 64 x 64 x 2 CEM candidates, so it does far more work.
    assert 0.1 < out["gflop_per_step"] < out["baseline_gflop_per_step"]
    assert out["baseline_gflop_per_step"] > 10 * out["gflop_per_step"]
    assert out["gflop_per_s"] == pytest.approx(out["gflop_per_step"] * out["steps_per_s"], rel=0.02)
    assert out["peak_gflop_per_s"] > 0
    assert out["peak_fraction"] == pytest.approx(out["gflop_per_s"] / out["peak_gflop_per_s"], rel=0.02)
    assert 0 < out["peak_fraction"] < 1.5
