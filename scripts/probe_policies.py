"""Research probes behind README numbers that no `nsl` command gives: a checkpoint acting with other CEM
settings, its Polyak-averaged weights, and CEM over the mean Q of several checkpoints. Each prints the
success on test scenes of one shift (default: the base task); episode i uses scene seed (--seed, i), so the scenes are those of
`nsl eval --episodes N --seed S`. Checkpoints are folders (catalogued ones live in $NSL_HOME/checkpoints).

    .venv/bin/python scripts/probe_policies.py cem --samples 256 --elites 16 --iterations 3 --seed 3000 DIR...
    .venv/bin/python scripts/probe_policies.py polyak --seed 3000 DIR...      # DIR must hold trainer_state.pt
    .venv/bin/python scripts/probe_policies.py ensemble --seed 2000 DIR DIR DIR DIR
"""

from __future__ import annotations

import argparse
import functools
import shutil
import tempfile
from pathlib import Path

import numpy as np
import safetensors.torch
import torch

from nsl.collectors import parse_shift
from nsl.eval import EvalConfig, evaluate
from nsl.learners import (CHECKPOINT_FORMAT, CONFIG_FILE, MODEL_FILE, TRAINER_FILE, CemConfig, cem_maximize,
                          full_actions, load_checkpoint, load_policy, noise_from_rngs)
from nsl.learners.augment import to_float


class MeanQPolicy:
    """Greedy CEM over the mean logit of several Q-networks (one image encoding per network)."""

    needs_privileged = False

    def __init__(self, dirs: list[str]):
        self.nets = [load_checkpoint(d).net.eval() for d in dirs]
        self.cem = CemConfig()

    def __call__(self, obs, *, rngs, privileged=None):
        image = to_float(torch.from_numpy(np.asarray(obs["image"])))
        state = torch.from_numpy(np.asarray(obs["state"], np.float32))
        cfg = self.nets[0].cfg
        noise = noise_from_rngs(rngs, len(cfg.action_dims), self.cem)
        with torch.inference_mode():
            ctxs = [n.encode(image, state) for n in self.nets]
            best, _ = cem_maximize(lambda c: sum(n.score(x, c) for n, x in zip(self.nets, ctxs)) / len(ctxs),
                                   noise, self.cem)
        return full_actions(best.numpy().astype(np.float32), cfg)


def polyak_folder(src: Path, dst: Path) -> Path:
    """A checkpoint folder holding the Polyak-averaged (target) weights from ``src``'s trainer state."""
    if not (src / TRAINER_FILE).is_file():
        raise SystemExit(f"{src} has no {TRAINER_FILE}; only a run's last checkpoint keeps the trainer state")
    polyak = torch.load(src / TRAINER_FILE, weights_only=False)["learner"]["polyak"]
    dst.mkdir(parents=True)
    shutil.copy(src / CONFIG_FILE, dst / CONFIG_FILE)
    weights = {k: v.contiguous() for k, v in polyak.items()}
    (dst / MODEL_FILE).write_bytes(safetensors.torch.save(weights, metadata={"format": CHECKPOINT_FORMAT}))
    return dst


def report(label: str, make_policy, args) -> None:
    cfg = EvalConfig(episodes=args.episodes, seed=args.seed, workers=args.workers)
    spec = parse_shift(args.shift)
    r = evaluate(make_policy, [spec], cfg, progress=False)[spec.name]
    print(f"{label}: {r.successes}/{r.episodes} = {r.successes / r.episodes:.1%} ({spec.name}, seed {args.seed})",
          flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("probe", choices=["cem", "polyak", "ensemble"])
    ap.add_argument("dirs", nargs="+", help="checkpoint folders")
    ap.add_argument("--shift", default="base", help="shift spec, e.g. harsh_lighting")
    ap.add_argument("--seed", type=int, default=3000)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--elites", type=int, default=6)
    ap.add_argument("--iterations", type=int, default=2)
    args = ap.parse_args()
    if args.probe == "ensemble":
        report(f"mean Q of {len(args.dirs)}", functools.partial(MeanQPolicy, args.dirs), args)
    elif args.probe == "cem":
        for d in args.dirs:
            cem = dict(samples=args.samples, elites=args.elites, iterations=args.iterations)
            report(f"{d} CEM {args.samples}/{args.elites}/{args.iterations}", functools.partial(load_policy, d, **cem), args)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            for i, d in enumerate(args.dirs):
                report(f"{d} Polyak", functools.partial(load_policy, str(polyak_folder(Path(d), Path(tmp) / str(i)))), args)


if __name__ == "__main__":
    main()
