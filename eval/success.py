"""Running a policy in the simulator for success rates, and paired policy evaluation.

Evaluation episode ``i`` uses scene seed ``(seed, i)`` whatever the policy or
the shift, so two checkpoints evaluated with the same seed face identical
scenes (objects, poses, colours, start pose): their comparison is paired.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from nsl.collectors import EnvConfig, Episode, ShiftSpec, collect_episodes
from nsl.progress import progress_bar

from .config import EvalConfig  # noqa: F401  (re-exported)
from .stats import SuccessRate, markdown_table, success_rate_from_outcomes, wilson_interval  # noqa: F401


def evaluate(
    make_policy: Callable,
    shifts: Sequence[ShiftSpec],
    config: EvalConfig,
    env_overrides: dict | None = None,
    progress: bool = True,
    runner: Callable | None = None,
) -> dict[str, SuccessRate]:
    """Success rate of the policy built by ``make_policy`` on each shift (``runner``: see ``collect_episodes``)."""
    results: dict[str, SuccessRate] = {}
    for spec in shifts:
        episodes = run_eval_episodes(make_policy, spec, config, env_overrides, progress, runner)
        results[spec.name] = SuccessRate(spec.name, len(episodes), sum(e.success for e in episodes))
    return results


def run_eval_episodes(
    make_policy: Callable,
    shift: ShiftSpec,
    config: EvalConfig,
    env_overrides: dict | None = None,
    progress: bool = True,
    runner: Callable | None = None,
) -> list[Episode]:
    env_config = EnvConfig(shift=shift.name, split=config.split, image_size=config.image_size, **(env_overrides or {}))
    out = []
    bar = progress_bar(total=config.episodes, desc=f"eval {shift.name}", unit="ep", disable=not progress, leave=False)
    for ep in collect_episodes(
        env_config, make_policy, range(config.episodes), config.seed, config.workers, config.batch, runner=runner
    ):
        out.append(ep)
        bar.update(1)
        bar.set_postfix(success=f"{sum(e.success for e in out) / len(out):.2f}", refresh=False)
    bar.close()
    return out


def evaluate_outcomes(
    make_policy: Callable,
    shifts: Sequence[ShiftSpec],
    config: EvalConfig,
    env_overrides: dict | None = None,
    progress: bool = True,
    runner: Callable | None = None,
) -> dict[str, list[bool]]:
    """Per-episode success on each shift, in episode-index order (scene seed ``(seed, i)``).

    Two policies' outcomes from the same ``config.seed`` are paired: pass them
    to :func:`nsl.eval.compare_paired`.  :func:`success_rate_from_outcomes` gives the rate.
    """
    return {
        spec.name: [
            bool(e.success) for e in run_eval_episodes(make_policy, spec, config, env_overrides, progress, runner)
        ]
        for spec in shifts
    }
