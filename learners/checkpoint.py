"""Checkpoints: the learner's schema on top of the shared folder format (``nsl.checkpoint_format``).

The folder format (file names, atomic writes, the content-hash id) belongs to
``nsl.checkpoint_format``, which the catalog uses too.  Here the files mean::

    model.safetensors     the online network's weights (all columns)
    config.json           format and version, architecture, training config,
                          method, data sources and weights, parent checkpoint,
                          code version, step
    trainer_state.pt      optional: target networks, optimiser and random
                          states, only needed to resume the run that wrote it

A checkpoint loads from the first two files alone, and :func:`read_config`
refuses a ``config.json`` this learner cannot interpret.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import safetensors.torch
import torch

from nsl import checkpoint_format as fmt
from nsl.checkpoint_format import CONFIG_FILE, TRAINER_FILE
from nsl.checkpoint_format import WEIGHTS_FILE as MODEL_FILE
from nsl.errors import ConfigError, CorruptDataError, IncompatibleVersionError
from nsl.version import __version__, code_version
from nsl.workspace import atomic_write_json as write_json  # noqa: F401  (nsl.learners.train writes run.json with it)

from .config import NetConfig, TrainConfig
from .networks import QNetwork

CHECKPOINT_FORMAT = "nsl-qtopt-checkpoint"
CHECKPOINT_VERSION = 1
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
        """The learning rate the checkpoint was trained with (fine-tuning starts from 25% of it)."""
        return float(self.config["training"]["lr"])

    @property
    def id(self) -> str:
        return checkpoint_id(self.path)


def checkpoint_config(
    net: QNetwork,
    *,
    training: TrainConfig,
    method: str,
    data: dict[str, Any],
    parent: dict[str, Any] | None,
    step: int,
    learner: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The ``config.json`` of a checkpoint (``training.lr`` must be the resolved learning rate); ``learner`` is a
    plugin learner's name and package (absent for the built-in learners)."""
    config = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "architecture": net.cfg.to_dict(),
        "training": training.to_dict(),
        "method": method,
        "data": data,
        "parent": parent,
        "code_version": code_version(),
        "step": int(step),
    }
    if learner is not None:
        config["learner"] = learner
    return config


def save_checkpoint(path: Path, net: QNetwork, config: dict[str, Any], trainer_state: dict | None = None) -> Path:
    """Write a checkpoint folder at ``path`` atomically (replacing one already there)."""
    weights = {k: v.detach().cpu().contiguous() for k, v in net.state_dict().items()}  # from any device
    files: dict[str, bytes] = {
        MODEL_FILE: safetensors.torch.save(weights, metadata={"format": CHECKPOINT_FORMAT}),
        CONFIG_FILE: fmt.encode_config(config),
    }
    if trainer_state is not None:
        buf = io.BytesIO()
        torch.save(trainer_state, buf)
        files[TRAINER_FILE] = buf.getvalue()
    fmt.write_folder(Path(path), files, replace=True)
    return Path(path)


def read_config(path: Path) -> dict[str, Any]:
    """The ``config.json`` of the checkpoint at ``path``, checked against the learner's schema."""
    path = Path(path)
    config = fmt.read_config(path)
    missing = [k for k in REQUIRED_KEYS if k not in config]
    if missing:
        raise CorruptDataError(
            f"checkpoint {path}: {CONFIG_FILE} lacks key(s) {missing}; it is incomplete or from "
            "another tool, so its weights cannot be interpreted"
        )
    if config["format"] != CHECKPOINT_FORMAT:
        raise CorruptDataError(f"checkpoint {path}: format {config['format']!r} is not {CHECKPOINT_FORMAT!r}")
    version = config["version"]
    if not isinstance(version, int) or version > CHECKPOINT_VERSION or version < 1:
        raise IncompatibleVersionError(
            f"checkpoint {path} has format version {version!r}; this nsl "
            f"({__version__}) reads version {CHECKPOINT_VERSION}; use a matching nsl"
        )
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
    from nsl import plugins

    path = Path(path)
    config = read_config(path)
    plugins.require(plugins.recorded(config), f"checkpoint {path}")  # trained by a plugin learner
    net = QNetwork(NetConfig.from_dict(config["architecture"]))
    model_file = path / MODEL_FILE
    if not model_file.is_file():
        raise CorruptDataError(f"checkpoint {path} has no {MODEL_FILE}; it is incomplete")
    try:
        weights = safetensors.torch.load(model_file.read_bytes())
    except Exception as e:  # safetensors raises its own error types for truncated or altered files
        raise CorruptDataError(
            f"checkpoint {path}: {MODEL_FILE} cannot be read ({e}); it is truncated or altered"
        ) from None
    expected = net.state_dict()
    missing, extra = sorted(set(expected) - set(weights)), sorted(set(weights) - set(expected))
    if missing or extra:
        raise CorruptDataError(
            f"checkpoint {path}: weights do not match the architecture in {CONFIG_FILE} "
            f"(missing {missing[:3]}{'...' if len(missing) > 3 else ''}, "
            f"unexpected {extra[:3]}{'...' if len(extra) > 3 else ''})"
        )
    for name, t in expected.items():
        if tuple(weights[name].shape) != tuple(t.shape):
            raise CorruptDataError(
                f"checkpoint {path}: tensor {name} has shape {tuple(weights[name].shape)} but the "
                f"architecture in {CONFIG_FILE} needs {tuple(t.shape)}"
            )
    net.load_state_dict(weights)
    net.eval()
    return Checkpoint(path, net, config)


def load_trainer_state(path: Path) -> dict | None:
    """The trainer state saved with the checkpoint at ``path``, or None."""
    f = Path(path) / TRAINER_FILE
    if not f.is_file():
        return None
    try:
        # On the CPU whatever device wrote it: the learner moves each part to its own device when it loads it.
        return torch.load(io.BytesIO(f.read_bytes()), map_location="cpu", weights_only=True)
    except Exception as e:
        raise CorruptDataError(
            f"checkpoint {path}: {TRAINER_FILE} cannot be read ({e}); delete this checkpoint "
            "folder to resume from the one before"
        ) from None


def checkpoint_id(path: Path) -> str:
    """Content hash of the checkpoint folder ``path`` (``nsl.checkpoint_format.checkpoint_id``)."""
    config = read_config(path)
    if not (Path(path) / MODEL_FILE).is_file():
        raise CorruptDataError(f"checkpoint {path} has no {MODEL_FILE}; it is incomplete")
    return fmt.checkpoint_id(Path(path) / MODEL_FILE, config)
