"""Why a fine-tune does or does not move a base: Q-function measurements before and after fine-tuning.

Reported in docs/experiments/plasticity.md, "Why fine-tuning fails on some shifts: a diagnosis".  For every checkpoint
given and every dataset given, on (up to ``--transitions``) transitions of the dataset, without augmentation:

* ``logits``: the logit of Q(s, a) for the data's actions, and ``max_logits`` for CEM's best action (what the
  Bellman target reads): mean, std, percentiles, the share with |logit| > 5 (sigmoid slope < 0.007) and the
  mean sigmoid slope p (1 - p);
* ``values``: mean Q(s, a), the one-step Bellman targets r + gamma (1 - done) Q(s', a*) (the checkpoint as both
  target networks), and the Monte-Carlo discounted returns of the data; ``optimism`` = mean target - mean return
  (positive: the checkpoint promises more than the data's episodes delivered); the mean |Q - target| (the size
  of the log-loss gradient on the logit) and the first frames' V(s0) = max_a Q against the data's success rate;
* ``action_spread``: the standard deviation of the logit over 32 uniform random actions, averaged over states (how
  much Q depends on the action at all), and the gap between CEM's best logit and the data action's;
* ``auc``: how well Q(s, a) ranks transitions of successful episodes above those of failed ones (0.5 = chance);
* ``dormant``: per layer (conv0-3 and the head's hidden layers), the share of units whose mean |activation| is at
  most tau times the layer's mean (Sokar et al. 2023), for tau in ``--tau``;
* ``rank``: effective rank (Roy and Vetterli 2007) and srank (delta = 0.01, Kumar et al. 2021) of the trunk's
  flattened features and of the head's last hidden layer;
* ``gradient``: the norm of the log-loss gradient against those targets, per layer and in total.

And for every checkpoint after the first, ``weight_change``: ||w - w_first|| / ||w_first|| per layer and over
all weights (the first checkpoint is the reference, normally the parent).

    PYTHONPATH=$PWD MUJOCO_GL=egl NSL_HOME=... python scripts/experiments/plasticity_diagnose.py \\
        --checkpoint ckpt:base --checkpoint ckpt:ft-offset25@latest \\
        --data grasp-base-oracle:400 --data tgt-offset25 --out diag-offset25.json

Checkpoints are catalog refs (ckpt:NAME[@STEP]) or checkpoint folders; datasets are NAME[@vN][:K] refs.  The
JSON goes to ``--out`` (written under a temporary name, then renamed) and a short table to stdout.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from nsl import keys
from nsl.datasets import api
from nsl.errors import ConfigError, NslError
from nsl.learners import load_checkpoint
from nsl.learners.augment import to_float
from nsl.learners.cem import active_actions, cem_maximize, noise_from_generator
from nsl.learners.config import TrainConfig
from nsl.learners.qtopt import bellman_target
from nsl.workspace import atomic_write_json

SATURATED = 5.0  # |logit| above which the sigmoid's slope is below 0.007
SRANK_DELTA = 0.01
CHUNK = 256


def resolve_checkpoint(ref: str) -> Path:
    """A checkpoint folder from a catalog ref (ckpt:NAME[@STEP]) or a folder path."""
    if Path(ref).is_dir():
        return Path(ref)
    if not ref.startswith("ckpt:"):
        raise ConfigError(f"checkpoint {ref!r} is neither a folder nor a catalog ref; write ckpt:NAME[@STEP]")
    from nsl.catalog import Catalog

    with Catalog() as cat:
        return Path(cat.resolve_checkpoint(ref).path)


def load_transitions(ref: str, limit: int, seed: int, gamma: float) -> dict:
    """Up to ``limit`` transitions of dataset ``ref`` (a seeded random subset), with next frames, episode success
    and the Monte-Carlo discounted return of each."""
    view = api.open_view(ref)
    a = view.episodes_arrays()
    labels = api.frame_labels(a, gamma=gamma)  # episode success, next-frame masks and Monte-Carlo returns
    ep, n = labels.episode, len(labels.episode)
    reward, done, following, success, ret = (
        labels.reward,
        labels.done,
        labels.following,
        labels.success,
        labels.mc_return,
    )
    success_of = labels.episode_success
    first = labels.first
    usable = np.flatnonzero(labels.known)  # a truncated episode's last frame has no known target
    rng = np.random.default_rng(seed)
    pick = np.sort(rng.choice(usable, size=min(limit, len(usable)), replace=False))
    nxt = np.where(following[pick], pick + 1, pick)
    return {
        "ref": ref,
        "episodes": int(len(success_of)),
        "frames": int(n),
        "success_rate": float(np.mean(list(success_of.values()))),
        "image": a[keys.OBS_IMAGE][pick],
        "state": a[keys.OBS_STATE][pick].astype(np.float32),
        "next_image": a[keys.OBS_IMAGE][nxt],
        "next_state": a[keys.OBS_STATE][nxt].astype(np.float32),
        "action": a[keys.ACTION][pick].astype(np.float32),
        "reward": reward[pick].astype(np.float32),
        "done": done[pick].astype(np.float32),
        "success": success[pick],
        "mc_return": ret[pick],
        "first": first[pick],
        "first_success": np.array([success_of[e] for e in ep[first]]),
        "first_image": a[keys.OBS_IMAGE][first],
        "first_state": a[keys.OBS_STATE][first].astype(np.float32),
    }


def summary(x: np.ndarray) -> dict:
    x = np.asarray(x, dtype=np.float64)
    p = 1.0 / (1.0 + np.exp(-x))
    pct = np.percentile(x, [1, 5, 50, 95, 99])
    return {
        "mean": float(x.mean()),
        "std": float(x.std()),
        "p1": float(pct[0]),
        "p5": float(pct[1]),
        "median": float(pct[2]),
        "p95": float(pct[3]),
        "p99": float(pct[4]),
        "min": float(x.min()),
        "max": float(x.max()),
        "saturated": float(np.mean(np.abs(x) > SATURATED)),
        "sigmoid_slope": float(np.mean(p * (1.0 - p))),
    }


def ranks(features: np.ndarray) -> dict:
    """Effective rank exp(H(sigma / sum sigma)) and srank: the fewest singular values holding 99% of their sum."""
    s = torch.linalg.svdvals(torch.as_tensor(features, dtype=torch.float64)).numpy()
    s = s[s > 0]
    if not len(s):
        return {"effective_rank": 0.0, "srank": 0, "dims": int(features.shape[1])}
    p = s / s.sum()
    srank = int(np.searchsorted(np.cumsum(p), 1.0 - SRANK_DELTA) + 1)
    return {
        "effective_rank": float(np.exp(-(p * np.log(p)).sum())),
        "srank": min(srank, len(s)),
        "dims": int(features.shape[1]),
    }


def dormant(scores: np.ndarray, taus: list[float]) -> dict:
    """Share of units with mean |activation| <= tau * the layer's mean (``scores`` are per-unit means)."""
    norm = scores / max(float(scores.mean()), 1e-12)
    return {f"tau={t:g}": float(np.mean(norm <= t)) for t in taus} | {"units": int(len(scores))}


def forward(net, image: torch.Tensor, state: torch.Tensor, action: torch.Tensor) -> dict:
    """Logits and the activations the measurements read (the last column's)."""
    caches = net.encode(image, state)
    cache = caches[-1]
    heads: list = []
    logit = None
    for c, k in zip(net.columns, caches):
        logit, acts = c.score(k, action.unsqueeze(1), heads)
        heads.append(acts)
    return {
        "logit": logit.squeeze(1),
        "convs": cache["convs"],
        "flat": cache["flat"],
        "head": [h.squeeze(1) for h in heads[-1]],
    }


def measure(net, data: dict, cfg: TrainConfig, taus: list[float], seed: int) -> dict:
    """Every per-dataset measurement of one network (see the module docstring)."""
    gen = torch.Generator().manual_seed(seed)
    n = len(data["reward"])
    logits, max_logits, targets, spreads = [], [], [], []
    conv_abs: list[list[torch.Tensor]] = []
    head_abs: list[list[torch.Tensor]] = []
    flats, lasts = [], []
    net.eval()
    net.zero_grad(set_to_none=True)
    for i in range(0, n, CHUNK):
        sl = slice(i, i + CHUNK)
        image = to_float(torch.from_numpy(data["image"][sl]))
        state = torch.from_numpy(data["state"][sl])
        action = active_actions(torch.from_numpy(data["action"][sl]), net.cfg)
        b = len(action)
        noise = noise_from_generator(b, action.shape[1], cfg.cem, gen)
        with torch.no_grad():
            target, _ = bellman_target(
                net,
                net,
                to_float(torch.from_numpy(data["next_image"][sl])),
                torch.from_numpy(data["next_state"][sl]),
                torch.from_numpy(data["reward"][sl]),
                torch.from_numpy(data["done"][sl]),
                cfg.gamma,
                cfg.cem,
                noise,
            )
            ctx = net.encode(image, state)
            _, best_logit = cem_maximize(
                lambda cand, ctx=ctx: net.score(ctx, cand),
                noise_from_generator(b, action.shape[1], cfg.cem, gen),
                cfg.cem,
            )
            rand = torch.rand(b, 32, action.shape[1], generator=gen) * 2.0 - 1.0
            spreads.append(net.score(ctx, rand).std(dim=1))
        out = forward(net, image, state, action)
        loss = F.binary_cross_entropy_with_logits(out["logit"], target, reduction="sum") / n
        loss.backward()  # the chunks' gradients add up to the gradient of the mean loss over all n transitions
        logits.append(out["logit"].detach())
        max_logits.append(best_logit)
        targets.append(target)
        conv_abs.append([c.detach().abs().mean(dim=(2, 3)) for c in out["convs"]])
        head_abs.append([h.detach().abs() for h in out["head"]])
        flats.append(out["flat"].detach())
        lasts.append(out["head"][-1].detach())
    grads: dict[str, float] = {}
    for name, p in net.named_parameters():
        if p.grad is not None:
            layer = name.rsplit(".", 1)[0]
            grads[layer] = grads.get(layer, 0.0) + p.grad.pow(2).sum().item()
    net.zero_grad(set_to_none=True)
    logit = torch.cat(logits).numpy().astype(np.float64)
    best = torch.cat(max_logits).numpy().astype(np.float64)
    target = torch.cat(targets).numpy().astype(np.float64)
    q = 1.0 / (1.0 + np.exp(-logit))
    succ = data["success"]

    from nsl.eval import q_ranking_auc

    try:
        auc = q_ranking_auc(q, succ)
    except ConfigError:  # all successes or all failures: no ranking to measure
        auc = None
    conv_scores = [torch.cat([c[j] for c in conv_abs]).mean(0).numpy() for j in range(len(conv_abs[0]))]
    head_scores = [torch.cat([h[j] for h in head_abs]).mean(0).numpy() for j in range(len(head_abs[0]))]
    layers = {f"conv{j}": s for j, s in enumerate(conv_scores)} | {f"head{j}": s for j, s in enumerate(head_scores)}
    with torch.no_grad():
        v0 = []
        for i in range(0, len(data["first_state"]), CHUNK):
            image = to_float(torch.from_numpy(data["first_image"][i : i + CHUNK]))
            state = torch.from_numpy(data["first_state"][i : i + CHUNK])
            ctx = net.encode(image, state)
            _, lg = cem_maximize(
                lambda cand, ctx=ctx: net.score(ctx, cand),
                noise_from_generator(len(state), len(net.cfg.action_dims), cfg.cem, gen),
                cfg.cem,
            )
            v0.append(torch.sigmoid(lg))
    v0 = torch.cat(v0).numpy().astype(np.float64)
    ret = data["mc_return"]
    return {
        "transitions": int(n),
        "logits": summary(logit),
        "max_logits": summary(best),
        "logits_by_outcome": {
            "success": float(logit[succ].mean()) if succ.any() else None,
            "failure": float(logit[~succ].mean()) if (~succ).any() else None,
        },
        "values": {
            "q_mean": float(q.mean()),
            "target_mean": float(target.mean()),
            "return_mean": float(ret.mean()),
            "optimism": float(target.mean() - ret.mean()),
            "q_minus_return": float(q.mean() - ret.mean()),
            "target_on_failures": float(target[~succ].mean()) if (~succ).any() else None,
            "return_on_failures": float(ret[~succ].mean()) if (~succ).any() else None,
            "abs_q_minus_target": float(np.abs(q - target).mean()),
            "v0_mean": float(v0.mean()),
            "success_rate": float(data["success_rate"]),
            "v0_on_failures": float(v0[~data["first_success"]].mean()) if (~data["first_success"]).any() else None,
        },
        "action_spread": {
            "logit_std_over_actions": float(torch.cat(spreads).mean()),
            "best_minus_data_logit": float((best - logit).mean()),
        },
        "auc": auc,
        "dormant": {name: dormant(s, taus) for name, s in layers.items()},
        "rank": {"trunk": ranks(torch.cat(flats).numpy()), "head_last": ranks(torch.cat(lasts).numpy())},
        "gradient": {
            "total": float(np.sqrt(sum(grads.values()))),
            "layers": {k: float(np.sqrt(v)) for k, v in grads.items()},
        },
    }


def weight_change(reference, net) -> dict:
    """Relative L2 change per layer (weights and bias together) and over all parameters."""
    ref = dict(reference.named_parameters())
    num: dict[str, float] = {}
    den: dict[str, float] = {}
    for name, p in net.named_parameters():
        if name not in ref or ref[name].shape != p.shape:
            continue
        layer = name.rsplit(".", 1)[0]
        num[layer] = num.get(layer, 0.0) + (p.detach() - ref[name].detach()).pow(2).sum().item()
        den[layer] = den.get(layer, 0.0) + ref[name].detach().pow(2).sum().item()
    total = float(np.sqrt(sum(num.values()) / max(sum(den.values()), 1e-30)))
    return {"total": total, "layers": {k: float(np.sqrt(num[k] / max(den[k], 1e-30))) for k in num}}


def diagnose(
    checkpoints: list[str],
    datasets: list[str],
    transitions: int = 2000,
    seed: int = 0,
    taus: tuple[float, ...] = (0.0, 0.025, 0.1),
) -> dict:
    """The measurements of every checkpoint on every dataset, and the weight changes from the first checkpoint."""
    if not checkpoints or not datasets:
        raise ConfigError("give at least one --checkpoint and one --data")
    loaded = [(ref, load_checkpoint(resolve_checkpoint(ref))) for ref in checkpoints]
    cfg = loaded[0][1].training
    data = {ref: load_transitions(ref, transitions, seed, cfg.gamma) for ref in datasets}
    out: dict = {
        "gamma": cfg.gamma,
        "seed": seed,
        "taus": list(taus),
        "checkpoints": {},
        "data": {},
        "measurements": {},
        "weight_change": {},
    }
    for ref, d in data.items():
        out["data"][ref] = {
            "episodes": d["episodes"],
            "frames": d["frames"],
            "success_rate": d["success_rate"],
            "measured_transitions": int(len(d["reward"])),
        }
    for ref, ckpt in loaded:
        out["checkpoints"][ref] = {
            "path": str(ckpt.path),
            "id": ckpt.id,
            "step": ckpt.step,
            "method": ckpt.config["method"],
            "parent": (ckpt.config.get("parent") or {}).get("id"),
        }
        out["measurements"][ref] = {dref: measure(ckpt.net, d, cfg, list(taus), seed) for dref, d in data.items()}
        if ref != loaded[0][0]:
            out["weight_change"][ref] = {"reference": loaded[0][0], **weight_change(loaded[0][1].net, ckpt.net)}
    return out


def print_table(result: dict) -> None:
    cols = (
        "logit mean",
        "|l|>5",
        "max-logit",
        "Q",
        "target",
        "return",
        "optimism",
        "AUC",
        "dormant.1",
        "trunk erank",
        "grad",
    )
    print("| checkpoint | data | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 2) + "|")
    for ref, per in result["measurements"].items():
        for dref, m in per.items():
            dead = (
                np.mean([v["tau=0.1"] for v in m["dormant"].values()])
                if "tau=0.1" in next(iter(m["dormant"].values()))
                else float("nan")
            )
            v = m["values"]
            row = (
                f"{m['logits']['mean']:.2f}",
                f"{m['logits']['saturated']:.2f}",
                f"{m['max_logits']['mean']:.2f}",
                f"{v['q_mean']:.3f}",
                f"{v['target_mean']:.3f}",
                f"{v['return_mean']:.3f}",
                f"{v['optimism']:+.3f}",
                "-" if m["auc"] is None else f"{m['auc']:.3f}",
                f"{dead:.3f}",
                f"{m['rank']['trunk']['effective_rank']:.1f}",
                f"{m['gradient']['total']:.3f}",
            )
            print(f"| {ref} | {dref} | " + " | ".join(row) + " |")
    for ref, w in result["weight_change"].items():
        print(
            f"weight change {w['reference']} -> {ref}: {w['total']:.4f} overall; "
            + ", ".join(f"{k} {v:.4f}" for k, v in w["layers"].items())
        )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--checkpoint",
        action="append",
        required=True,
        help="ckpt:NAME[@STEP] or a folder; the first is the reference for the weight changes (repeat)",
    )
    p.add_argument("--data", action="append", required=True, help="dataset NAME[@vN][:K] (repeat)")
    p.add_argument("--transitions", type=int, default=2000, help="transitions measured per dataset (a seeded subset)")
    p.add_argument("--seed", type=int, default=0, help="seed of the subset and of CEM's noise")
    p.add_argument("--tau", default="0,0.025,0.1", help="dormancy thresholds, comma-separated")
    p.add_argument("--out", type=Path, default=None, help="write the JSON here")
    args = p.parse_args(argv)
    torch.set_num_threads(max(1, min(2, torch.get_num_threads())))
    try:
        taus = tuple(float(t) for t in args.tau.split(","))
    except ValueError:
        print(f"error: --tau {args.tau!r} must be comma-separated numbers, e.g. 0,0.025,0.1", file=sys.stderr)
        return 2
    try:
        if args.transitions < 2:
            raise ConfigError(f"--transitions {args.transitions} must be at least 2")
        result = diagnose(args.checkpoint, args.data, args.transitions, args.seed, taus)
    except NslError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.out is not None:
        atomic_write_json(args.out, result)
    print_table(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
