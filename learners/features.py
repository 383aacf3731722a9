"""Supervised features: a Q-network whose trunk was trained to classify images, not by reinforcement learning.

The study's ImageNet column (Table 5.2) fine-tunes a network with supervised pre-trained convolutional
features on the same data as the RL-pre-trained base.  Two sources of such a trunk:

* :func:`train_features`: the Q-network's own trunk trained on labelled frames (the project's analogue of
  ImageNet: the 899 train objects rendered by the simulator, ``nsl.collectors.object_frames``): trunk ->
  global average pool -> a batch-norm-then-linear layer, Adam.  ``label="classes"`` classifies the object
  (cross-entropy, random-shift augmentation); ``"pose"`` regresses the object's position relative to the
  camera (squared error on standardised targets, no shift: it would move the answer); ``"both"`` sums the two;
* :func:`encoder_features`: a torchvision ResNet's weights from a file (e.g. real ImageNet weights).

Either becomes a checkpoint of the one format (method ``"supervised"``), its head freshly initialised and
never trained.  The fine-tuning methods ``new_head`` (trunk trained) and ``new_head_frozen`` (trunk frozen)
start from it like from any parent.  The same arguments give the same weights.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from nsl.errors import ConfigError
from nsl.progress import progress_bar

from .augment import prepare_images
from .checkpoint import checkpoint_config, save_checkpoint
from .config import ENCODERS, FeatureConfig, NetConfig, TrainConfig
from .networks import QNetwork, is_head_parameter, resnet_trunk

POSE_LABELS = ("u", "v", "h")  # nsl.collectors.POSE_LABELS: the learners do not import the collectors

METHOD = "supervised"  # the method a features checkpoint records


def _features(net: QNetwork, x: torch.Tensor) -> torch.Tensor:
    """The trunk's output map, averaged over positions: (B, channels)."""
    state = torch.zeros(x.shape[0], net.cfg.state_dim)
    return net.encode(x, state)[0]["convs"][-1].mean(dim=(2, 3))


def classifier(channels: int, classes: int) -> nn.Sequential:
    """The classifier on the pooled trunk features: batch norm, then a linear layer.

    The batch norm matters.  The pooled features of a freshly initialised trunk are small and nearly alike across
    frames; a bare linear layer over 899 classes stays at chance for hundreds of steps on them (the loss sits at
    ln 899 = 6.80), while the normalised features train from the first steps
    (``scripts/experiments/features_probe.py``).  Only the trunk is kept; the classifier is discarded.
    """
    return nn.Sequential(nn.BatchNorm1d(channels), nn.Linear(channels, classes))


def _pose_error(net: QNetwork, head: nn.Module, images: np.ndarray, poses: np.ndarray, mean: np.ndarray) -> dict:
    """Held-out pose regression: each label's mean squared error over that of predicting the training mean (1 - R^2
    against the training mean; below 1 means the trunk learned something), and their average."""
    if not len(images):
        return {}
    preds = []
    with torch.no_grad():
        for i in range(0, len(images), 512):
            x = prepare_images(torch.from_numpy(images[i : i + 512]), 0, 0.0, None)
            preds.append(head(_features(net, x)).numpy())
    scale = head.get_buffer("scale").numpy()  # set by _pose_head
    pred = np.concatenate(preds) * scale + mean
    ratios = ((pred - poses) ** 2).mean(axis=0) / np.maximum(((poses - mean) ** 2).mean(axis=0), 1e-12)
    return {"pose_error_ratio": float(ratios.mean()), "pose_error_ratios": [float(r) for r in ratios]}


def _pose_head(channels: int, std: np.ndarray) -> nn.Module:
    """The regressor on the pooled trunk features (batch norm, then linear), predicting standardised poses."""
    head = classifier(channels, len(std))
    head.register_buffer("scale", torch.from_numpy(std.astype(np.float32)))
    return head


def _accuracy(net: QNetwork, head: nn.Module, images: np.ndarray, labels: np.ndarray) -> float | None:
    if not len(images):
        return None
    correct = 0
    with torch.no_grad():
        for i in range(0, len(images), 512):
            x = prepare_images(torch.from_numpy(images[i : i + 512]), 0, 0.0, None)
            correct += int((head(_features(net, x)).argmax(1).numpy() == labels[i : i + 512]).sum())
    return correct / len(images)


def train_features(
    images: np.ndarray,
    labels: np.ndarray,
    *,
    architecture: NetConfig,
    training: TrainConfig,
    config: FeatureConfig,
    data: dict[str, Any],
    out: Path,
    per_class: int,
    poses: np.ndarray | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Train ``architecture``'s trunk on ``images`` (class-major, ``per_class`` frames each) to predict their
    ``labels`` and/or ``poses`` (``config.label``) and save the network at ``out``; returns what the held-out
    frames measured.  ``training`` is recorded as the checkpoint's training config (fine-tunes from it take 25% of
    its rate and keep its n-step and crop, as from the RL base)."""
    classes = int(labels.max()) + 1
    if len(images) != classes * per_class or per_class <= config.holdout:
        raise ConfigError(
            f"features: {len(images)} frames are not {classes} classes x {per_class}, or per_class is not above "
            f"holdout {config.holdout}"
        )
    use_classes, use_pose = config.label in ("classes", "both"), config.label in ("pose", "both")
    if use_pose and (poses is None or len(poses) != len(images)):
        raise ConfigError(f"features: label {config.label!r} needs a pose for each of the {len(images)} frames")
    held = (np.arange(len(images)) % per_class) >= per_class - config.holdout
    train_x, train_y = images[~held], labels[~held]
    torch.manual_seed(config.seed)
    net = QNetwork(NetConfig.from_dict({**architecture.to_dict(), "columns": 1})).train()
    channels = net.cfg.feature_channels
    heads: dict[str, nn.Module] = {}
    if use_classes:
        heads["classes"] = classifier(channels, classes)
    if use_pose:
        assert poses is not None
        train_p = poses[~held].astype(np.float64)
        pose_mean, pose_std = train_p.mean(axis=0), np.maximum(train_p.std(axis=0), 1e-6)
        heads["pose"] = _pose_head(channels, pose_std)
        targets_t = torch.from_numpy(((train_p - pose_mean) / pose_std).astype(np.float32))
    params = [p for n, p in net.named_parameters() if not is_head_parameter(n)]
    params += [p for h in heads.values() for p in h.parameters()]
    opt = torch.optim.Adam(params, lr=config.lr, weight_decay=config.weight_decay)
    gen = torch.Generator().manual_seed(config.seed)
    images_t, labels_t = torch.from_numpy(train_x), torch.from_numpy(train_y)
    crop = config.augment_crop if not use_pose else 0  # a shifted frame would move the pose it is labelled with
    for h in heads.values():
        h.train()
    loss_sum, n = 0.0, 0
    for _ in progress_bar(range(config.steps), desc="train features", unit="step", disable=not progress):
        idx = torch.randint(0, len(images_t), (config.batch_size,), generator=gen)
        feats = _features(net, prepare_images(images_t[idx], crop, 0.0, gen))
        loss = torch.zeros(())
        if use_classes:
            loss = loss + nn.functional.cross_entropy(heads["classes"](feats), labels_t[idx])
        if use_pose:
            loss = loss + nn.functional.mse_loss(heads["pose"](feats), targets_t[idx])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        loss_sum, n = loss_sum + loss.item(), n + 1
    net.eval()
    for h in heads.values():
        h.eval()
    every = max(1, len(train_x) // 4096)  # training figures on at most about 4,096 frames
    result: dict[str, Any] = {"final_loss": loss_sum / max(n, 1)}
    if use_classes:
        result |= {
            "classes": classes,
            "train_accuracy": _accuracy(net, heads["classes"], train_x[::every], train_y[::every]),
            "heldout_accuracy": _accuracy(net, heads["classes"], images[held], labels[held]),
            "chance": 1.0 / classes,
        }
    if use_pose:
        assert poses is not None
        heldout = _pose_error(net, heads["pose"], images[held], poses[held], pose_mean)
        trained = _pose_error(net, heads["pose"], train_x[::every], poses[~held][::every], pose_mean)
        result |= {
            "pose_labels": list(POSE_LABELS),
            "heldout_pose_error_ratio": heldout.get("pose_error_ratio"),
            "heldout_pose_error_ratios": heldout.get("pose_error_ratios"),
            "train_pose_error_ratio": trained.get("pose_error_ratio"),
        }
    settings = asdict(config)
    if config.label == "classes":
        del settings["label"]  # the classifier's records (and checkpoint ids) from before the pose label hold
    record = {**data, "features": {**settings, **result}}
    _save(out, net, training, record)
    return result


def _save(out: Path, net: QNetwork, training: TrainConfig, data: dict[str, Any]) -> None:
    config = checkpoint_config(net, training=training, method=METHOD, data=data, parent=None, step=0)
    save_checkpoint(Path(out), net, config)


def load_encoder(path: str | Path) -> tuple[str, dict[str, torch.Tensor]]:
    """``(architecture, trunk weights)`` of a torchvision ResNet state dict saved at ``path``.

    Accepts ``torch.save(model.state_dict(), path)`` (also wrapped as ``{"state_dict": ...}`` or with
    ``module.`` prefixes) and safetensors files; the classifier ``fc`` is dropped.  Anything else fails in one line.
    """
    p = Path(path)
    hint = "save one with torch.save(torchvision.models.resnet18(weights=...).state_dict(), PATH)"
    if not p.is_file():
        raise ConfigError(f"--encoder {p}: no such file; give a torchvision ResNet state dict ({hint})")
    try:
        if p.suffix == ".safetensors":
            import safetensors.torch

            weights: Any = safetensors.torch.load_file(str(p))
        else:
            weights = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as e:
        raise ConfigError(f"--encoder {p}: not a readable state dict ({type(e).__name__}); {hint}") from None
    if isinstance(weights, dict) and isinstance(weights.get("state_dict"), dict):
        weights = weights["state_dict"]
    if not isinstance(weights, dict) or not all(isinstance(v, torch.Tensor) for v in weights.values()):
        raise ConfigError(f"--encoder {p}: holds no tensor state dict; {hint}")
    weights = {
        k.removeprefix("module."): v
        for k, v in weights.items()
        if not k.removeprefix("module.").startswith("fc.") and not k.endswith("num_batches_tracked")
    }
    reasons = []
    for arch in ENCODERS[1:]:
        expected = resnet_trunk(arch).state_dict()
        missing = sorted(set(expected) - set(weights))
        extra = sorted(set(weights) - set(expected))
        bad = [k for k in expected if k in weights and weights[k].shape != expected[k].shape]
        if not (missing or extra or bad):
            return arch, {k: weights[k].float() for k in expected}
        reasons.append(f"{arch}: {len(missing)} missing, {len(extra)} unexpected, {len(bad)} mis-shaped")
    raise ConfigError(f"--encoder {p} is not a torchvision ResNet-18/34/50 state dict ({'; '.join(reasons)}); {hint}")


def encoder_features(
    path: str | Path, *, architecture: NetConfig, training: TrainConfig, out: Path, seed: int = 0
) -> dict[str, Any]:
    """A features checkpoint at ``out`` from the ResNet weights at ``path``: ``architecture``'s head (freshly
    drawn from ``seed``) on the ResNet trunk; returns what it recorded."""
    arch, weights = load_encoder(path)
    cfg = {**architecture.to_dict(), "encoder": arch, "coord_channels": False, "columns": 1}
    if cfg["pool"] == "spatial":
        cfg["pool"] = "flatten"
    torch.manual_seed(seed)
    net = QNetwork(NetConfig.from_dict(cfg))
    net.columns[0].encoder.load_state_dict(weights)  # type: ignore[union-attr]  # set for a ResNet architecture
    net.eval()
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    record = {"encoder": {"file": Path(path).name, "sha256": digest, "architecture": arch, "seed": seed}}
    _save(out, net, training, record)
    return record["encoder"]
