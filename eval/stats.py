"""Success rates and their 95% Wilson intervals; this module imports no simulator.

``nsl.eval`` loads its modules on first use, so ``from nsl.eval import
wilson_interval`` (or ``SuccessRate``) needs neither MuJoCo nor PyTorch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from nsl.stats import Z95, wilson_interval

__all__ = ["Z95", "SuccessRate", "markdown_table", "success_rate_from_outcomes", "wilson_interval"]


@dataclass(frozen=True)
class SuccessRate:
    shift: str
    episodes: int
    successes: int

    @property
    def success_rate(self) -> float:
        return self.successes / self.episodes if self.episodes else 0.0

    @property
    def ci(self) -> tuple[float, float]:
        return wilson_interval(self.successes, self.episodes)

    def to_dict(self) -> dict:
        lo, hi = self.ci
        return {
            "success_rate": self.success_rate,
            "ci_low": lo,
            "ci_high": hi,
            "episodes": self.episodes,
            "successes": self.successes,
        }

    def __str__(self) -> str:
        lo, hi = self.ci
        return f"{100 * self.success_rate:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}] (n={self.episodes})"


def markdown_table(rows: dict[str, dict[str, SuccessRate]]) -> str:
    """A table with one row per policy and one column per shift."""
    shifts = list(next(iter(rows.values())).keys()) if rows else []
    lines = ["| policy | " + " | ".join(shifts) + " |", "|---|" + "---|" * len(shifts)]
    for name, res in rows.items():
        cells = []
        for s in shifts:
            r = res[s]
            lo, hi = r.ci
            cells.append(f"{100 * r.success_rate:.0f}% [{100 * lo:.0f}-{100 * hi:.0f}]")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def success_rate_from_outcomes(shift: str, outcomes: Sequence[bool]) -> SuccessRate:
    return SuccessRate(shift, len(outcomes), int(sum(bool(o) for o in outcomes)))
