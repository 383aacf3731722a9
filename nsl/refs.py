"""Names and the dataset reference grammar, shared by the datasets folder, the catalog and the CLI.

A dataset reference is ``[data:]NAME[@vN][:K]``: dataset ``NAME``, version
``N`` (default: the newest) and tier ``K``, the nested subset made of the
first ``K`` episodes (default: all of them).  Names of datasets, checkpoints
and tags use letters, digits, ``.``, ``_`` and ``-`` and start with a letter
or a digit.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from nsl.errors import ConfigError

DATA_PREFIX = "data:"
CKPT_PREFIX = "ckpt:"
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")


def check_name(kind: str, name: str) -> str:
    """Validate a dataset, checkpoint or tag name; return it."""
    if not isinstance(name, str) or not NAME_RE.fullmatch(name):
        raise ConfigError(
            f"{kind} name {name!r} is not valid; use letters, digits, '.', '_' and '-' "
            "(no '@', ':' or spaces, at most 100 characters), starting with a letter or digit"
        )
    return name


@dataclass(frozen=True)
class DataRef:
    """A parsed dataset reference."""

    name: str
    version: int | None = None  # None: the newest version
    tier: int | None = None  # None: all episodes; K: the first K episodes

    def __str__(self) -> str:
        v = f"@v{self.version}" if self.version is not None else ""
        return f"{self.name}{v}" + (f":{self.tier}" if self.tier is not None else "")


def parse_tier(tier: int | str | None, what: str = "tier") -> int | None:
    """A tier as an episode count >= 1 (``"800"`` and ``800`` alike), or None for all episodes."""
    if tier is None or tier == "":
        return None
    if isinstance(tier, bool) or not (isinstance(tier, int) or (isinstance(tier, str) and tier.isdigit())):
        raise ConfigError(f"{what} {tier!r} is not a number of episodes; write e.g. grasp-base@v1:100")
    if int(tier) < 1:
        raise ConfigError(f"{what} {tier!r} must be at least 1 episode")
    return int(tier)


def parse_data_ref(text: str) -> DataRef:
    """Parse ``[data:]NAME[@vN][:K]``."""
    if not isinstance(text, str):
        raise ConfigError(f"dataset reference {text!r} is malformed; write NAME, NAME@v2 or NAME@v2:100")
    body = text.strip()
    if body.startswith(CKPT_PREFIX):
        raise ConfigError(f"{text!r} is a checkpoint reference; a dataset is wanted, e.g. data:grasp-base@v1")
    body, colon, tier = body.removeprefix(DATA_PREFIX).partition(":")
    name, at, version = body.partition("@")
    check_name("dataset", name)
    v = None
    if at:
        if not re.fullmatch(r"v[0-9]+", version) or int(version[1:]) < 1:
            raise ConfigError(
                f"dataset reference {text!r} is malformed: version {version!r}; write it as @vN, "
                f"e.g. {name}@v1 or {name}@v1:100"
            )
        v = int(version[1:])
    return DataRef(name, v, parse_tier(tier, f"dataset reference {text!r}: tier") if colon else None)
