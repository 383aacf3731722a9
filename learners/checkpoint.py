"""Checkpoints: a folder with the weights in safetensors and a JSON config beside them.

Layout of one checkpoint folder::

    model.safetensors     the online network's weights (all columns)
    config.json           format and version, architecture, training config,
                          method, data sources and weights, parent checkpoint,
                          code version, step
    trainer_state.pt      optional: target networks, optimiser and random
                          states, only needed to resume the run that wrote it

A checkpoint loads from the first two files alone.  A folder is written under
a temporary name and renamed into place, so a checkpoint either exists
completely or not at all.  :func:`checkpoint_id` is a content hash (weights
and config) for the catalog.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import safetensors.torch
import torch

import nsl
from nsl.errors import ConfigError, CorruptDataError, IncompatibleVersionError, UnknownReferenceError
from nsl.workspace import atomic_write_bytes

from .config import NetConfig, TrainConfig
from .networks import QNetwork

CHECKPOINT_FORMAT = "nsl-qtopt-checkpoint"
CHECKPOINT_VERSION = 1
MODEL_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
TRAINER_FILE = "trainer_state.pt"
REQUIRED_KEYS = ("format", "version", "architecture", "training", "method", "data", "parent", "code_version", "step")


@dataclass
class Checkpoint:
    """A loaded checkpoint: its network (in eval mode) and its config."""

    path: Path
    net: QNetwork
    config: dict[str, Any]

    @property
    def architecture(self) -> NetConfig:
        return self.net.cfg

    @property
    def training(self) -> TrainConfig:
        return TrainConfig.from_dict(self.config["training"])

    @property
    def step(self) -> int:
        return int(self.config["step"])

    @property
    def lr(self) -> float:
        return float(self.config["training"]["lr"])

    @property
    def id(self) -> str:
        return checkpoint_id(self.path)


def checkpoint_config(net: QNetwork, *, training: TrainConfig, method: str, data: dict[str, Any],
                      parent: dict[str, Any] | None, step: int) -> dict[str, Any]:
    """The ``config.json`` of a checkpoint (``training.lr`` must be the resolved learning rate)."""
    return {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "architecture": net.cfg.to_dict(),
        "training": training.to_dict(),
        "method": method,
        "data": data,
        "parent": parent,
        "code_version": nsl.code_version(),
        "step": int(step),
    }


def save_checkpoint(path: Path, net: QNetwork, config: dict[str, Any], trainer_state: dict | None = None) -> Path:
    """Write a checkpoint folder at ``path`` atomically (replacing one already there)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    try:
        weights = {k: v.detach().contiguous() for k, v in net.state_dict().items()}
        (tmp / MODEL_FILE).write_bytes(safetensors.torch.save(weights, metadata={"format": CHECKPOINT_FORMAT}))
        (tmp / CONFIG_FILE).write_text(json.dumps(config, indent=2, sort_keys=True) + "\n")
        if trainer_state is not None:
            buf = io.BytesIO()
            torch.save(trainer_state, buf)
            (tmp / TRAINER_FILE).write_bytes(buf.getvalue())
        for f in tmp.iterdir():
            with open(f, "rb") as fh:
                os.fsync(fh.fileno())
        if path.exists():
            shutil.rmtree(path)
        os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path


def read_config(path: Path) -> dict[str, Any]:
    """The validated ``config.json`` of the checkpoint at ``path``."""
    path = Path(path)
    if not path.is_dir():
        raise UnknownReferenceError(f"no checkpoint folder at {path}; pass the folder that holds {MODEL_FILE} and {CONFIG_FILE}")
    cfg_file = path / CONFIG_FILE
    if not cfg_file.is_file():
        raise CorruptDataError(f"checkpoint {path} has no {CONFIG_FILE}; it is incomplete or not an nsl checkpoint")
    try:
        config = json.loads(cfg_file.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CorruptDataError(f"checkpoint {path}: {CONFIG_FILE} is not valid JSON ({e}); restore it or retrain") from None
    if not isinstance(config, dict):
        raise CorruptDataError(f"checkpoint {path}: {CONFIG_FILE} must hold a JSON object, not {type(config).__name__}")
    missing = [k for k in REQUIRED_KEYS if k not in config]
    if missing:
        raise CorruptDataError(f"checkpoint {path}: {CONFIG_FILE} lacks key(s) {missing}; it is incomplete or from "
                               "another tool, so its weights cannot be interpreted")
    if config["format"] != CHECKPOINT_FORMAT:
        raise CorruptDataError(f"checkpoint {path}: format {config['format']!r} is not {CHECKPOINT_FORMAT!r}")
    version = config["version"]
    if not isinstance(version, int) or version > CHECKPOINT_VERSION or version < 1:
        raise IncompatibleVersionError(f"checkpoint {path} has format version {version!r}; this nsl "
                                       f"({nsl.__version__}) reads version {CHECKPOINT_VERSION}; use a matching nsl")
    for section, parse in (("architecture", NetConfig.from_dict), ("training", TrainConfig.from_dict)):
        if not isinstance(config[section], dict):
            raise CorruptDataError(f"checkpoint {path}: {CONFIG_FILE} '{section}' must be an object")
        try:
            parse(config[section])
        except (ConfigError, TypeError) as e:
            raise CorruptDataError(f"checkpoint {path}: invalid '{section}' in {CONFIG_FILE}: {e}") from None
    return config


def load_checkpoint(path: Path) -> Checkpoint:
    """Load the network of the checkpoint at ``path``, refusing weights that do not match its config."""
    path = Path(path)
    config = read_config(path)
    net = QNetwork(NetConfig.from_dict(config["architecture"]))
    model_file = path / MODEL_FILE
    if not model_file.is_file():
        raise CorruptDataError(f"checkpoint {path} has no {MODEL_FILE}; it is incomplete")
    try:
        weights = safetensors.torch.load(model_file.read_bytes())
    except Exception as e:  # safetensors raises its own error types for truncated or altered files
        raise CorruptDataError(f"checkpoint {path}: {MODEL_FILE} cannot be read ({e}); it is truncated or altered") from None
    expected = net.state_dict()
    missing, extra = sorted(set(expected) - set(weights)), sorted(set(weights) - set(expected))
    if missing or extra:
        raise CorruptDataError(f"checkpoint {path}: weights do not match the architecture in {CONFIG_FILE} "
                               f"(missing {missing[:3]}{'...' if len(missing) > 3 else ''}, "
                               f"unexpected {extra[:3]}{'...' if len(extra) > 3 else ''})")
    for name, t in expected.items():
        if tuple(weights[name].shape) != tuple(t.shape):
            raise CorruptDataError(f"checkpoint {path}: tensor {name} has shape {tuple(weights[name].shape)} but the "
                                   f"architecture in {CONFIG_FILE} needs {tuple(t.shape)}")
    net.load_state_dict(weights)
    net.eval()
    return Checkpoint(path, net, config)


def load_trainer_state(path: Path) -> dict | None:
    """The trainer state saved with the checkpoint at ``path``, or None."""
    f = Path(path) / TRAINER_FILE
    if not f.is_file():
        return None
    try:
        return torch.load(io.BytesIO(f.read_bytes()), weights_only=True)
    except Exception as e:
        raise CorruptDataError(f"checkpoint {path}: {TRAINER_FILE} cannot be read ({e}); delete this checkpoint "
                               "folder to resume from the one before") from None


def checkpoint_id(path: Path) -> str:
    """Content hash of a checkpoint: sha256 over its weights file and its canonical config."""
    path = Path(path)
    config = read_config(path)
    h = hashlib.sha256()
    h.update((path / MODEL_FILE).read_bytes())
    h.update(b"\0")
    h.update(json.dumps(config, sort_keys=True, separators=(",", ":")).encode())
    return h.hexdigest()


def write_json(path: Path, obj: Any) -> None:
    atomic_write_bytes(Path(path), (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode())
