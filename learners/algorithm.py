"""The learner interface: what the training loop asks of an offline learner, and where learners are found.

A learner (QT-Opt, IQL, or a plugin's) is an :class:`Algorithm`.  ``nsl.learners.train`` owns everything around
it: the fine-tuning methods' starting networks, the data, the learning-rate schedule, checkpoints, resuming,
early stopping and logging.  The learner owns the gradient step::

    state   = algo.create(net, lr, cfg, options)     # networks, optimisers, generators; net is the online network
    metrics = algo.update(state, batch, cfg, step, options)   # one step on a sampler batch (tensors by nsl.keys)
    policy  = algo.policy(net, cem, **kw)            # how a checkpoint acts (default: CEM over its Q-network)

``state`` has ``online`` (the network a checkpoint saves, a ``QNetwork``), ``set_lr(lr)``, ``state_dict()`` and
``load_state_dict()`` (what a resumed run restores).  ``metrics`` holds at least ``losses/q_loss``, ``q/mean``
and ``q/target_mean``, as numbers or as 0-d tensors that the loop reads only when it logs (on a GPU, reading one
makes the host wait for the device).  ``cfg.device`` is where the state lives: ``create`` moves ``net`` there and
``update`` moves the batch.  ``options`` is the learner's own settings (``Algorithm.Options``, a dataclass), recorded in
``TrainConfig.learner_options``.  An algorithm declares the fine-tuning ``methods`` it supports and whether
``early_stopping`` (a CEM policy evaluated in the simulator) applies; ``train`` refuses the rest in one line.

Learners are found by name (``learners/registry.py``): the built-in ``qtopt`` and ``iql``, those registered with
``register_learner``, then the ``nsl.learners`` entry points of installed packages.  A run with a plugin learner
records the package and version in its checkpoints (``nsl.plugins``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, ClassVar

from nsl.errors import ConfigError

from .config import METHODS, CemConfig, TrainConfig


@dataclass(frozen=True)
class NoOptions:
    """A learner without settings of its own."""


class Algorithm:
    """Base class of learners: override ``create`` and ``update``; the rest has defaults."""

    name: ClassVar[str] = ""
    methods: ClassVar[tuple[str, ...]] = METHODS  # fine-tuning methods it supports (nsl.learners.METHODS)
    early_stopping: ClassVar[bool] = True  # its checkpoints can be scored in the simulator while it trains
    conservative: ClassVar[bool] = False  # it applies TrainConfig.conservative (else that weight must stay 0)
    Options: ClassVar[type] = NoOptions  # a frozen dataclass of its own settings

    def options(self, values: dict[str, Any] | None) -> Any:
        """The learner's settings from ``TrainConfig.learner_options``, refusing unknown names in one line."""
        values = dict(values or {})
        known = {f.name for f in fields(self.Options)}
        bad = sorted(set(values) - known)
        if bad:
            raise ConfigError(
                f"learner {self.name!r} has no option(s) {bad}; its options are {sorted(known) or 'none'}"
            )
        try:
            return self.Options(**values)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"learner {self.name!r}: {e}") from None

    def option_dict(self, options: Any) -> dict[str, Any]:
        return asdict(options)

    def create(self, net, lr: float, cfg: TrainConfig, options: Any):  # pragma: no cover - interface
        raise NotImplementedError

    def update(self, state, batch: dict, cfg: TrainConfig, step: int, options: Any) -> dict[str, Any]:
        raise NotImplementedError  # pragma: no cover - interface

    def policy(self, net, cem: CemConfig, **kwargs: Any):
        """How a checkpoint of this learner acts, given ``CEMPolicy``'s keywords; None (the default) is greedy CEM
        over its Q-network, as QT-Opt's and IQL's act."""
        return None
