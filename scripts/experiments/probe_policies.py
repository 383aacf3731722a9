"""Research probes behind numbers in docs/experiments/ that no `nsl` command gives ("Acting with other
CEM settings, Polyak weights and ensembles", "Plasticity of a base", "Ranking recipes on 1,000 scenes"): a
checkpoint acting with other CEM settings, its Polyak-averaged weights, and CEM over the mean Q of several
checkpoints. Each prints the success on test scenes of one shift (default: the base task); episode i uses scene
seed (--seed, i), so the scenes are those of `nsl eval --episodes N --seed S`. Checkpoints are folders
(catalogued ones live in $NSL_HOME/checkpoints).

    .venv/bin/python scripts/experiments/probe_policies.py cem --samples 256 --elites 16 --iterations 3 \
        --seed 3000 DIR...
    .venv/bin/python scripts/experiments/probe_policies.py polyak --seed 3000 DIR...    # DIR must hold trainer_state.pt
    .venv/bin/python scripts/experiments/probe_policies.py ensemble --seed 2000 DIR DIR DIR DIR
"""

from __future__ import annotations

import argparse
import functools
import shutil
import tempfile
from pathlib import Path

import safetensors.torch
import torch

from nsl.collectors import parse_shift
from nsl.eval import EvalConfig, evaluate
from nsl.learners import (
    CHECKPOINT_FORMAT,
    CONFIG_FILE,
    MODEL_FILE,
    TRAINER_FILE,
    CemConfig,
    CEMPolicy,
    load_checkpoint,
    load_policy,
)


class MeanQNet(torch.nn.Module):
    """Several Q-networks as one: the mean of their logits, each network encoding the image once."""

    def __init__(self, nets):
        super().__init__()
        self.nets = torch.nn.ModuleList(nets)
        self.cfg = nets[0].cfg

    def encode(self, image, state):
        return [n.encode(image, state) for n in self.nets]

    def score(self, ctxs, actions):
        return sum(n.score(c, actions) for n, c in zip(self.nets, ctxs)) / len(self.nets)


def mean_q_policy(dirs: list[str]) -> CEMPolicy:
    """Greedy CEM (QT-Opt's settings) over the mean Q of the checkpoints in ``dirs``."""
    return CEMPolicy(MeanQNet([load_checkpoint(d).net for d in dirs]), CemConfig(), name=f"mean-q-of-{len(dirs)}")


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
    print(
        f"{label}: {r.successes}/{r.episodes} = {r.successes / r.episodes:.1%} ({spec.name}, seed {args.seed})",
        flush=True,
    )


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
        report(f"mean Q of {len(args.dirs)}", functools.partial(mean_q_policy, args.dirs), args)
    elif args.probe == "cem":
        cem = dict(samples=args.samples, elites=args.elites, iterations=args.iterations)
        for d in args.dirs:
            report(
                f"{d} CEM {args.samples}/{args.elites}/{args.iterations}",
                functools.partial(load_policy, d, **cem),
                args,
            )
    else:
        with tempfile.TemporaryDirectory() as tmp:
            for i, d in enumerate(args.dirs):
                report(
                    f"{d} Polyak", functools.partial(load_policy, str(polyak_folder(Path(d), Path(tmp) / str(i)))), args
                )


if __name__ == "__main__":
    main()
