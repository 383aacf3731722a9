"""A research probe behind docs/experiments/plateau.md, "Where the fine-tunes plateau": the study's fine-tune with
implicit Q-learning's targets (Kostrikov et al. 2022) instead of QT-Opt's, to test whether a learner that bootstraps
only through actions the data took improves more than one step over the policy that collected the target data.

From a parent checkpoint, on the given data mix (one-step transitions):

    V(s)    = sigmoid(v(s, 0)), fitted to the tau-expectile of Q_polyak(s, a) over the data's actions a
    Q(s, a) trained by log loss towards r + gamma * (1 - done) * V(s')      (no CEM maximum in the target)

``v`` is a copy of the parent scoring the zero action; it is fitted alone for --v-warmup steps first. Both
networks train at 25% of the parent's rate with its crop and colour augmentation, batches of 64. The Q-network
is written as a checkpoint folder OUT that `probe_policies.py cem --shift S --seed 3000 OUT` evaluates.

    .venv/bin/python scripts/experiments/probe_iql.py --init ckpt:rounds-r4@6000 --data REF=W ... --tau 0.8 --out DIR
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from nsl import keys
from nsl.catalog import Catalog
from nsl.datasets import api
from nsl.learners import checkpoint_config, checkpoint_id, load_checkpoint, save_checkpoint
from nsl.learners.augment import prepare_images
from nsl.learners.cem import active_actions
from nsl.learners.qtopt import batch_to_torch, polyak_update


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--init", required=True, help="parent checkpoint, e.g. ckpt:rounds-r4@6000")
    p.add_argument("--data", action="append", required=True, help="REF=WEIGHT, repeatable (the study's 50/50 mix)")
    p.add_argument("--steps", type=int, default=1000, help="joint Q and V steps after the warm-up")
    p.add_argument("--v-warmup", type=int, default=300, help="steps fitting V alone first")
    p.add_argument("--tau", type=float, default=0.8, help="expectile of V (0.5 = the data's mean, towards 1 = its max)")
    p.add_argument("--seed", type=int, default=0, help="seed of sampling and augmentation")
    p.add_argument("--out", required=True, type=Path, help="checkpoint folder to write")
    args = p.parse_args()

    with Catalog() as cat:
        parent = load_checkpoint(Path(cat.resolve_checkpoint(args.init).path))
    cfg = parent.training.replace(n_step=1, lr=0.25 * parent.lr, steps=args.steps, seed=args.seed)
    mix = [(ref, float(w)) for ref, w in (d.split("=") for d in args.data)]
    sampler = api.make_sampler(mix, n_step=1, gamma=cfg.gamma)
    torch.manual_seed(args.seed)
    q = parent.net.train()
    v = copy.deepcopy(q)
    q_polyak = copy.deepcopy(q).requires_grad_(False)
    opt_q = torch.optim.Adam(q.parameters(), lr=cfg.lr)
    opt_v = torch.optim.Adam(v.parameters(), lr=cfg.lr)
    rng, gen = np.random.default_rng(args.seed), torch.Generator().manual_seed(args.seed)

    bar = tqdm(range(args.v_warmup + args.steps), desc="iql", unit="step")
    for step in bar:
        b = batch_to_torch(sampler.sample(cfg.batch_size, rng))
        image = prepare_images(b[keys.OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen)
        state, action = b[keys.OBS_STATE], active_actions(b[keys.ACTION], q.cfg)
        zero = torch.zeros_like(action)
        with torch.no_grad():
            q_data = torch.sigmoid(q_polyak(image, state, action))
        diff = q_data - torch.sigmoid(v(image, state, zero))
        v_loss = (torch.abs(args.tau - (diff < 0).float()) * diff**2).mean()
        opt_v.zero_grad(set_to_none=True)
        v_loss.backward()
        opt_v.step()
        if step < args.v_warmup:
            continue
        with torch.no_grad():
            next_image = prepare_images(b[keys.NEXT_OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, gen)
            v_next = torch.sigmoid(v(next_image, b[keys.NEXT_OBS_STATE], zero))
            target = b[keys.REWARD] + cfg.gamma * (1.0 - b[keys.DONE]) * v_next
        q_loss = F.binary_cross_entropy_with_logits(q(image, state, action), target)
        opt_q.zero_grad(set_to_none=True)
        q_loss.backward()
        torch.nn.utils.clip_grad_norm_(q.parameters(), cfg.grad_clip)
        opt_q.step()
        polyak_update(q_polyak, q, cfg.polyak)
        if step % 100 == 0:
            bar.set_postfix(q_loss=f"{q_loss.item():.4f}", v_loss=f"{v_loss.item():.5f}", v=f"{v_next.mean():.3f}")
    parent_info = {"id": checkpoint_id(parent.path), "step": parent.step, "method": parent.config["method"]}
    config = checkpoint_config(
        q,
        training=cfg,
        method="ft",
        data={**sampler.describe(), "probe": "iql", "tau": args.tau, "v_warmup": args.v_warmup},
        parent=parent_info,
        step=args.steps,
    )
    save_checkpoint(args.out, q.eval(), config)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
