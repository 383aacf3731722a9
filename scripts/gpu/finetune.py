"""The fine-tuning recipe on a GPU machine that has only torch and numpy, and its checkpoints back in the catalog.

Measures: whether a 2,000-step fine-tune of ``ckpt:base`` trained on a GPU (``--device cuda``, the step replayed
from one CUDA graph) scores as the same fine-tune trained here on the CPU, on 1,000 selection scenes, per seed.
Three steps, the middle one on the GPU (``scripts/gpu/check.sh`` runs it):

    # here: the base's weights and the data mix as arrays, under the device tool's 64 MiB
    python scripts/gpu/finetune.py export build/gpu --data grasp-base:200=0.5 --data grasp-offset:200=0.5
    # on the GPU machine (scripts/gpu/check.sh): one fine-tune per seed, weights and timings in $OUT
    python scripts/gpu/finetune.py train build/gpu --seed 0 --out $OUT/ft-s0.pt --device cuda
    # here: each returned fine-tune as a catalogued checkpoint, then `nsl eval` as for any other
    python scripts/gpu/finetune.py import $FILES/ft-s0.pt --data build/gpu --name gpu-ft-s0

The CPU side of the comparison is ``nsl train --init ckpt:base --data grasp-base:200=0.5
--data grasp-offset:200=0.5 --seed S --name cpu-ft-sS``, the same recipe on the same data (its batches are drawn
by the CPU's sampler, so the two runs differ by their draws as two seeds do).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

BASE_FILE, DATA_FILE, META_FILE = "base.pt", "data.npz", "meta.json"
LIMIT = 60 * 2**20  # the device tool carries 64 MiB in all


def export(args: argparse.Namespace) -> None:
    from nsl.catalog import Catalog
    from nsl.datasets import api
    from nsl.learners import inherited_settings, load_checkpoint
    from nsl.services.refs import resolve_init
    from nsl.services.train import parse_data

    out = Path(args.dir)
    out.mkdir(parents=True, exist_ok=True)
    with Catalog() as cat:
        entry = resolve_init(cat, args.base)
    base = load_checkpoint(entry.path)
    inherited = inherited_settings(entry.path)
    mix = parse_data(args.data)
    sampler = api.make_sampler(mix, n_step=inherited["n_step"], gamma=base.training.gamma)
    arrays: dict[str, np.ndarray] = {}
    weights = []
    for k, (table, w) in enumerate(sampler.tables()):
        used, inverse = np.unique(np.concatenate([table["obs"], table["next"]]), return_inverse=True)
        t = len(table["obs"])
        arrays[f"{k}/images"] = np.asarray(table["images"][used])
        arrays[f"{k}/obs"], arrays[f"{k}/next"] = inverse[:t], inverse[t:]
        arrays |= {f"{k}/{name}": np.asarray(v) for name, v in table.items() if name not in ("images", "obs", "next")}
        weights.append(w)
    np.savez_compressed(out / DATA_FILE, **arrays)
    torch.save({"state_dict": base.net.state_dict(), "config": base.config}, out / BASE_FILE)
    meta = {
        "base": args.base,
        "base_id": entry.id,
        "mix": mix,
        "weights": weights,
        "inherited": inherited,
        "data": sampler.describe(),
    }
    (out / META_FILE).write_text(json.dumps(meta, indent=2))
    size = sum(p.stat().st_size for p in out.iterdir())
    print(f"wrote {out}: {size / 2**20:.1f} MiB ({len(weights)} sources)")
    if size > LIMIT:
        sys.exit(f"{out} holds {size / 2**20:.0f} MiB, over the device tool's 64 MiB; export fewer episodes")


def _recipe(meta: dict, base_config: dict, seed: int, steps: int, device: str):
    from nsl.learners import TrainConfig
    from nsl.learners.config import FINE_TUNE_CONSERVATIVE, FINE_TUNE_LR_FACTOR

    return TrainConfig(
        steps=steps,
        seed=seed,
        lr=float(base_config["training"]["lr"]) * FINE_TUNE_LR_FACTOR,
        conservative=FINE_TUNE_CONSERVATIVE,
        n_step=meta["inherited"]["n_step"],
        augment_crop=meta["inherited"]["augment_crop"],
        device=device,
    )


def train(args: argparse.Namespace) -> None:
    from nsl.learners import Learner, NetConfig, QNetwork
    from nsl.learners.cuda_graph import DeviceData, GraphedStep
    from nsl.learners.device import resolve_device

    folder = Path(args.dir)
    meta = json.loads((folder / META_FILE).read_text())
    base = torch.load(folder / BASE_FILE, map_location="cpu", weights_only=True)
    data = np.load(folder / DATA_FILE)
    tables = []
    for k, w in enumerate(meta["weights"]):
        prefix = f"{k}/"
        tables.append(({name[len(prefix) :]: data[name] for name in data.files if name.startswith(prefix)}, w))
    device = resolve_device(args.device)
    cfg = _recipe(meta, base["config"], args.seed, args.steps, device)
    torch.manual_seed(cfg.seed)
    net = QNetwork(NetConfig.from_dict(base["config"]["architecture"]))
    net.load_state_dict(base["state_dict"])
    learner = Learner.create(net.train(), cfg.lr, cfg)
    step_fn = GraphedStep(learner, DeviceData(tables, device), cfg)
    window = torch.zeros(8, dtype=torch.float64, device=device)
    t0 = time.perf_counter()
    for step in range(cfg.steps):
        window += step_fn(step)
    if device == "cuda":
        torch.cuda.synchronize()
    seconds = time.perf_counter() - t0
    result = {
        "seed": cfg.seed,
        "steps": cfg.steps,
        "device": device,
        "gpu": torch.cuda.get_device_name() if device == "cuda" else None,
        "seconds": round(seconds, 2),
        "steps_per_s": round(cfg.steps / seconds, 1),
        "mean_metrics": (window / cfg.steps).tolist(),
        "training": cfg.to_dict(),
    }
    torch.save({"state_dict": learner.online.cpu().state_dict(), "result": result}, args.out)
    print(json.dumps(result))


def import_(args: argparse.Namespace) -> None:
    from nsl.catalog import Catalog
    from nsl.learners import NetConfig, QNetwork, TrainConfig, checkpoint_config, save_checkpoint
    from nsl.services.refs import dataset_uses
    from nsl.workspace import runs_dir

    meta = json.loads((Path(args.data) / META_FILE).read_text())
    saved = torch.load(args.weights, map_location="cpu", weights_only=True)
    base = torch.load(Path(args.data) / BASE_FILE, map_location="cpu", weights_only=True)
    net = QNetwork(NetConfig.from_dict(base["config"]["architecture"]))
    net.load_state_dict(saved["state_dict"])
    result = saved["result"]
    training = TrainConfig.from_dict(result["training"])
    parent = {"id": meta["base_id"], "step": int(base["config"]["step"]), "method": base["config"]["method"]}
    config = checkpoint_config(
        net, training=training, method="ft", data=meta["data"], parent=parent, step=result["steps"]
    )
    folder = save_checkpoint(runs_dir() / args.name / "final", net, config)
    with Catalog() as cat:
        uses = dataset_uses(cat, [tuple(m) for m in meta["mix"]])
        entry = cat.save_checkpoint(
            args.name, result["steps"], folder / "model.safetensors", config, parent=meta["base_id"], data=uses
        )
    print(f"ckpt:{entry.ref} ({result['device']}, {result['steps_per_s']} steps/s) from {args.weights}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="action", required=True)
    e = sub.add_parser("export", help="here: the base and the data mix as arrays")
    e.add_argument("dir")
    e.add_argument("--base", default="ckpt:base")
    e.add_argument("--data", action="append", required=True, metavar="REF[=WEIGHT]")
    e.set_defaults(func=export)
    t = sub.add_parser("train", help="on the GPU machine: one fine-tune (torch and numpy only)")
    t.add_argument("dir")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--steps", type=int, default=2000)
    t.add_argument("--device", default="cuda")
    t.add_argument("--out", required=True)
    t.set_defaults(func=train)
    i = sub.add_parser("import", help="here: a returned fine-tune as a catalogued checkpoint")
    i.add_argument("weights")
    i.add_argument("--data", required=True, help="the folder export wrote")
    i.add_argument("--name", required=True)
    i.set_defaults(func=import_)
    args = p.parse_args()
    args.func(args)


if __name__ == "__main__":
    main()
