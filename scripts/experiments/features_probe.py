"""Why the supervised features' classifier normalises the pooled trunk features: the training loss of the
classifier with batch norm (``nsl.learners.features.classifier``) against a bare linear layer.

Renders ``--frames`` frames of each of ``--classes`` train objects (``nsl.collectors.object_frames``, seed 0), then
trains the shipped base's architecture (fresh weights) to classify them, as ``nsl features`` does (Adam 1e-3,
batch 128, random-shift augmentation), and prints the mean cross-entropy of every 100 steps; chance is
ln(classes) (6.80 for all 899).  ``--plain`` uses the bare linear layer instead.  About 2 minutes each for the
defaults on this 2-core machine:

    MUJOCO_GL=egl .venv/bin/python scripts/experiments/features_probe.py --classes 899 --frames 8 --steps 500
    MUJOCO_GL=egl .venv/bin/python scripts/experiments/features_probe.py --classes 899 --frames 8 --steps 500 --plain
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import torch
from torch import nn

import nsl
from nsl.collectors import object_frames
from nsl.learners import NetConfig, QNetwork, load_checkpoint
from nsl.learners.augment import prepare_images
from nsl.learners.features import _features, classifier
from nsl.learners.networks import is_head_parameter


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--classes", type=int, default=899)
    ap.add_argument("--frames", type=int, default=8, help="frames per class")
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--plain", action="store_true", help="a bare linear classifier (no batch norm)")
    args = ap.parse_args()
    base = load_checkpoint(Path(nsl.__file__).parent / "assets" / "base")
    images, labels, _ = object_frames(args.frames, 0, args.classes, base.architecture.image_size)
    torch.manual_seed(0)
    net = QNetwork(NetConfig.from_dict({**base.architecture.to_dict(), "columns": 1})).train()
    channels = net.cfg.feature_channels
    head = nn.Linear(channels, args.classes) if args.plain else classifier(channels, args.classes)
    params = [p for n, p in net.named_parameters() if not is_head_parameter(n)] + list(head.parameters())
    opt = torch.optim.Adam(params, lr=1e-3, weight_decay=1e-4)
    gen = torch.Generator().manual_seed(0)
    x_all, y_all = torch.from_numpy(images), torch.from_numpy(labels)
    print(
        f"{'plain linear' if args.plain else 'batch norm + linear'}; chance loss ln {args.classes} = "
        f"{math.log(args.classes):.3f}"
    )
    window = []
    for step in range(1, args.steps + 1):
        idx = torch.randint(0, len(x_all), (128,), generator=gen)
        loss = nn.functional.cross_entropy(head(_features(net, prepare_images(x_all[idx], 4, 0.0, gen))), y_all[idx])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        window.append(loss.item())
        if step % 100 == 0:
            print(f"steps {step - 99}-{step}: mean loss {sum(window) / len(window):.3f}", flush=True)
            window = []


if __name__ == "__main__":
    main()
