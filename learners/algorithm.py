"""The learner interface: what the training loop asks of an offline learner, and where learners are found.

A learner (QT-Opt, IQL, or a plugin's) is an :class:`Algorithm`.  ``nsl.learners.train`` owns everything around
it: the fine-tuning methods' starting networks, the data, the learning-rate schedule, checkpoints, resuming,
early stopping and logging.  The learner owns the gradient step::

    state   = algo.create(net, lr, cfg, options)     # networks, optimisers, generators; net is the online network
    metrics = algo.update(state, batch, cfg, step, options)   # one step on a sampler batch (tensors by nsl.keys)
    policy  = algo.policy(net, cem, **kw)            # how a checkpoint acts (default: CEM over its Q-network)

``state`` has ``online`` (the network a checkpoint saves, a ``QNetwork``), ``set_lr(lr)``, ``state_dict()`` and
``load_state_dict()`` (what a resumed run restores).  ``metrics`` holds at least ``losses/q_loss``, ``q/mean``
and ``q/target_mean``.  ``options`` is the learner's own settings (``Algorithm.Options``, a dataclass), recorded in
``TrainConfig.learner_options``.  An algorithm declares the fine-tuning ``methods`` it supports and whether
``early_stopping`` (a CEM policy evaluated in the simulator) applies; ``train`` refuses the rest in one line.

Learners are found by name: the built-in ``qtopt`` and ``iql``, those registered here with
:func:`register_learner`, then the ``nsl.learners`` entry points of installed packages.  A run with a plugin
learner records the package and version in its checkpoints (``nsl.plugins``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, ClassVar

from nsl.errors import ConfigError, unknown

from .config import METHODS, CemConfig, TrainConfig

BUILT_IN = ("qtopt", "iql")
DEFAULT_LEARNER = "qtopt"


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

    def update(self, state, batch: dict, cfg: TrainConfig, step: int, options: Any) -> dict[str, float]:
        raise NotImplementedError  # pragma: no cover - interface

    def policy(self, net, cem: CemConfig, **kwargs: Any):
        """How a checkpoint of this learner acts: greedy CEM over its Q-network (``CEMPolicy``'s keywords)."""
        from .policy import CEMPolicy

        return CEMPolicy(net, cem, **kwargs)


_REGISTERED: dict[str, tuple[Algorithm, dict[str, str] | None]] = {}


def register_learner(algo: Algorithm, plugin: dict[str, str] | None = None) -> None:
    """Make ``algo`` available as ``--learner algo.name`` in this process (a notebook's plugin); ``plugin`` is
    the package and version its checkpoints record (default: ``__main__``)."""
    if not isinstance(algo, Algorithm) or not algo.name:
        raise ConfigError(f"register_learner takes an nsl.learners.Algorithm with a name, not {algo!r}")
    if algo.name in BUILT_IN:
        raise ConfigError(f"learner {algo.name!r} is built in; give yours another name (e.g. mypkg.{algo.name})")
    _REGISTERED[algo.name] = (algo, plugin or {"package": "__main__", "version": "0"})


def learner_names() -> list[str]:
    """Every learner name: the built-in ones, then those registered here or installed as plugins."""
    from nsl import plugins

    return [*BUILT_IN, *sorted(set(_REGISTERED) | set(plugins.names("nsl.learners")))]


def find_learner(name: str) -> tuple[Algorithm, dict[str, str] | None]:
    """The algorithm called ``name`` and, for a plugin's, its package and version (None for a built-in one)."""
    if name == "qtopt":
        from .qtopt import QTOpt

        return QTOpt(), None
    if name == "iql":
        from .iql import IQL

        return IQL(), None
    if name not in _REGISTERED:
        from nsl import plugins

        found = plugins.load("nsl.learners", name)
        if found is None:
            raise unknown(
                "learner", name, learner_names(), "a plugin learner comes from an installed package's nsl.learners"
            )
        obj, info = found
        algo = obj() if isinstance(obj, type) else obj
        if not isinstance(algo, Algorithm):
            raise ConfigError(
                f"plugin learner {name!r} of package {info['package']} is not an nsl.learners.Algorithm; "
                "fix that package"
            )
        _REGISTERED[name] = (algo, info)
    return _REGISTERED[name]


def parse_learner(spec: str) -> tuple[str, dict[str, Any]]:
    """``"iql:expectile=0.9,v_warmup=100"`` -> ``("iql", {"expectile": 0.9, "v_warmup": 100})``."""
    name, _, rest = spec.partition(":")
    if not name:
        raise ConfigError(f"--learner {spec!r}: write NAME or NAME:KEY=VALUE,..., e.g. iql:expectile=0.9")
    options: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"--learner {spec!r}: option {item!r} is not KEY=VALUE, e.g. iql:expectile=0.9")
        options[key] = _number(value)
    return name, options


def _number(value: str) -> Any:
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    return value
