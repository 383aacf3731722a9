"""The settings of an evaluation and of early stopping, and the stopping rule: light (no simulator, no NumPy).

``nsl eval`` and ``nsl train``'s early-stopping options take their defaults
from these classes, so each default is written once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from nsl.errors import ConfigError
from nsl.scenes import EVAL_SCENES, SELECTION_SCENES

# criterion -> (curve column, mode)
CRITERIA: dict[str, tuple[str, str]] = {
    "eval": ("target_success", "max"),
    "softopc": ("softopc", "max"),
    "auc": ("auc", "max"),
    "td": ("td_error", "min"),
    "qmean": ("q_mean", "max"),  # the average Q of held-out data: its peak (Kumar et al. 2021)
    "fqe": ("fqe", "max"),  # fitted Q evaluation's estimate of the success rate (nsl.learners.fqe)
}


@dataclass(frozen=True)
class EvalConfig:
    """How a policy is evaluated; saved with every evaluation."""

    episodes: int = 100  # episodes per shift
    split: str = "test"  # object split: held-out test objects by default
    seed: int = EVAL_SCENES  # scene seeds (seed, i); equal seeds give paired comparisons
    workers: int = 1  # processes
    batch: int = 8  # environments per worker stepping in lock-step (batched policy calls)
    image_size: int = 64

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class EarlyStopConfig:
    """``nsl train --early-stop``: what is evaluated, how often, and when to stop."""

    every: int = 2000  # gradient steps between evaluations (the trainer's eval_every)
    episodes: int = 50  # simulator episodes on the target shift per evaluation (0: offline criteria only)
    base_episodes: int = 0  # episodes on the base task per evaluation, to see forgetting (0: skip)
    patience: int = 5  # evaluations without improvement before stopping
    min_delta: float = 0.0  # smallest improvement that counts (success fraction, or criterion units)
    criterion: str = "eval"  # what decides: eval (target success) | softopc | auc | td (held-out TD error)
    seed: int = SELECTION_SCENES  # evaluation scene seeds, the same at every step (paired across steps)
    held_out: float = 0.1  # fraction of target episodes held out for the offline criteria

    def __post_init__(self):
        if self.criterion not in CRITERIA:
            raise ConfigError(f"early-stop criterion {self.criterion!r} is unknown; use one of {', '.join(CRITERIA)}")
        if self.every < 1:
            raise ConfigError(f"early-stop every {self.every!r} must be at least 1 gradient step")
        if self.episodes < 0 or self.base_episodes < 0:
            raise ConfigError(f"early-stop episodes ({self.episodes}, base {self.base_episodes}) must be >= 0")
        if self.criterion == "eval" and self.episodes < 1:
            raise ConfigError("early-stop criterion 'eval' needs episodes >= 1; or choose softopc, auc or td")
        if not isinstance(self.patience, int) or self.patience < 1:
            raise ConfigError(f"early-stop patience {self.patience!r} must be an integer of at least 1")
        if self.min_delta < 0:
            raise ConfigError(f"early-stop min_delta {self.min_delta!r} must be >= 0")
        if not 0.0 < self.held_out < 1.0:
            raise ConfigError(f"early-stop held_out {self.held_out!r} must be between 0 and 1 (e.g. 0.1)")

    @property
    def column(self) -> str:
        return CRITERIA[self.criterion][0]

    @property
    def mode(self) -> str:
        return CRITERIA[self.criterion][1]

    def stopper(self) -> EarlyStopping:
        return EarlyStopping(self.patience, self.min_delta, self.mode)

    def eval_config(self, base: bool = False, **overrides: Any) -> EvalConfig:
        """The EvalConfig of one evaluation (``base=True``: the base-task episodes)."""
        return EvalConfig(**{"episodes": self.base_episodes if base else self.episodes, "seed": self.seed, **overrides})

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> EarlyStopConfig:
        unknown = sorted(set(d) - set(cls.__dataclass_fields__))
        if unknown:
            raise ConfigError(f"unknown early-stop setting(s) {unknown}; known: {sorted(cls.__dataclass_fields__)}")
        return cls(**d)


class EarlyStopping:
    """Stop after ``patience`` consecutive evaluations that do not improve on the best by more than ``min_delta``.

    ``update(step, value)`` returns True once the patience is used up.  A NaN
    value never improves.  The whole curve is kept in ``history``.
    """

    def __init__(self, patience: int, min_delta: float = 0.0, mode: str = "max"):
        if not isinstance(patience, int) or patience < 1:
            raise ConfigError(f"patience {patience!r} must be an integer of at least 1 (evaluations)")
        if min_delta < 0:
            raise ConfigError(f"min_delta {min_delta!r} must be >= 0")
        if mode not in ("max", "min"):
            raise ConfigError(f"mode {mode!r} is unknown; use 'max' or 'min'")
        self.patience, self.min_delta, self.mode = patience, float(min_delta), mode
        self.history: list[tuple[int, float]] = []
        self.best_step: int | None = None
        self.best_value: float | None = None
        self.bad_evals = 0  # consecutive evaluations without improvement
        self.stopped_step: int | None = None

    def improves(self, value: float) -> bool:
        if math.isnan(value):
            return False
        if self.best_value is None:
            return True
        if self.mode == "max":
            return value > self.best_value + self.min_delta
        return value < self.best_value - self.min_delta

    def update(self, step: int, value: float | None) -> bool:
        value = math.nan if value is None else float(value)
        if self.history and step <= self.history[-1][0]:
            raise ConfigError(f"early stopping got step {step} after step {self.history[-1][0]}; steps must increase")
        self.history.append((int(step), value))
        if self.improves(value):
            self.best_step, self.best_value, self.bad_evals = int(step), value, 0
        else:
            self.bad_evals += 1
        if self.bad_evals >= self.patience and self.stopped_step is None:
            self.stopped_step = int(step)
        return self.should_stop

    @property
    def should_stop(self) -> bool:
        return self.stopped_step is not None

    def state_dict(self) -> dict:
        return {
            "patience": self.patience,
            "min_delta": self.min_delta,
            "mode": self.mode,
            "best_step": self.best_step,
            "best_value": self.best_value,
            "bad_evals": self.bad_evals,
            "stopped_step": self.stopped_step,
            "history": [list(h) for h in self.history],
        }
