"""The evaluation records a run folder holds, and how they are read and written.

``nsl report RUN`` reads these files; the commands that produce them write
them with the helpers here (always to a temporary file, then a rename)::

    curve.csv        one row per evaluation during training (early-stopping curve)
    early_stop.json  the early-stopping settings, its decision and reference lines
    matrix.json      the continual performance matrix R[stage, task]
    tiers.json       success per dataset tier (sample efficiency, Table 5.2)

Success values are fractions in [0, 1].  A success measurement is a
:class:`Rate`: a fraction with the number of episodes behind it (``None`` when
only the fraction is known, e.g. a number copied from a paper), from which
the 95% Wilson interval is computed.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, overload

from nsl.errors import ConfigError, CorruptDataError
from nsl.workspace import atomic_write_bytes, atomic_write_json

from .stats import SuccessRate, wilson_interval

CURVE_FILE = "curve.csv"
EARLY_STOP_FILE = "early_stop.json"
MATRIX_FILE = "matrix.json"
TIERS_FILE = "tiers.json"
REPORT_DIR = "report"

MATRIX_FORMAT = "nsl.continual-matrix"
TIERS_FORMAT = "nsl.tiers"
RECORD_VERSION = 1

CURVE_COLUMNS = (
    "step",
    "target_success",
    "target_ci_low",
    "target_ci_high",
    "target_episodes",
    "base_success",
    "base_ci_low",
    "base_ci_high",
    "base_episodes",
    "softopc",
    "auc",
    "td_error",
    "q_mean",
    "fqe",
)
OFFLINE_COLUMNS = ("softopc", "auc", "td_error", "q_mean", "fqe")


def _finite(x: Any) -> float | None:
    """``x`` as a float, or None for missing/NaN (how JSON and CSV store 'not measured')."""
    if x is None or x == "":
        return None
    v = float(x)
    return None if math.isnan(v) else v


@dataclass(frozen=True)
class Rate:
    """A success rate and the number of episodes it was measured on (None: unknown)."""

    success_rate: float
    episodes: int | None = None

    def __post_init__(self):
        object.__setattr__(self, "success_rate", float(self.success_rate))
        if self.episodes is not None:
            object.__setattr__(self, "episodes", int(self.episodes))
        if not (0.0 <= self.success_rate <= 1.0):
            raise ConfigError(f"success rate {self.success_rate!r} is out of range; use a fraction in [0, 1]")
        if self.episodes is not None and self.episodes < 1:
            raise ConfigError(f"episodes {self.episodes!r} must be at least 1 (or None if unknown)")

    @overload
    @classmethod
    def of(cls, value: Rate | SuccessRate | Mapping) -> Rate: ...
    @overload
    @classmethod
    def of(cls, value: Rate | SuccessRate | Mapping | float | None) -> Rate | None: ...
    @classmethod
    def of(cls, value: Rate | SuccessRate | Mapping | float | None) -> Rate | None:
        """Accept a Rate, a SuccessRate, a ``{"success_rate"|"successes", "episodes"}`` dict or a fraction."""
        if value is None or isinstance(value, Rate):
            return value
        if isinstance(value, SuccessRate):
            return cls(value.success_rate, value.episodes)
        if isinstance(value, Mapping):
            episodes = value.get("episodes")
            episodes = None if episodes is None else int(episodes)
            if value.get("success_rate") is not None:
                return cls(float(value["success_rate"]), episodes)
            if value.get("successes") is not None and episodes:
                return cls(int(value["successes"]) / episodes, episodes)
            raise ConfigError(f"a success record needs 'success_rate' or 'successes' and 'episodes'; got {dict(value)}")
        v = _finite(value)
        return None if v is None else cls(v)

    @property
    def ci(self) -> tuple[float, float] | None:
        if self.episodes is None:
            return None
        return wilson_interval(round(self.success_rate * self.episodes), self.episodes)

    def to_dict(self) -> dict:
        ci = self.ci
        return {
            "success_rate": self.success_rate,
            "episodes": self.episodes,
            "ci_low": None if ci is None else ci[0],
            "ci_high": None if ci is None else ci[1],
        }

    def percent(self, intervals: bool = True) -> str:
        """``63% [55-71]`` (or ``63%`` without a known episode count)."""
        ci = self.ci
        if not intervals or ci is None:
            return f"{100 * self.success_rate:.0f}%"
        return f"{100 * self.success_rate:.0f}% [{100 * ci[0]:.0f}-{100 * ci[1]:.0f}]"


# --- curve.csv ------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CurveRow:
    """One evaluation during training, at gradient step ``step``."""

    step: int
    target: Rate | None = None  # success on the target shift (simulator episodes)
    base: Rate | None = None  # success on the base task (forgetting)
    softopc: float | None = None  # offline criteria on held-out target data
    auc: float | None = None
    td_error: float | None = None
    q_mean: float | None = None  # the average Q-value of the held-out transitions
    fqe: float | None = None  # fitted Q evaluation's estimate of the success rate

    def value(self, column: str) -> float | None:
        if column == "target_success":
            return None if self.target is None else self.target.success_rate
        if column == "base_success":
            return None if self.base is None else self.base.success_rate
        return getattr(self, column)

    def to_dict(self) -> dict:
        """The flat record (curve.csv columns; also what the trainer logs to eval.jsonl)."""
        out: dict[str, Any] = {"step": self.step}
        for prefix, rate in (("target", self.target), ("base", self.base)):
            d = rate.to_dict() if rate is not None else {}
            out.update(
                {
                    f"{prefix}_success": d.get("success_rate"),
                    f"{prefix}_ci_low": d.get("ci_low"),
                    f"{prefix}_ci_high": d.get("ci_high"),
                    f"{prefix}_episodes": d.get("episodes"),
                }
            )
        out.update(softopc=self.softopc, auc=self.auc, td_error=self.td_error, q_mean=self.q_mean, fqe=self.fqe)
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> CurveRow:
        if d.get("step") in (None, ""):
            raise ConfigError(f"a curve record needs a 'step'; got keys {sorted(d)}")

        def rate(prefix: str) -> Rate | None:
            v = _finite(d.get(f"{prefix}_success"))
            if v is None:
                return None
            n = _finite(d.get(f"{prefix}_episodes"))
            return Rate(v, None if n is None else int(n))

        return cls(
            int(float(d["step"])),
            rate("target"),
            rate("base"),
            _finite(d.get("softopc")),
            _finite(d.get("auc")),
            _finite(d.get("td_error")),
            _finite(d.get("q_mean")),
            _finite(d.get("fqe")),
        )


def write_curve(path: Path, rows: Iterable[CurveRow]) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CURVE_COLUMNS)
    for row in sorted(rows, key=lambda r: r.step):
        d = row.to_dict()
        w.writerow(
            [
                "" if d[c] is None else repr(int(d[c]) if c.endswith(("step", "episodes")) else float(d[c]))
                for c in CURVE_COLUMNS
            ]
        )
    atomic_write_bytes(Path(path), buf.getvalue().encode())


def read_curve(path: Path) -> list[CurveRow]:
    """Rows of a curve.csv, sorted by step; unknown extra columns are ignored."""
    path = Path(path)
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if not reader.fieldnames or "step" not in reader.fieldnames:
            raise CorruptDataError(
                f"{path} has no 'step' column; a curve.csv starts with the header {','.join(CURVE_COLUMNS)}"
            )
        try:
            rows = [CurveRow.from_dict(r) for r in reader]
        except (ValueError, ConfigError) as e:
            raise CorruptDataError(f"{path}: {e}; rewrite it with nsl.eval.write_curve") from None
    return sorted(rows, key=lambda r: r.step)


def read_eval_jsonl(path: Path) -> list[CurveRow]:
    """Curve rows from a trainer's eval.jsonl (the lines that carry curve fields)."""
    rows = []
    for n, line in enumerate(Path(path).read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            d = json.loads(line)
        except json.JSONDecodeError:
            raise CorruptDataError(f"{path}:{n} is not JSON; the run was probably killed while writing") from None
        if any(_finite(d.get(c)) is not None for c in ("target_success", *OFFLINE_COLUMNS)):
            rows.append(CurveRow.from_dict(d))
    return sorted(rows, key=lambda r: r.step)


# --- matrix.json ----------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PerformanceMatrix:
    """``success[i][j]``: success on ``tasks[j]`` of the checkpoint after stage ``i``.

    Stage 0 is the initial checkpoint (the base policy, never trained in the
    sequence); stage ``i >= 1`` fine-tuned stage ``i - 1``'s checkpoint on task
    ``stages[i]``.  A run in progress has fewer rows; :meth:`with_stage` adds one.
    """

    tasks: tuple[str, ...]  # columns; usually 'base' plus the sequence's shifts
    stages: tuple[str, ...]  # row names: stages[0] names the initial checkpoint, stages[i] the task trained at i
    success: tuple[tuple[float | None, ...], ...]  # fractions; None = not evaluated
    episodes: tuple[tuple[int | None, ...], ...] | None = None  # episodes behind each cell (for intervals)
    base_task: str | None = "base"  # the task the initial checkpoint was trained on (forgetting from stage 0)
    single: Mapping[str, float] | None = None  # single-step fine-tuning from the initial checkpoint, per task
    reference: Mapping[str, float] | None = None  # from-scratch success per task (forward transfer baseline)
    curves: Mapping[str, Mapping[str, list]] | None = None  # task -> {"steps": [...], "success": [...]} in its stage
    reference_curves: Mapping[str, Mapping[str, list]] | None = None  # the same for the from-scratch baseline

    def __post_init__(self):
        object.__setattr__(self, "tasks", tuple(self.tasks))
        object.__setattr__(self, "stages", tuple(self.stages))
        object.__setattr__(self, "success", tuple(tuple(_finite(v) for v in row) for row in self.success))
        if self.episodes is not None:
            object.__setattr__(
                self, "episodes", tuple(tuple(None if v is None else int(v) for v in row) for row in self.episodes)
            )
        if len(set(self.tasks)) != len(self.tasks) or not self.tasks:
            raise ConfigError(f"matrix tasks {list(self.tasks)} must be non-empty and unique")
        trained = self.stages[1:]
        if len(set(trained)) != len(trained):
            raise ConfigError(f"matrix stages {list(trained)} repeat a task; each task is trained once")
        missing = [s for s in trained if s not in self.tasks]
        if missing:
            raise ConfigError(
                f"stages {missing} are not among the matrix tasks {list(self.tasks)}; add them as columns"
            )
        if self.base_task is not None and self.base_task not in self.tasks:
            raise ConfigError(
                f"base_task {self.base_task!r} is not a matrix task; use one of {list(self.tasks)} or None"
            )
        if self.base_task in trained:
            raise ConfigError(f"base_task {self.base_task!r} cannot also be trained at a later stage")
        if len(self.success) != len(self.stages):
            raise ConfigError(f"matrix has {len(self.success)} rows for {len(self.stages)} stages")
        for i, row in enumerate(self.success):
            if len(row) != len(self.tasks):
                raise ConfigError(f"matrix row {i} has {len(row)} values for {len(self.tasks)} tasks")
            bad = [v for v in row if v is not None and not 0.0 <= v <= 1.0]
            if bad:
                raise ConfigError(f"matrix row {i} has success values {bad} outside [0, 1]; store fractions")
        if self.episodes is not None and [len(r) for r in self.episodes] != [len(r) for r in self.success]:
            raise ConfigError("matrix episodes must have the same shape as success")

    def rate(self, i: int, j: int) -> Rate | None:
        v = self.success[i][j]
        if v is None:
            return None
        return Rate(v, None if self.episodes is None else self.episodes[i][j])

    def with_stage(self, stage: str, results: Mapping[str, Rate | SuccessRate | float]) -> PerformanceMatrix:
        """A copy with one more row: ``results`` maps every task to its success after ``stage``."""
        rates = {t: Rate.of(v) for t, v in results.items()}
        unknown = sorted(set(rates) - set(self.tasks))
        if unknown:
            raise ConfigError(f"results for unknown tasks {unknown}; the matrix tasks are {list(self.tasks)}")
        success = (*self.success, tuple(None if (r := rates.get(t)) is None else r.success_rate for t in self.tasks))
        old = self.episodes or tuple((None,) * len(self.tasks) for _ in self.success)
        counts = (*old, tuple(None if (r := rates.get(t)) is None else r.episodes for t in self.tasks))
        episodes = None if all(n is None for row in counts for n in row) else counts
        return PerformanceMatrix(
            self.tasks,
            (*self.stages, stage),
            success,
            episodes,
            self.base_task,
            self.single,
            self.reference,
            self.curves,
            self.reference_curves,
        )

    def to_dict(self) -> dict:
        return {
            "format": MATRIX_FORMAT,
            "version": RECORD_VERSION,
            "tasks": list(self.tasks),
            "stages": list(self.stages),
            "success": [list(r) for r in self.success],
            "episodes": None if self.episodes is None else [list(r) for r in self.episodes],
            "base_task": self.base_task,
            "single": None if self.single is None else dict(self.single),
            "reference": None if self.reference is None else dict(self.reference),
            "curves": self.curves,
            "reference_curves": self.reference_curves,
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> PerformanceMatrix:
        if d.get("format", MATRIX_FORMAT) != MATRIX_FORMAT:
            raise ConfigError(f"not a performance matrix (format {d.get('format')!r}, expected {MATRIX_FORMAT!r})")
        return cls(
            d["tasks"],
            d["stages"],
            d["success"],
            d.get("episodes"),
            d.get("base_task", "base"),
            d.get("single"),
            d.get("reference"),
            d.get("curves"),
            d.get("reference_curves"),
        )

    def save(self, path: Path) -> None:
        atomic_write_json(Path(path), self.to_dict())

    @classmethod
    def load(cls, path: Path) -> PerformanceMatrix:
        return _load(path, cls.from_dict, ("tasks", "stages", "success"))


def _load(path: Path, parse, required: tuple[str, ...]):
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise CorruptDataError(f"{path} is not valid JSON ({e.msg} at line {e.lineno})") from None
    missing = [k for k in required if k not in d]
    if missing:
        raise CorruptDataError(f"{path} lacks {missing}; see docs/eval.md for the record format")
    try:
        return parse(d)
    except KeyError as e:
        raise CorruptDataError(f"{path}: a record lacks the field {e}; see docs/eval.md for the format") from None
    except (ConfigError, TypeError, ValueError) as e:
        raise CorruptDataError(f"{path}: {e}") from None


# --- tiers.json -----------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TierRow:
    """One challenge (shift): the base policy, each dataset tier, and comparison methods."""

    base: Rate | None = None  # the initial policy on this shift (tier 0)
    tiers: Mapping[int, Rate] | None = None  # number of target attempts -> fine-tuned success
    comparisons: Mapping[str, Rate] | None = None  # e.g. {"scratch": ..., "imagenet": ...} (largest tier)

    def to_dict(self) -> dict:
        return {
            "base": None if self.base is None else self.base.to_dict(),
            "tiers": [{"attempts": k, **v.to_dict()} for k, v in sorted((self.tiers or {}).items())],
            "comparisons": [{"name": k, **v.to_dict()} for k, v in (self.comparisons or {}).items()],
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> TierRow:
        return cls(
            Rate.of(d.get("base")),
            {int(t["attempts"]): Rate.of(t) for t in d.get("tiers") or []},
            {c["name"]: Rate.of(c) for c in d.get("comparisons") or []},
        )


@dataclass(frozen=True)
class TierResults:
    """Sample efficiency: success by number of target attempts, one row per shift (Table 5.2, Fig. 5.6)."""

    rows: Mapping[str, TierRow]

    def __post_init__(self):
        if not self.rows:
            raise ConfigError("tier results need at least one shift row")

    @property
    def tiers(self) -> list[int]:
        return sorted({k for r in self.rows.values() for k in (r.tiers or {})})

    @property
    def comparison_names(self) -> list[str]:
        names: list[str] = []
        for r in self.rows.values():
            names += [k for k in (r.comparisons or {}) if k not in names]
        return names

    def to_dict(self) -> dict:
        return {
            "format": TIERS_FORMAT,
            "version": RECORD_VERSION,
            "rows": [{"shift": k, **v.to_dict()} for k, v in self.rows.items()],
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> TierResults:
        if d.get("format", TIERS_FORMAT) != TIERS_FORMAT:
            raise ConfigError(f"not a tiers record (format {d.get('format')!r}, expected {TIERS_FORMAT!r})")
        if not isinstance(d["rows"], list) or not all(isinstance(r, Mapping) for r in d["rows"]):
            raise ConfigError('tiers \'rows\' must be a list of {"shift", "base", "tiers", "comparisons"} objects')
        return cls({r["shift"]: TierRow.from_dict(r) for r in d["rows"]})

    def save(self, path: Path) -> None:
        atomic_write_json(Path(path), self.to_dict())

    @classmethod
    def load(cls, path: Path) -> TierResults:
        return _load(path, cls.from_dict, ("rows",))
