"""Catalog entries as small frozen records, and the reference grammar.

References used throughout the CLI::

    ckpt:NAME               newest checkpoint registered under NAME (same as @latest)
    ckpt:NAME@STEP          the checkpoint of NAME saved at gradient step STEP
    ckpt:NAME@best          highest evaluated success rate on the shift NAME was trained for
    ckpt:NAME@best:SHIFT    ... on SHIFT instead (e.g. ckpt:harsh@best:base)
    ckpt:NAME@TAG           the checkpoint tagged TAG, which must be one of NAME's
    ckpt:TAG                a tag used as an alias (e.g. ckpt:base)
    ckpt:3fa9c2d41e7b       an id prefix (6 or more hex digits)
    data:NAME[@vN][:K]      dataset NAME, version N (default: the newest), its first K episodes (nsl.refs)

The ``ckpt:`` prefix is optional where only a checkpoint makes sense.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from nsl.errors import ConfigError
from nsl.refs import CKPT_PREFIX, DATA_PREFIX, NAME_RE, DataRef, check_name, parse_data_ref, parse_tier
from nsl.stats import wilson_interval

__all__ = [
    "CKPT_PREFIX",
    "DATA_PREFIX",
    "CheckpointEntry",
    "CheckpointRef",
    "DataRef",
    "DataUse",
    "DatasetEntry",
    "EvaluationEntry",
    "ResolvedData",
    "check_name",
    "dumps",
    "parse_checkpoint_ref",
    "parse_data_ref",
    "short_hash",
    "wilson_interval",
]

HEX_RE = re.compile(r"[0-9a-f]{6,64}")
RESERVED = ("best", "latest")  # selectors that cannot be tag names
SHORT_ID = 12  # hex digits shown for a checkpoint id


def short_hash(h: str | None) -> str:
    """The first 12 hex digits of a content hash, without an algorithm prefix such as ``sha256:``."""
    return (h or "?").rpartition(":")[2][:SHORT_ID]


@dataclass(frozen=True)
class DataUse:
    """One dataset a checkpoint was trained on, with its share of each batch."""

    dataset: str
    version: int
    weight: float = 1.0  # fraction of each batch drawn from this dataset (e.g. 0.5 for a 50/50 mix)
    tier: int | None = None  # the subset used: the first K episodes (e.g. 800 attempts), as in data:NAME@vN:K
    hash: str = ""  # the dataset's content hash, filled in from the catalog at registration

    def __post_init__(self) -> None:
        check_name("dataset", self.dataset)
        object.__setattr__(self, "tier", parse_tier(self.tier, f"tier of dataset {self.dataset!r}"))
        if not isinstance(self.version, int) or self.version < 1:
            raise ConfigError(f"dataset version {self.version!r} for {self.dataset!r} must be an integer >= 1")
        if not (isinstance(self.weight, (int, float)) and self.weight > 0):
            raise ConfigError(f"weight {self.weight!r} for dataset {self.dataset!r} must be a positive number")

    @property
    def ref(self) -> str:
        return f"{DATA_PREFIX}{self.label}"

    @property
    def label(self) -> str:
        """``NAME@vN[:K]``."""
        return f"{self.dataset}@v{self.version}" + (f":{self.tier}" if self.tier is not None else "")

    @staticmethod
    def mix(uses: Sequence[DataUse]) -> str:
        """``base@v1 x0.5, harsh@v1:800 x0.5`` (empty for no data)."""
        return ", ".join(f"{u.label} x{u.weight:g}" for u in uses)


@dataclass(frozen=True)
class DatasetEntry:
    name: str
    version: int
    hash: str  # content hash from the dataset's manifest
    shift: dict[str, Any]  # shift spec (ShiftSpec.to_dict()); shift["name"] is e.g. "harsh_lighting"
    episodes: int
    provenance: dict[str, Any]  # how it was collected: config, policy, seeds, code version
    path: str
    created: str
    files: dict[str, str] = field(default_factory=dict, repr=False)  # relative path -> sha256 at registration

    @property
    def ref(self) -> str:
        return f"{self.name}@v{self.version}"

    @property
    def shift_name(self) -> str:
        return str(self.shift.get("name", "base"))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class CheckpointEntry:
    id: str  # content hash of the weights and the config (see folders.checkpoint_id)
    name: str
    step: int
    parent: str | None  # id of the checkpoint training started from; None for training from scratch
    shift: str  # the shift it was trained for; the default for @best
    data: tuple[DataUse, ...]
    config: dict[str, Any]  # content of config.json
    code_version: str
    path: str
    created: str
    files: dict[str, str] = field(default_factory=dict, repr=False)  # file name -> sha256

    @property
    def ref(self) -> str:
        return f"{self.name}@{self.step}"

    @property
    def short_id(self) -> str:
        return self.id[:SHORT_ID]

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["data"] = [asdict(u) for u in self.data]
        return d


@dataclass(frozen=True)
class EvaluationEntry:
    id: int
    checkpoint: str
    shift: str  # shift spec name, e.g. "harsh_lighting" or "base"
    split: str  # object split: "train" or "test"
    episodes: int
    successes: int
    ci_low: float  # 95% interval of the success rate
    ci_high: float
    seed: int
    created: str
    precision: str = "fp32"  # the arithmetic the policy acted in
    extra: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def rate(self) -> float:
        return self.successes / self.episodes

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class CheckpointRef:
    name: str
    selector: str | None = None  # None (latest), "latest", "best", a step ("1500") or a tag
    shift: str | None = None  # only with "best": the shift to rank on

    def __str__(self) -> str:
        sel = f"@{self.selector}" if self.selector else ""
        return f"{CKPT_PREFIX}{self.name}{sel}" + (f":{self.shift}" if self.shift else "")


@dataclass(frozen=True)
class ResolvedData:
    """A ``data:`` reference resolved to its catalog row; the tier is for the datasets loader."""

    dataset: DatasetEntry
    tier: int | None = None

    def use(self, weight: float = 1.0) -> DataUse:
        """The :class:`DataUse` to record when training on this data with ``weight``."""
        return DataUse(self.dataset.name, self.dataset.version, weight, self.tier, self.dataset.hash)


def parse_checkpoint_ref(text: str) -> CheckpointRef:
    """Parse ``[ckpt:]NAME[@STEP|@best[:SHIFT]|@latest|@TAG]``."""
    body = text.strip()
    if body.startswith(DATA_PREFIX):
        raise ConfigError(f"{text!r} is a dataset reference; a checkpoint is wanted, e.g. ckpt:base@latest")
    body = body.removeprefix(CKPT_PREFIX)
    name, at, selector = body.partition("@")
    check_name("checkpoint", name)
    if not at:
        return CheckpointRef(name)
    shift = None
    if selector.startswith("best:"):
        selector, shift = "best", selector[len("best:") :]
        if not shift:
            raise ConfigError(f"reference {text!r} has an empty shift after @best:; write e.g. ckpt:{name}@best:base")
    if not (selector.isdigit() or selector in RESERVED or NAME_RE.fullmatch(selector)):
        raise ConfigError(
            f"reference {text!r} has an invalid selector {selector!r}; use @STEP, @best, @best:SHIFT, @latest or @TAG"
        )
    return CheckpointRef(name, selector, shift)


def dumps(obj: Any) -> str:
    """Canonical JSON for catalog columns."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))
