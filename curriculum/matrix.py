"""The transfer-advantage matrix: what an entry means, and the ``matrix.json`` file that holds it.

Definitions (Skill Builder, Ch. 6 of the source; ``docs/transfer.md``)::

    AUC(run)        area under a run's success curve on the target task, over its evaluated points
                    (step 0 included), by the trapezoid rule, divided by the step range: a mean success in [0, 1]
                    (``nsl.eval.curve_auc``)
    A(src -> dst)   AUC(fine-tune src's checkpoint on dst's data) / AUC(train from scratch on dst's data),
                    both with the same steps, data mix and evaluation scenes.  A > 1: src helps; A < 1: it hurts.

Seeds are paired: seed ``s`` of a fine-tune is divided by seed ``s`` of the scratch run, giving ``A_s``; the
entry is the mean of the ``A_s`` and its interval the 95% Student-t interval over seeds (none from one seed).
A scratch AUC below the floor (by default one success in the evaluation's N scenes, ``1/N``) is raised to
the floor: below it the ratio measures evaluation noise, not transfer, and a scratch AUC of 0 would make
every ratio infinite.

File format (``matrix.json``; ``nsl transfer`` writes it, ``nsl curriculum`` reads it)::

    {"format": "nsl.transfer-matrix", "version": 1,
     "tasks": ["base", "harsh_lighting", ...],        # the order every table and tie-break uses
     "base": "base",                                  # the task the base checkpoint has learned (or null)
     "advantage": {"SRC": {"DST": 1.8, ...}, ...},    # every ordered pair SRC != DST; null = not measured
     "interval": {"SRC": {"DST": [1.2, 2.4]}},        # optional; 95% over seeds
     "meta": {...}}                                   # anything else (plan, AUCs, proxy scores)

A hand-written file needs only ``tasks`` and ``advantage``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, CorruptDataError
from nsl.stats import t_interval as stats_t_interval
from nsl.workspace import atomic_write_bytes

MATRIX_FORMAT = "nsl.transfer-matrix"
MATRIX_VERSION = 1
SCRATCH = "scratch"  # the root vertex: learning a task from a random initialisation, advantage 1 by definition

Pair = tuple[str, str]


@dataclass(frozen=True)
class TransferMatrix:
    """Measured advantages ``A[(src, dst)]`` between tasks (None: not measured)."""

    tasks: tuple[str, ...]
    advantage: Mapping[Pair, float | None]
    interval: Mapping[Pair, tuple[float, float]] = field(default_factory=dict)
    base: str | None = None  # the task the base checkpoint has learned
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        tasks = tuple(self.tasks)
        object.__setattr__(self, "tasks", tasks)
        if len(tasks) < 1 or len(set(tasks)) != len(tasks):
            raise ConfigError(f"transfer matrix tasks {list(tasks)} must be a non-empty list of distinct names")
        if SCRATCH in tasks:
            raise ConfigError(f"transfer matrix: {SCRATCH!r} names the from-scratch root; rename that task")
        known = set(tasks)
        for (src, dst), a in self.advantage.items():
            if src not in known or dst not in known:
                bad = src if src not in known else dst
                raise ConfigError(
                    f"transfer matrix is not square: entry A({src} -> {dst}) names task {bad!r}, "
                    f"which is not in its tasks {list(tasks)}"
                )
            if a is not None and (
                not isinstance(a, (int, float)) or isinstance(a, bool) or not math.isfinite(a) or a < 0
            ):
                raise ConfigError(
                    f"transfer matrix entry A({src} -> {dst}) = {a!r} must be a finite number >= 0 "
                    "(a ratio of success-curve areas), or null if not measured"
                )
        missing = [(s, d) for s in tasks for d in tasks if s != d and (s, d) not in self.advantage]
        if missing:
            s, d = missing[0]
            raise ConfigError(
                f"transfer matrix has no entry A({s} -> {d}) ({len(missing)} missing); every ordered "
                "pair of its tasks needs a value, or null if it was not measured"
            )
        if self.base is not None and self.base not in known:
            raise ConfigError(f"transfer matrix base {self.base!r} is not one of its tasks {list(tasks)}")

    def get(self, src: str, dst: str) -> float | None:
        """A(src -> dst); 1.0 from scratch by definition."""
        if src == SCRATCH:
            return 1.0
        return self.advantage[(src, dst)]

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": MATRIX_FORMAT,
            "version": MATRIX_VERSION,
            "tasks": list(self.tasks),
            "base": self.base,
            "advantage": {s: {d: self.advantage[(s, d)] for d in self.tasks if d != s} for s in self.tasks},
            "interval": {
                s: {d: list(self.interval[(s, d)]) for d in self.tasks if (s, d) in self.interval}
                for s in self.tasks
                if any((s, d) in self.interval for d in self.tasks)
            },
            "meta": dict(self.meta),
        }

    def markdown(self, digits: int = 2) -> str:
        """The matrix as a Markdown table: rows fine-tune from, columns learn; intervals in brackets."""
        head = "| from \\ to | " + " | ".join(self.tasks) + " |"
        lines = [head, "|" + "---|" * (len(self.tasks) + 1)]
        for s in self.tasks:
            cells = []
            for d in self.tasks:
                a = None if s == d else self.advantage[(s, d)]
                ci = self.interval.get((s, d))
                cells.append(
                    "-"
                    if s == d
                    else "n/a"
                    if a is None
                    else f"{a:.{digits}f}" + (f" [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]" if ci else "")
                )
            lines.append(f"| {s} | " + " | ".join(cells) + " |")
        return "\n".join(lines)


def matrix_from_dict(d: Mapping[str, Any], source: str = "transfer matrix") -> TransferMatrix:
    """A :class:`TransferMatrix` from its JSON form (validated; one-line errors that name ``source``)."""
    if not isinstance(d, Mapping):
        raise CorruptDataError(f"{source} must be a JSON object with 'tasks' and 'advantage'")
    version = d.get("version", MATRIX_VERSION)
    if d.get("format", MATRIX_FORMAT) != MATRIX_FORMAT or not isinstance(version, int) or version > MATRIX_VERSION:
        raise CorruptDataError(
            f"{source} is {d.get('format')!r} version {d.get('version')!r}; this nsl reads "
            f"{MATRIX_FORMAT!r} up to version {MATRIX_VERSION}"
        )
    tasks, rows = d.get("tasks"), d.get("advantage")
    if not isinstance(tasks, list) or not all(isinstance(t, str) for t in tasks):
        raise ConfigError(f"{source}: 'tasks' must be a list of task names")
    if not isinstance(rows, Mapping) or not all(isinstance(r, Mapping) for r in rows.values()):
        raise ConfigError(f"{source}: 'advantage' must map each task to a row {{task: value}}")
    advantage = {(s, t): v for s, row in rows.items() for t, v in row.items() if s != t}
    interval = {}
    for s, row in (d.get("interval") or {}).items():
        for t, ci in row.items():
            if ci is not None:
                if not (isinstance(ci, Sequence) and len(ci) == 2):
                    raise ConfigError(f"{source}: interval of A({s} -> {t}) must be [low, high]; got {ci!r}")
                interval[(s, t)] = (float(ci[0]), float(ci[1]))
    try:
        return TransferMatrix(tuple(tasks), advantage, interval, d.get("base"), d.get("meta") or {})
    except ConfigError as e:
        raise ConfigError(f"{source}: {str(e).removeprefix('transfer matrix ')}") from None


def load_matrix(path: str | Path) -> TransferMatrix:
    """Read and check a ``matrix.json``."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(
            f"transfer matrix {path} does not exist; `nsl transfer run PLAN` writes one "
            '(or write {"tasks": [...], "advantage": {...}} by hand)'
        )
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise CorruptDataError(f"transfer matrix {path} is not valid JSON: {e}") from None
    return matrix_from_dict(data, str(path))


def save_matrix(matrix: TransferMatrix, path: str | Path) -> Path:
    """Write ``matrix.json`` (temporary file, then rename)."""
    path = Path(path)
    atomic_write_bytes(path, (json.dumps(matrix.to_dict(), indent=2, sort_keys=True) + "\n").encode())
    return path


# --- one entry from measured curves ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Advantage:
    """One entry A(src -> dst) from per-seed AUCs."""

    value: float | None  # mean over seeds of A_s (None: no seed measured both runs)
    interval: tuple[float, float] | None  # 95% Student-t interval over seeds (None with fewer than 2 seeds)
    per_seed: Mapping[int, float]  # A_s
    floored: tuple[int, ...] = ()  # seeds whose scratch AUC was raised to the floor

    def to_dict(self) -> dict[str, Any]:
        return {
            "value": self.value,
            "interval": None if self.interval is None else list(self.interval),
            "per_seed": {str(k): v for k, v in self.per_seed.items()},
            "floored": list(self.floored),
        }


def advantage(ft_auc: Mapping[int, float], scratch_auc: Mapping[int, float], floor: float) -> Advantage:
    """A(src -> dst) from ``{seed: AUC}`` of the fine-tunes and of the scratch runs on dst (paired by seed)."""
    if not 0.0 < floor <= 1.0:
        raise ConfigError(f"AUC floor {floor!r} must be in (0, 1], e.g. 1/N for N evaluation scenes")
    seeds = sorted(set(ft_auc) & set(scratch_auc))
    per_seed, floored = {}, []
    for s in seeds:
        for what, v in (("fine-tune", ft_auc[s]), ("scratch", scratch_auc[s])):
            if not 0.0 <= v <= 1.0:
                raise ConfigError(f"{what} AUC {v!r} of seed {s} is out of range; an AUC of success is in [0, 1]")
        if scratch_auc[s] < floor:
            floored.append(s)
        per_seed[s] = ft_auc[s] / max(scratch_auc[s], floor)
    if not per_seed:
        return Advantage(None, None, {}, ())
    values = list(per_seed.values())
    mean = sum(values) / len(values)
    return Advantage(mean, _t_interval(values), per_seed, tuple(floored))


def t_interval(values: Sequence[float]) -> tuple[float, float] | None:
    """The 95% Student-t interval of the mean of ``values`` (None for fewer than two), from ``nsl.stats``."""
    got = stats_t_interval(values)
    return None if got is None else (got[0] - got[1], got[0] + got[1])


def _t_interval(values: Sequence[float]) -> tuple[float, float] | None:
    """:func:`t_interval` clipped at 0: an advantage is a ratio of areas."""
    ci = t_interval(values)
    return None if ci is None else (max(0.0, ci[0]), ci[1])
