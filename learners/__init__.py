"""Offline learners in PyTorch (QT-Opt, IQL, plugins): the Q-network, CEM, fine-tuning methods, checkpoints, the
CEM policy.

Public surface (other folders import these from ``nsl.learners`` only)::

    NetConfig, CemConfig, TrainConfig, METHODS         # settings
    FINE_TUNE_STEPS, FINE_TUNE_CONSERVATIVE            # the fine-tuning recipe's defaults (with the 25% rate)
    QNetwork                                           # Q(image, state, action) -> logit
    cem_maximize, noise_from_generator, noise_from_rngs
    Learner, update, bellman_target                    # one QT-Opt step
    Algorithm, register_learner, find_learner          # the learner interface (QTOpt, IQL, plugins)
    learner_names, parse_learner
    train, TrainResult                                 # the loop: pre-training and fine-tuning
    inherited_settings                                 # what a fine-tune keeps from its parent (n-step, crop)
    Sampler, ArraySampler                              # the data contract and an in-memory sampler
    Checkpoint, load_checkpoint, save_checkpoint, checkpoint_config, checkpoint_id, read_config
    CEMPolicy, load_policy                             # a checkpoint acting in the collectors
    LeRobotActing                                      # ... and with LeRobot's select_action(batch)
    layer_distances                                    # where a fine-tune changed the weights (Fig. 5.8)
    FeatureConfig, train_features, encoder_features    # supervised features (Table 5.2's ImageNet column)
    load_encoder

Each name loads its module on first use, so ``from nsl.learners import TrainConfig``
loads no PyTorch.  The learner knows no simulator: it never imports ``nsl.collectors`` or ``nsl.eval``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nsl.lazy import lazy_exports

_EXPORTS = {
    "algorithm": ("Algorithm", "NoOptions"),
    "registry": ("find_learner", "learner_names", "parse_learner", "register_learner"),
    "cem": ("cem_maximize", "full_actions", "noise_from_generator", "noise_from_rngs"),
    "checkpoint": (
        "CHECKPOINT_FORMAT",
        "CHECKPOINT_VERSION",
        "CONFIG_FILE",
        "MODEL_FILE",
        "TRAINER_FILE",
        "Checkpoint",
        "checkpoint_config",
        "checkpoint_id",
        "load_checkpoint",
        "read_config",
        "save_checkpoint",
    ),
    "config": (
        "FINE_TUNE_CONSERVATIVE",
        "FINE_TUNE_STEPS",
        "METHODS",
        "CemConfig",
        "FeatureConfig",
        "NetConfig",
        "TrainConfig",
    ),
    "features": ("encoder_features", "load_encoder", "train_features"),
    "networks": ("QNetwork",),
    "policy": ("CEMPolicy", "LeRobotActing", "load_policy"),
    "iql": ("IQL", "IQLOptions"),
    "qtopt": ("Learner", "QTOpt", "bellman_target", "update"),
    "sampler": ("ArraySampler", "Sampler", "synthetic_sampler"),
    "training": ("FINAL_DIR", "TrainResult", "inherited_settings", "train"),
    "weight_change": ("layer_distances",),
}
__all__, __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())


if TYPE_CHECKING:  # static analysers see the eager imports
    from .algorithm import Algorithm, NoOptions  # noqa: F401
    from .cem import cem_maximize, full_actions, noise_from_generator, noise_from_rngs  # noqa: F401
    from .checkpoint import (  # noqa: F401
        CHECKPOINT_FORMAT,
        CHECKPOINT_VERSION,
        CONFIG_FILE,
        MODEL_FILE,
        TRAINER_FILE,
        Checkpoint,
        checkpoint_config,
        checkpoint_id,
        load_checkpoint,
        read_config,
        save_checkpoint,
    )
    from .config import (  # noqa: F401
        FINE_TUNE_CONSERVATIVE,
        FINE_TUNE_STEPS,
        METHODS,
        CemConfig,
        FeatureConfig,
        NetConfig,
        TrainConfig,
    )
    from .features import encoder_features, load_encoder, train_features  # noqa: F401
    from .iql import IQL, IQLOptions  # noqa: F401
    from .networks import QNetwork  # noqa: F401
    from .policy import CEMPolicy, LeRobotActing, load_policy  # noqa: F401
    from .qtopt import Learner, QTOpt, bellman_target, update  # noqa: F401
    from .registry import find_learner, learner_names, parse_learner, register_learner  # noqa: F401
    from .sampler import ArraySampler, Sampler, synthetic_sampler  # noqa: F401
    from .training import FINAL_DIR, TrainResult, inherited_settings, train  # noqa: F401
