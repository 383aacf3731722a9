"""``nsl bench learner``: QT-Opt training steps per second, against a plain batched PyTorch step.

Both sides train the same network (the default ``NetConfig``, 64x64 images)
at batch 64 on the same synthetic transitions, with the same augmentation,
log loss and clipped double-Q targets with CEM (64 samples, 6 elites, 2
iterations).  They differ only in how the step is computed:

* ``steps_per_s``: ``nsl.learners.update``: the conv trunk runs once per next
  state and only the head per candidate, terminal transitions are skipped,
  images are channels_last.
* ``baseline_steps_per_s``: the plain step a careful implementation writes
  first: CEM batched over the whole batch (no Python loop over samples), each
  candidate scored by the network's ordinary forward pass on the tiled next
  image, so the trunk runs once per candidate, in the default memory format.
* ``reuse_steps_per_s`` (for reference): the same batched step, but with the
  trunk run once per next state and the head per candidate, as nsl does;
  ``speedup_vs_reuse`` is what the rest of nsl's step adds.

Figures of work, from ``torch.utils.flop_counter.FlopCounterMode`` on one step
of each side (forward and backward): ``gflop_per_step`` (nsl's step),
``gflop_per_s`` (achieved), ``peak_gflop_per_s`` (a large float32 matmul
timed in the same run, with the same threads) and ``peak_fraction``
(``peak_fraction_fp32``).

On a CPU with bfloat16 arithmetic, the same update with ``precision="bf16"``
(CPU autocast): ``bf16_steps_per_s``, ``bf16_speedup_vs_fp32`` (against
``steps_per_s``, the float32 step, in this run), ``bf16_gflop_per_s`` and
``peak_fraction_bf16`` against a bfloat16 matmul timed in this run.
Everything is measured in this run, on this machine, one after the other.
"""

from __future__ import annotations

import argparse
import time

from nsl import keys

HELP = "QT-Opt training steps/s (batch 64, 64x64, CEM targets) against a plain batched PyTorch step"
BATCH = 64
IMAGE = 64
PEAK_MATMUL = 1024  # square float32 matmul used to measure the machine's peak


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--steps", type=int, default=0, help="timed steps of nsl's update (0 = 60, with --quick 20)")
    p.add_argument(
        "--baseline-steps", type=int, default=0, help="timed steps of the plain batched step (0 = 5, with --quick 2)"
    )
    p.add_argument("--threads", type=int, default=0, help="torch threads (0 = torch's choice)")
    p.add_argument(
        "--device",
        default="cpu",
        choices=("cpu", "cuda", "auto"),
        help="cpu: nsl's step against a plain batched step (above); cuda (or auto with a GPU): nsl's step on the "
        "GPU, eager and as one CUDA graph, at batch 64 and 1,024 in fp32 and bf16, with the profiler's kernel "
        "time, the busy fraction and the matmul peaks (needs only torch)",
    )


def _synthetic_sampler(n: int = 512, seed: int = 0):
    from nsl.learners import synthetic_sampler

    return synthetic_sampler(n, seed, IMAGE)


def _time(step_fn, warmup: int, steps: int) -> float:
    for i in range(warmup):
        step_fn(i)
    t = time.perf_counter()
    for i in range(steps):
        step_fn(warmup + i)
    return steps / (time.perf_counter() - t)


def _time_alternating(step_fns: dict, warmup: int, rounds: int, steps: int) -> dict[str, float]:
    """Best steps/s of each step function over ``rounds`` rounds of ``steps`` steps, the functions taking turns.

    Taking turns and keeping each side's best round makes the ratio of two sides robust to other processes: a
    burst of load slows one round of one side, not all of it.
    """
    for fn in step_fns.values():
        for i in range(warmup):
            fn(i)
    best = dict.fromkeys(step_fns, 0.0)
    for r in range(rounds):
        for name, fn in step_fns.items():
            t = time.perf_counter()
            for i in range(steps):
                fn(warmup + r * steps + i)
            best[name] = max(best[name], steps / (time.perf_counter() - t))
    return best


def _gflop(step_fn) -> float:
    """Floating-point operations of one call of ``step_fn`` (forward and backward), in GFLOP."""
    from torch.utils.flop_counter import FlopCounterMode

    counter = FlopCounterMode(display=False)
    with counter:
        step_fn()
    return counter.get_total_flops() / 1e9


def _peak_gflop_per_s(repeats: int, dtype=None) -> float:
    """Achieved GFLOP/s of a large matmul in ``dtype`` (default float32): this machine's practical peak."""
    import torch

    dtype = dtype or torch.float32
    gen = torch.Generator().manual_seed(0)
    a = torch.rand(PEAK_MATMUL, PEAK_MATMUL, generator=gen).to(dtype)
    b = torch.rand(PEAK_MATMUL, PEAK_MATMUL, generator=gen).to(dtype)
    out = torch.empty(PEAK_MATMUL, PEAK_MATMUL, dtype=dtype)
    torch.mm(a, b, out=out)  # warm-up
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        torch.mm(a, b, out=out)
        best = min(best, time.perf_counter() - t)
    return 2 * PEAK_MATMUL**3 / best / 1e9


def _plain_batched_step(learner, batch, cfg, step: int, reuse_trunk: bool = False) -> None:
    """A plain QT-Opt step: CEM batched over the batch, every candidate scored by the full forward pass.

    With ``reuse_trunk`` the trunk runs once per next state and only the head per candidate (nsl's
    main saving), leaving the remaining differences: terminal transitions, memory format, fused updates.
    """
    import torch
    import torch.nn.functional as F

    from nsl.learners.augment import prepare_images

    net, polyak, lagged, cem, gen = learner.online, learner.polyak, learner.lagged, cfg.cem, learner.generator
    image = prepare_images(batch[keys.OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen, channels_last=False)
    next_image = prepare_images(
        batch[keys.NEXT_OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen, channels_last=False
    )
    action = batch[keys.ACTION][:, list(net.cfg.action_dims)]
    reward, done, next_state = batch[keys.REWARD], batch[keys.DONE], batch[keys.NEXT_OBS_STATE]
    b, dims, n = len(reward), action.shape[1], cem.samples
    with torch.no_grad():
        if reuse_trunk:
            ctx = polyak.encode(next_image, next_state)
        else:
            tiled_image = next_image.repeat_interleave(n, 0)  # (B*N, 3, H, W): one copy per candidate
            tiled_state = next_state.repeat_interleave(n, 0)
        mean, std = torch.zeros(b, 1, dims), torch.full((b, 1, dims), cem.init_std)
        best_a, best_q = torch.zeros(b, dims), torch.full((b,), -float("inf"))
        for _ in range(cem.iterations):
            cand = (mean + std * torch.randn(b, n, dims, generator=gen)).clamp(-1, 1)
            if reuse_trunk:
                q = polyak.score(ctx, cand)
            else:
                q = polyak(tiled_image, tiled_state, cand.reshape(b * n, dims)).view(b, n)
            top_q, top_i = q.topk(cem.elites, dim=1)
            better = top_q[:, 0] > best_q
            best_q = torch.where(better, top_q[:, 0], best_q)
            best_a = torch.where(better[:, None], cand[torch.arange(b), top_i[:, 0]], best_a)
            elites = cand.gather(1, top_i[..., None].expand(-1, -1, dims))
            mean, std = elites.mean(1, keepdim=True), elites.std(1, unbiased=False, keepdim=True).clamp_min(cem.min_std)
        value = torch.minimum(polyak(next_image, next_state, best_a), lagged(next_image, next_state, best_a)).sigmoid()
        target = reward + cfg.gamma * (1.0 - done) * value
    loss = F.binary_cross_entropy_with_logits(net(image, batch[keys.OBS_STATE], action), target)
    learner.optimizer.zero_grad()
    loss.backward()
    torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.grad_clip)
    learner.optimizer.step()
    with torch.no_grad():
        for p_t, p in zip(polyak.parameters(), net.parameters()):
            p_t.mul_(cfg.polyak).add_(p, alpha=1 - cfg.polyak)
    if (step + 1) % cfg.lag_period == 0:
        lagged.load_state_dict(net.state_dict())


def run(args: argparse.Namespace) -> dict:
    import numpy as np
    import torch

    from nsl.learners.device import resolve_device

    device = resolve_device(getattr(args, "device", "cpu"))
    if device != "cpu":
        from ._device import learner_figures

        return learner_figures(device, steps=args.steps or (30 if args.quick else 200), quick=args.quick)

    threads = torch.get_num_threads()
    if args.threads:
        torch.set_num_threads(args.threads)
    try:
        return _run(args, torch, np)
    finally:
        torch.set_num_threads(threads)  # the caller's process keeps its own setting


def _run(args: argparse.Namespace, torch, np) -> dict:
    from nsl.learners import Learner, NetConfig, QNetwork, TrainConfig, update
    from nsl.learners.precision import bf16_supported
    from nsl.learners.qtopt import batch_to_torch

    steps = args.steps or (20 if args.quick else 60)
    base_steps = args.baseline_steps or (2 if args.quick else 5)
    cfg = TrainConfig(batch_size=BATCH, seed=0)
    net_cfg = NetConfig(image_size=IMAGE)
    sampler = _synthetic_sampler()
    rng = np.random.default_rng(0)
    batches = [batch_to_torch(sampler.sample(BATCH, rng)) for _ in range(8)]

    def make_learner(config=cfg):
        torch.manual_seed(0)
        return Learner.create(QNetwork(net_cfg), 3e-4, config)

    ours = make_learner()
    gflop = _gflop(lambda: update(ours, batches[0], cfg, 0))
    sides = {"fp32": lambda i: update(ours, batches[i % len(batches)], cfg, i)}
    if bf16_supported():
        cfg16 = cfg.replace(precision="bf16")
        ours16 = make_learner(cfg16)  # the same start; with fused Adam, as training in bf16 does
        sides["bf16"] = lambda i: update(ours16, batches[i % len(batches)], cfg16, i)
    rounds = 4
    best = _time_alternating(sides, warmup=3, rounds=rounds, steps=max(1, steps // rounds))
    ours_sps = best["fp32"]

    plain = make_learner()
    base_gflop = _gflop(lambda: _plain_batched_step(plain, batches[0], cfg, 0))
    base_sps = _time(
        lambda i: _plain_batched_step(plain, batches[i % len(batches)], cfg, i), warmup=1, steps=base_steps
    )
    reuse = make_learner()
    reuse_sps = _time(
        lambda i: _plain_batched_step(reuse, batches[i % len(batches)], cfg, i, reuse_trunk=True),
        warmup=1,
        steps=max(base_steps, 2),
    )
    peak = _peak_gflop_per_s(repeats=5 if args.quick else 20)
    achieved = gflop * ours_sps
    bf16 = {}
    if bf16_supported():
        sps16 = best["bf16"]
        peak16 = _peak_gflop_per_s(repeats=5 if args.quick else 20, dtype=torch.bfloat16)
        bf16 = {
            "bf16_steps_per_s": round(sps16, 3),
            "bf16_speedup_vs_fp32": round(sps16 / ours_sps, 2),
            "bf16_gflop_per_s": round(gflop * sps16, 2),
            "peak_bf16_gflop_per_s": round(peak16, 2),
            "peak_fraction_bf16": round(gflop * sps16 / peak16, 4),
        }
    return {
        **bf16,
        "bf16_supported": bf16_supported(),
        "peak_fraction_fp32": round(achieved / peak, 4),
        "steps_per_s": round(ours_sps, 3),
        "baseline_steps_per_s": round(base_sps, 3),
        "speedup": round(ours_sps / base_sps, 2),
        "target_speedup": 2.0,
        "reuse_steps_per_s": round(reuse_sps, 3),
        "speedup_vs_reuse": round(ours_sps / reuse_sps, 2),
        "gflop_per_step": round(gflop, 3),
        "baseline_gflop_per_step": round(base_gflop, 3),
        "gflop_per_s": round(achieved, 2),
        "baseline_gflop_per_s": round(base_gflop * base_sps, 2),
        "peak_gflop_per_s": round(peak, 2),
        "peak_fraction": round(achieved / peak, 4),
        "batch": BATCH,
        "image_size": IMAGE,
        "cem": f"{cfg.cem.samples}/{cfg.cem.elites}/{cfg.cem.iterations}",
        "threads": torch.get_num_threads(),
        "timed_steps": steps,
        "timed_baseline_steps": base_steps,
    }
