"""Success rates with 95% Wilson intervals, and paired policy evaluation.

Evaluation episode ``i`` uses scene seed ``(seed, i)`` whatever the policy or
the shift, so two checkpoints evaluated with the same seed face identical
scenes (objects, poses, colours, start pose): their comparison is paired.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

from tqdm import tqdm

from nsl.collectors import EnvConfig, Episode, ShiftSpec, collect_episodes

Z95 = 1.959963984540054


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval for a binomial proportion (95% by default)."""
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


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
        return {"success_rate": self.success_rate, "ci_low": lo, "ci_high": hi, "episodes": self.episodes,
                "successes": self.successes}

    def __str__(self) -> str:
        lo, hi = self.ci
        return f"{100 * self.success_rate:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}] (n={self.episodes})"


@dataclass(frozen=True)
class EvalConfig:
    """How a policy is evaluated; saved with every evaluation."""

    episodes: int = 100  # episodes per shift
    split: str = "test"  # object split: held-out test objects by default
    seed: int = 1000  # scene seeds (seed, i); equal seeds give paired comparisons
    workers: int = 1  # processes
    batch: int = 8  # environments per worker stepping in lock-step (batched policy calls)
    image_size: int = 64

    def to_dict(self) -> dict:
        return asdict(self)


def evaluate(make_policy: Callable, shifts: Sequence[ShiftSpec], config: EvalConfig, env_overrides: dict | None = None,
             progress: bool = True, runner: Callable | None = None) -> dict[str, SuccessRate]:
    """Success rate of the policy built by ``make_policy`` on each shift (``runner``: see ``collect_episodes``)."""
    results: dict[str, SuccessRate] = {}
    for spec in shifts:
        episodes = run_eval_episodes(make_policy, spec, config, env_overrides, progress, runner)
        results[spec.name] = SuccessRate(spec.name, len(episodes), sum(e.success for e in episodes))
    return results


def run_eval_episodes(make_policy: Callable, shift: ShiftSpec, config: EvalConfig, env_overrides: dict | None = None,
                      progress: bool = True, runner: Callable | None = None) -> list[Episode]:
    env_config = EnvConfig(shift=shift.name, split=config.split, image_size=config.image_size, **(env_overrides or {}))
    out = []
    bar = tqdm(total=config.episodes, desc=f"eval {shift.name}", unit="ep", disable=not progress, leave=False)
    for ep in collect_episodes(env_config, make_policy, range(config.episodes), config.seed, config.workers,
                               config.batch, runner=runner):
        out.append(ep)
        bar.update(1)
        bar.set_postfix(success=f"{sum(e.success for e in out) / len(out):.2f}")
    bar.close()
    return out


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


def evaluate_outcomes(make_policy: Callable, shifts: Sequence[ShiftSpec], config: EvalConfig,
                      env_overrides: dict | None = None, progress: bool = True,
                      runner: Callable | None = None) -> dict[str, list[bool]]:
    """Per-episode success on each shift, in episode-index order (scene seed ``(seed, i)``).

    Two policies' outcomes from the same ``config.seed`` are paired: pass them
    to :func:`nsl.eval.compare_paired`.  :func:`success_rate_from_outcomes` gives the rate.
    """
    return {spec.name: [bool(e.success) for e in run_eval_episodes(make_policy, spec, config, env_overrides,
                                                                     progress, runner)]
            for spec in shifts}


def success_rate_from_outcomes(shift: str, outcomes: Sequence[bool]) -> SuccessRate:
    return SuccessRate(shift, len(outcomes), int(sum(bool(o) for o in outcomes)))
