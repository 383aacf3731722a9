"""``nsl bench learner``: QT-Opt training steps per second against a plain PyTorch loop.

Both sides train the same network (the default ``NetConfig``, 64x64 images)
at batch 64 on the same synthetic transitions, with the same augmentation,
log loss and clipped double-Q targets with CEM (64 samples, 6 elites, 2
iterations).  They differ in how the step is computed:

* ``steps_per_s``: ``nsl.learners.update``: CEM batched over the whole batch,
  the conv trunk run once per next state and only the head per candidate,
  terminal transitions skipped, channels_last images, ``torch.no_grad``
  targets.
* ``baseline_steps_per_s``: a plain loop: default memory format, and the
  target's CEM maximum computed per sample in a Python loop, each candidate
  scored by the network's ordinary forward pass (image, state, action).
* ``reuse_loop_steps_per_s`` (for reference): the same per-sample loop, but
  running the trunk once per sample and the head per candidate.

All three are measured in this run, on this machine, one after the other.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
import torch.nn.functional as F

from nsl import keys

HELP = "QT-Opt training steps/s (batch 64, 64x64, CEM targets) against a plain PyTorch loop"
BATCH = 64
IMAGE = 64


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--steps", type=int, default=0, help="timed steps of nsl's update (default 60, quick 20)")
    p.add_argument("--baseline-steps", type=int, default=0, help="timed steps of the plain loop (default 3, quick 1)")
    p.add_argument("--threads", type=int, default=0, help="torch threads (default: torch's choice)")


def _synthetic_sampler(n: int = 512, seed: int = 0):
    from nsl.learners import ArraySampler

    rng = np.random.default_rng(seed)
    images = rng.integers(0, 256, (n, IMAGE, IMAGE, 3), dtype=np.uint8)
    ep = np.arange(n) % 8
    return ArraySampler(images, rng.random((n, len(keys.STATE_NAMES)), dtype=np.float32), rng.uniform(-1, 1, (n, 6)).astype(np.float32),
                        ((ep == 7) & (rng.random(n) < 0.5)).astype(np.float32), (ep == 7).astype(np.float32),
                        np.minimum(np.arange(n) + 1, n - 1), name="synthetic")


def _time(step_fn, warmup: int, steps: int) -> float:
    for i in range(warmup):
        step_fn(i)
    t = time.perf_counter()
    for i in range(steps):
        step_fn(warmup + i)
    return steps / (time.perf_counter() - t)


def _plain_loop_step(learner, batch, cfg, step: int, gen: torch.Generator, reuse_trunk: bool) -> None:
    """A straightforward QT-Opt step: per-sample CEM for the target, default memory format."""
    from nsl.learners.augment import prepare_images

    net, polyak, lagged, cem = learner.online, learner.polyak, learner.lagged, cfg.cem
    image = prepare_images(batch[keys.OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen, channels_last=False)
    next_image = prepare_images(batch[keys.NEXT_OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen,
                                channels_last=False)
    action = batch[keys.ACTION][:, list(net.cfg.action_dims)]
    reward, done, next_state = batch[keys.REWARD], batch[keys.DONE], batch[keys.NEXT_OBS_STATE]
    dims = action.shape[1]
    targets = []
    with torch.no_grad():
        for i in range(len(reward)):
            if done[i] > 0.5:
                targets.append(reward[i])
                continue
            img, st = next_image[i:i + 1], next_state[i:i + 1]
            ctx = polyak.encode(img, st) if reuse_trunk else None
            mean, std = torch.zeros(dims), torch.full((dims,), cem.init_std)
            best_a, best_q = None, -float("inf")
            for _ in range(cem.iterations):
                cand = (mean + std * torch.randn(cem.samples, dims, generator=gen)).clamp(-1, 1)
                if reuse_trunk:
                    q = polyak.score(ctx, cand.unsqueeze(0))[0]
                else:
                    q = polyak(img.expand(cem.samples, -1, -1, -1), st.expand(cem.samples, -1), cand)
                top = q.topk(cem.elites).indices
                if q[top[0]] > best_q:
                    best_q, best_a = q[top[0]].item(), cand[top[0]]
                mean, std = cand[top].mean(0), cand[top].std(0, unbiased=False).clamp_min(cem.min_std)
            v = torch.minimum(polyak(img, st, best_a[None]), lagged(img, st, best_a[None])).sigmoid()[0]
            targets.append(reward[i] + cfg.gamma * v)
    target = torch.stack(targets)
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
    from nsl.learners import Learner, NetConfig, QNetwork, TrainConfig, update
    from nsl.learners.qtopt import batch_to_torch

    if args.threads:
        torch.set_num_threads(args.threads)
    steps = args.steps or (20 if args.quick else 60)
    base_steps = args.baseline_steps or (1 if args.quick else 3)
    cfg = TrainConfig(batch_size=BATCH, seed=0)
    net_cfg = NetConfig(image_size=IMAGE)
    sampler = _synthetic_sampler()
    rng = np.random.default_rng(0)
    batches = [batch_to_torch(sampler.sample(BATCH, rng)) for _ in range(8)]

    def make_learner():
        torch.manual_seed(0)
        return Learner.create(QNetwork(net_cfg), 3e-4, cfg)

    ours = make_learner()
    ours_sps = _time(lambda i: update(ours, batches[i % len(batches)], cfg, i), warmup=3, steps=steps)

    gen = torch.Generator().manual_seed(0)
    reuse = make_learner()
    reuse_sps = _time(lambda i: _plain_loop_step(reuse, batches[i % len(batches)], cfg, i, gen, reuse_trunk=True),
                      warmup=1, steps=max(base_steps, 2))
    plain = make_learner()
    with torch.no_grad():  # warm the plain forward pass at the candidate batch size (its step takes seconds)
        b = batches[0]
        plain.polyak(torch.rand(cfg.cem.samples, 3, IMAGE, IMAGE), b[keys.OBS_STATE][:1].expand(cfg.cem.samples, -1),
                     torch.zeros(cfg.cem.samples, len(net_cfg.action_dims)))
    base_sps = _time(lambda i: _plain_loop_step(plain, batches[i % len(batches)], cfg, i, gen, reuse_trunk=False),
                     warmup=0 if args.quick else 1, steps=base_steps)
    return {
        "steps_per_s": round(ours_sps, 3),
        "baseline_steps_per_s": round(base_sps, 3),
        "reuse_loop_steps_per_s": round(reuse_sps, 3),
        "speedup": round(ours_sps / base_sps, 2),
        "speedup_vs_reuse_loop": round(ours_sps / reuse_sps, 2),
        "target_speedup": 2.0,
        "batch": BATCH,
        "image_size": IMAGE,
        "cem": f"{cfg.cem.samples}/{cfg.cem.elites}/{cfg.cem.iterations}",
        "threads": torch.get_num_threads(),
        "timed_steps": steps,
        "timed_baseline_steps": base_steps,
    }
