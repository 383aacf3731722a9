"""The figures of ``nsl bench learner --device`` and ``nsl bench eval --device``: nsl's step and acting on a device.

Only torch and nsl's learner are needed (no simulator, no dataset library), so
these run on a bare GPU machine.  Everything is measured in one run, one side
after the other, on synthetic transitions (``nsl.learners.synthetic_sampler``):

* ``learner``: steps/s of ``nsl.learners.update``'s step, eager and (on CUDA)
  replayed from one CUDA graph (``learners/cuda_graph.py``), at batch 64 and
  1,024 in fp32 and bf16; transitions/s; from ``torch.profiler``, the device's
  kernel time a step, the busy fraction (kernel time / wall time) and the
  kernel-time limit (1 / kernel time a step); and the matmul peak of each
  precision (8,192-square on CUDA).
* ``acting``: states/s of the CEM policy searching one state a call (the CPU's
  default) and a batch of states a call (the GPU's), and their ratio.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import torch

IMAGE = 64
BATCHES = (64, 1024)


def _sync(device: str) -> None:
    if device == "cuda":
        torch.cuda.synchronize()


def _rate(fn: Callable[[int], object], device: str, warmup: int, steps: int) -> float:
    """Calls/s of ``fn(i)`` over ``steps`` calls after ``warmup``, waiting for the device at both ends."""
    for i in range(warmup):
        fn(i)
    _sync(device)
    t = time.perf_counter()
    for i in range(steps):
        fn(warmup + i)
    _sync(device)
    return steps / (time.perf_counter() - t)


def _kernel_seconds(fn: Callable[[int], object], device: str, steps: int) -> float | None:
    """The device's kernel time per call of ``fn`` (torch.profiler), or None off CUDA."""
    if device != "cuda":
        return None
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CUDA]) as prof:
        for i in range(steps):
            fn(i)
        _sync(device)
    total_us = 0.0
    for e in prof.key_averages():
        total_us += float(getattr(e, "self_device_time_total", getattr(e, "self_cuda_time_total", 0.0)))
    return total_us / 1e6 / steps


def matmul_peak_tflops(device: str, dtype: torch.dtype, size: int, repeats: int) -> float:
    """Achieved TFLOP/s of a ``size``-square matmul in ``dtype`` on ``device``."""
    gen = torch.Generator(device=device).manual_seed(0)
    a = torch.rand(size, size, generator=gen, device=device).to(dtype)
    b = torch.rand(size, size, generator=gen, device=device).to(dtype)
    torch.mm(a, b)
    _sync(device)
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        torch.mm(a, b)
        _sync(device)
        best = min(best, time.perf_counter() - t)
    return 2 * size**3 / best / 1e12


def learner_figures(device: str, steps: int, quick: bool) -> dict:
    """Steps/s, transitions/s and kernel figures of the QT-Opt step on ``device`` (see the module docstring)."""
    import numpy as np

    from nsl.learners import Learner, NetConfig, QNetwork, TrainConfig, synthetic_sampler
    from nsl.learners.cuda_graph import DeviceData, GraphedStep
    from nsl.learners.device import to_device
    from nsl.learners.precision import resolve_precision
    from nsl.learners.qtopt import batch_to_torch, step_metrics

    precisions = ["fp32"] + (["bf16"] if resolve_precision("auto", device) == "bf16" else [])
    batches = BATCHES[:1] if quick else BATCHES
    sampler = synthetic_sampler(4096 if not quick else 512, 0, IMAGE)
    data = DeviceData(sampler.tables(), device)
    out: dict = {"device": device, "precisions": precisions, "batches": list(batches)}
    if device == "cuda":
        out["gpu"] = torch.cuda.get_device_name()
    for batch in batches:
        rng = np.random.default_rng(0)
        # The eager step reads batches already on the device, as the graphed one does.
        ready = [to_device(batch_to_torch(sampler.sample(batch, rng)), device) for _ in range(4)]
        for precision in precisions:
            cfg = TrainConfig(batch_size=batch, seed=0, precision=precision, device=device, conservative=0.1)
            torch.manual_seed(0)
            learner = Learner.create(QNetwork(NetConfig(image_size=IMAGE)), 3e-4, cfg)
            key = f"b{batch}_{precision}"
            eager = lambda i, lr=learner, c=cfg, r=ready: step_metrics(lr, r[i % len(r)], c, i)  # noqa: E731
            sides = {"eager": round(_rate(eager, device, 3, steps), 2)}
            kernel = _kernel_seconds(eager, device, max(5, steps // 4))  # the eager step's kernels: the limit
            if device == "cuda":
                sides["graph"] = round(_rate(GraphedStep(learner, data, cfg), device, 5, steps), 2)
            best = max(sides.values())
            out |= {f"{key}_{side}_steps_per_s": v for side, v in sides.items()}
            out[f"{key}_steps_per_s"] = best
            out[f"{key}_transitions_per_s"] = round(best * batch)
            if kernel is not None:
                out[f"{key}_kernel_ms_per_step"] = round(kernel * 1e3, 3)
                out[f"{key}_kernel_limit_steps_per_s"] = round(1.0 / kernel, 1)
                # kernel time / wall time a step, which is also the fraction of the kernel-time limit reached
                out |= {f"{key}_{side}_busy_fraction": round(kernel * v, 3) for side, v in sides.items()}
    size, repeats = (8192, 10) if device == "cuda" else (512, 3)
    out["matmul_size"] = size
    for precision in precisions:
        dtype = torch.bfloat16 if precision == "bf16" else torch.float32
        out[f"matmul_peak_{precision}_tflops"] = round(matmul_peak_tflops(device, dtype, size, repeats), 2)
    out["timed_steps"] = steps
    return out


def acting_figures(device: str, states: int, quick: bool) -> dict:
    """States/s of CEM acting one state a call against ``states`` states a call, on ``device``."""
    import numpy as np

    from nsl import keys
    from nsl.learners import CEMPolicy, NetConfig, QNetwork

    torch.manual_seed(0)
    net = QNetwork(NetConfig(image_size=IMAGE))
    rng = np.random.default_rng(0)
    obs = {
        "image": rng.integers(0, 256, (states, IMAGE, IMAGE, 3), dtype=np.uint8),
        "state": rng.random((states, len(keys.STATE_NAMES)), dtype=np.float32),
    }
    out: dict = {"device": device, "states_per_call": states}
    calls = 2 if quick else 5
    for name, batched in (("per_state", False), ("batched", True)):
        policy = CEMPolicy(net, device=device, batched=batched)

        def act(i: int, p: CEMPolicy = policy) -> None:
            p(obs, rngs=[np.random.default_rng([i, k]) for k in range(states)])

        out[f"{name}_states_per_s"] = round(_rate(act, device, 1, calls) * states, 1)
    out["batched_speedup"] = round(out["batched_states_per_s"] / out["per_state_states_per_s"], 2)
    return out
