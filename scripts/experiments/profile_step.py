"""Where a QT-Opt training step's time goes, in float32 and in bfloat16, by kind of operation.

Profiles ``nsl.learners.update`` on the bench's synthetic batches (``nsl bench learner``: batch 64, 64x64 images,
CEM 64/6/2 targets, augmentation on, no conservative term) with ``torch.profiler`` over 10 steps after 5 warm-up
steps, in this process's torch threads, and prints milliseconds per step for each kind of operation, then the
largest copies by shape.  About 20 seconds:

    .venv/bin/python scripts/experiments/profile_step.py
"""

from __future__ import annotations

import numpy as np
import torch
from torch.profiler import profile

from nsl.learners import Learner, NetConfig, QNetwork, TrainConfig, synthetic_sampler, update
from nsl.learners.qtopt import batch_to_torch

STEPS = 10
BATCH = 64


KINDS = {  # profiler op name -> row of the table
    "aten::mkldnn_convolution": "convolutions, forward (online, Polyak and lagged trunks)",
    "aten::convolution_backward": "convolutions, backward",
    "aten::copy_": "copies and casts (images, the trunk's input, weights)",
    "aten::clamp_min": "ReLU, forward and backward",
    "aten::threshold_backward": "ReLU, forward and backward",
    "aten::addmm": "matrix products (the heads, CEM's candidates)",
    "aten::mm": "matrix products (the heads, CEM's candidates)",
    "aten::index_select": "augmentation (random shift, colour jitter)",
    "aten::addcmul": "augmentation (random shift, colour jitter)",
    "Optimizer.step#Adam.step": "Adam",
}


def profile_steps(precision: str) -> tuple[float, dict[str, float], list]:
    cfg = TrainConfig(batch_size=BATCH, seed=0, precision=precision)
    sampler, rng = synthetic_sampler(), np.random.default_rng(0)
    batches = [batch_to_torch(sampler.sample(BATCH, rng)) for _ in range(8)]
    torch.manual_seed(0)
    learner = Learner.create(QNetwork(NetConfig()), 3e-4, cfg)
    for i in range(5):
        update(learner, batches[i % 8], cfg, i)
    with profile(record_shapes=True) as prof:
        for i in range(STEPS):
            update(learner, batches[i % 8], cfg, 5 + i)
    events = prof.key_averages()
    total = sum(e.self_cpu_time_total for e in events) / STEPS / 1000
    rows: dict[str, float] = {}
    for e in events:
        kind = KINDS.get(e.key)
        if kind is not None:
            t = (e.cpu_time_total if e.key.startswith("Optimizer") else e.self_cpu_time_total) / STEPS / 1000
            rows[kind] = rows.get(kind, 0.0) + t
    copies = sorted(
        (e for e in prof.key_averages(group_by_input_shape=True) if e.key == "aten::copy_"),
        key=lambda e: -e.self_cpu_time_total,
    )[:4]
    return total, rows, copies


def main() -> None:
    results = {p: profile_steps(p) for p in ("fp32", "bf16")}
    print("| ms per step | float32 | bfloat16 |")
    print("|---|---|---|")
    print(f"| a step, under the profiler | {results['fp32'][0]:.1f} | {results['bf16'][0]:.1f} |")
    for kind in dict.fromkeys(KINDS.values()):
        print(f"| {kind} | {results['fp32'][1].get(kind, 0):.1f} | {results['bf16'][1].get(kind, 0):.1f} |")
    for p, (_, _, copies) in results.items():
        print(f"\nlargest copies, {p}:")
        for e in copies:
            ms, calls = e.self_cpu_time_total / STEPS / 1000, e.count / STEPS
            print(f"  {ms:.2f} ms/step, {calls:.1f} calls: {e.input_shapes}")


if __name__ == "__main__":
    main()
