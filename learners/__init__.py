"""Offline QT-Opt in PyTorch: the Q-network, CEM, fine-tuning methods, checkpoints, the CEM policy.

Public surface (other folders import these from ``nsl.learners`` only)::

    NetConfig, CemConfig, TrainConfig, METHODS         # settings
    FINE_TUNE_STEPS, FINE_TUNE_CONSERVATIVE            # the fine-tuning recipe's defaults (with the 25% rate)
    QNetwork                                           # Q(image, state, action) -> logit
    cem_maximize, noise_from_generator, noise_from_rngs
    Learner, update, bellman_target                    # one QT-Opt step
    train, TrainResult                                 # the loop: pre-training and fine-tuning
    inherited_settings                                 # what a fine-tune keeps from its parent (n-step, crop)
    Sampler, ArraySampler                              # the data contract and an in-memory sampler
    Checkpoint, load_checkpoint, save_checkpoint, checkpoint_config, checkpoint_id, read_config
    CEMPolicy, load_policy                             # a checkpoint acting in the collectors

The learner knows no simulator: it never imports ``nsl.collectors`` or ``nsl.eval``.
"""

from .cem import cem_maximize, full_actions, noise_from_generator, noise_from_rngs
from .checkpoint import (CHECKPOINT_FORMAT, CHECKPOINT_VERSION, CONFIG_FILE, MODEL_FILE, TRAINER_FILE, Checkpoint,
                         checkpoint_config, checkpoint_id, load_checkpoint, read_config, save_checkpoint)
from .config import FINE_TUNE_CONSERVATIVE, FINE_TUNE_STEPS, METHODS, CemConfig, NetConfig, TrainConfig
from .networks import QNetwork
from .policy import CEMPolicy, load_policy
from .qtopt import Learner, bellman_target, update
from .sampler import ArraySampler, Sampler
from .train import FINAL_DIR, TrainResult, inherited_settings, train

__all__ = [
    "cem_maximize", "full_actions", "noise_from_generator", "noise_from_rngs",
    "CHECKPOINT_FORMAT", "CHECKPOINT_VERSION", "CONFIG_FILE", "MODEL_FILE", "TRAINER_FILE", "Checkpoint",
    "checkpoint_config", "checkpoint_id", "load_checkpoint", "read_config", "save_checkpoint",
    "FINE_TUNE_CONSERVATIVE", "FINE_TUNE_STEPS", "METHODS", "CemConfig", "NetConfig", "TrainConfig", "QNetwork",
    "CEMPolicy", "load_policy",
    "Learner", "bellman_target", "update", "ArraySampler", "Sampler",
    "FINAL_DIR", "TrainResult", "inherited_settings", "train",
]
