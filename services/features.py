"""Supervised features (Table 5.2's ImageNet column): a catalogued checkpoint whose trunk learned by supervision.

``nsl features`` renders labelled frames of the 899 train objects (``nsl.collectors.object_frames``), trains
the trunk of ``--like``'s architecture to classify them, or with ``--label pose`` to tell where the object is
relative to the camera (``nsl.learners.train_features``), and catalogues the network as ``ckpt:NAME``; with
``--encoder PATH`` the trunk is a torchvision ResNet with the weights in PATH instead.  Its head is fresh:
fine-tune it with ``nsl train --init ckpt:NAME --method new_head`` (trunk trained too) or ``--method
new_head_frozen`` (trunk frozen).  Running it again with the same settings returns the
checkpoint already made.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from .options import FeaturesConfig

__all__ = ["FeaturesConfig", "FeaturesResult", "features"]


@dataclass(frozen=True)
class FeaturesResult:
    """A features checkpoint: its catalog ref and id, its folder and what its training measured."""

    checkpoint: str  # ckpt:NAME@0
    id: str | None  # its catalog id; None until registered (register=False)
    path: Path
    record: dict[str, Any]  # accuracies (trained) or the encoder file's name and hash (imported)

    def summary(self) -> str:
        r = self.record
        parts = []
        if "heldout_accuracy" in r:
            parts.append(
                f"{r['classes']} classes, held-out accuracy {100 * r['heldout_accuracy']:.1f}% "
                f"(chance {100 * r['chance']:.2f}%), training accuracy {100 * r['train_accuracy']:.1f}%"
            )
        if "heldout_pose_error_ratio" in r:
            per = ", ".join(f"{k} {v:.2f}" for k, v in zip(r["pose_labels"], r["heldout_pose_error_ratios"]))
            parts.append(
                f"pose on held-out frames: squared error {r['heldout_pose_error_ratio']:.2f} of the mean's ({per}; "
                f"training frames {r['train_pose_error_ratio']:.2f})"
            )
        if parts:
            return f"{self.checkpoint}: " + "; ".join(parts)
        return f"{self.checkpoint}: {r['architecture']} trunk from {r['file']} (sha256 {r['sha256'][:12]})"


def features(
    config: FeaturesConfig,
    name: str = "features",
    *,
    progress: bool = True,
    register: bool = True,
    wait: bool = False,
) -> FeaturesResult:
    """Train (or import) supervised features as checkpoint ``name``; the same call again returns it.

    ``register=False`` writes the checkpoint folder but leaves the catalog to :func:`register_features` (a study
    unit on a cluster node).  Holds run ``name``'s writer lock: while another process writes it this raises
    LockedError naming it, or with ``wait`` waits for it."""
    from nsl.locks import run_lock

    with run_lock(name, wait=wait):
        return _features(config, name, progress, register)


def _features(config: FeaturesConfig, name: str, progress: bool, register: bool) -> FeaturesResult:
    from nsl.catalog import Catalog
    from nsl.learners import FeatureConfig, TrainConfig, encoder_features, load_checkpoint, train_features

    from .refs import open_run, pinned, resolve_init

    run_dir = open_run(name, config)
    final = run_dir / "final"
    entry = pinned(config.like)  # a study unit's (resolved by its driver, which alone opens the catalog)
    if entry is None:
        with Catalog() as cat:
            entry = resolve_init(cat, config.like)
    like = load_checkpoint(Path(entry.path))
    # the recipe fine-tunes keep (n-step, crop, rate) is the --like checkpoint's
    training = TrainConfig.from_dict(like.config["training"]).replace(steps=0, seed=config.seed)
    if not (final / "config.json").is_file():
        if config.encoder is not None:
            encoder_features(
                config.encoder, architecture=like.architecture, training=training, out=final, seed=config.seed
            )
        else:
            from nsl.collectors import object_frames

            fc = FeatureConfig(
                steps=config.steps, batch_size=config.batch_size, lr=config.lr, seed=config.seed, label=config.label
            )
            images, labels, poses = object_frames(
                config.frames, config.seed, config.classes, like.architecture.image_size, progress=progress
            )
            frames = {"frames": {"objects": "train", "classes": config.classes, "per_class": config.frames}}
            train_features(
                images,
                labels,
                architecture=like.architecture,
                training=training,
                config=fc,
                data=frames,
                out=final,
                per_class=config.frames,
                poses=poses,
                progress=progress,
            )
    data = json.loads((final / "config.json").read_text())["data"]
    record = {**(data.get("features") or data["encoder"]), "config": asdict(config)}
    return FeaturesResult(f"ckpt:{name}@0", register_features(name, final) if register else None, final, record)


def register_features(name: str, final: Path) -> str:
    """Catalogue the features checkpoint folder ``final`` as ``ckpt:NAME@0``; its id (idempotent)."""
    from nsl.catalog import Catalog

    from .train import register_checkpoint

    with Catalog() as cat:
        return register_checkpoint(cat, name, final, None, (), "base").id
