"""Online fine-tuning in rounds (the study's Sec. 5.10.2): the policy keeps collecting in the target task.

Round ``i`` (1..rounds)::

    collect   the current policy (round i-1's checkpoint; round 1: --init) gathers --episodes grasps in --shift,
              with epsilon-greedy exploration, scene seed seed + i               -> dataset NAME-r<i>
    train     the current policy is fine-tuned on every round's data so far (each round's share of --ratio in
              proportion to its episodes) mixed with the base data (1 - ratio)   -> checkpoint NAME-r<i>
    evaluate  that checkpoint on --eval-episodes scenes of the shift              -> RUN/rounds.json

Round 1 starts from --init with --method (``ft``: all parameters; ``new_head``: a fresh head on the parent's
trunk, Fig. 5.10's second curve); later rounds continue their predecessor with ``ft``.  Round 0 in
``rounds.json`` is --init itself at 0 grasps.  Every dataset and checkpoint is catalogued; a killed run resumes
where it stopped (collection and training inside a round too) and ends with the same numbers.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import collect as collect_service
from . import evaluate as evaluate_service
from . import train as train_service
from .options import CollectConfig, EvaluateOptions, OnlineConfig, TrainOptions

__all__ = ["OnlineConfig", "OnlineResult", "online"]

ROUNDS_FILE = "rounds.json"


@dataclass(frozen=True)
class OnlineResult:
    """A finished online run: its folder and one row per round (round 0 is the starting policy)."""

    run_dir: Path
    rounds: list[dict[str, Any]]

    def markdown(self) -> str:
        lines = ["| round | grasps collected | checkpoint | success | 95% CI |", "|---|---|---|---|---|"]
        for r in self.rounds:
            ci = f"{100 * r['ci_low']:.1f}-{100 * r['ci_high']:.1f}"
            lines.append(f"| {r['round']} | {r['grasps']} | {r['checkpoint']} | {100 * r['success']:.1f}% | {ci} |")
        return "\n".join(lines)


def round_mix(base: list[tuple[str, float]], rounds: list[tuple[str, int]], ratio: float) -> list[str]:
    """``--data`` specs of one round's training: the rounds' datasets share ``ratio`` in proportion to their
    episodes, the base datasets ``1 - ratio`` in proportion to their weights."""
    total = sum(n for _, n in rounds)
    base_total = sum(w for _, w in base)
    out = [f"{ref}={(1 - ratio) * w / base_total!r}" for ref, w in base] if ratio < 1 else []
    return out + [f"{ref}:{n}={ratio * n / total!r}" for ref, n in rounds]


def check(config: OnlineConfig) -> None:
    """Refuse a bad configuration in one line, before any work."""
    from nsl.collectors import parse_shift
    from nsl.errors import ConfigError

    spec = parse_shift(config.shift, engine=config.engine)
    if not spec.shifts and spec.engine == "mujoco":
        raise ConfigError(f"--shift {config.shift!r} is the base task; name the target shift, e.g. harsh_lighting@2")
    for name in ("rounds", "episodes", "steps", "eval_episodes"):
        if getattr(config, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')} {getattr(config, name)} must be at least 1")
    if not 0 < config.ratio <= 1:
        raise ConfigError(f"--ratio {config.ratio} is the target data's share of each batch; use (0, 1], e.g. 0.5")
    if config.method not in ("ft", "new_head"):
        raise ConfigError(f"--method {config.method!r}: online rounds start with ft (all parameters) or new_head")
    if not config.base_data and config.ratio < 1:
        raise ConfigError("--base-data is empty; give the base dataset(s) mixed into every round, or --ratio 1")


def online(config: OnlineConfig, name: str = "online", *, progress: bool = True, wait: bool = False) -> OnlineResult:
    """Run (or resume) ``config.rounds`` rounds of collection and fine-tuning as run ``name``.

    Holds run ``name``'s writer lock: while another process runs it this raises LockedError naming it, or with
    ``wait`` waits for it."""
    from nsl.locks import run_lock

    with run_lock(name, wait=wait):
        return _online(config, name, progress)


def _online(config: OnlineConfig, name: str, progress: bool) -> OnlineResult:
    from nsl import workspace
    from nsl.catalog import Catalog
    from nsl.datasets import api

    from .refs import open_run, resolve_init

    check(config)
    base = train_service.parse_data(list(config.base_data)) if config.ratio < 1 else []
    for ref, _ in base:
        api.open_view(ref)
    with Catalog() as cat:
        init = resolve_init(cat, config.init)
    run_dir = open_run(name, config)
    path = run_dir / ROUNDS_FILE
    rows: list[dict[str, Any]] = json.loads(path.read_text()) if path.exists() else []
    policy, collected = f"ckpt:{init.id}", []
    envs: dict[str, Any] = {} if config.num_envs is None else {"num_envs": config.num_envs}  # None: the defaults

    for i in range(config.rounds + 1):
        if i > 0:
            data = f"{name}-r{i}"
            collect_service.collect(
                CollectConfig(
                    shift=config.target,
                    episodes=config.episodes,
                    policy=policy,
                    data=data,
                    workers=config.workers,
                    seed=config.seed + i,
                    epsilon=config.epsilon,
                    **envs,
                ),
                progress=progress,
            )
            collected.append((data, config.episodes))
            result = train_service.train(
                TrainOptions(
                    data=tuple(round_mix(base, collected, config.ratio)),
                    name=data,
                    init=policy,
                    method=config.method if i == 1 else "ft",
                    steps=config.steps,
                    seed=config.seed,
                    learner=config.learner,
                    target_shift=config.target,
                    precision=config.precision,
                    device=config.device,
                ),
                progress=progress,
            )
            policy = f"ckpt:{result.id}"
        if i < len(rows):
            continue  # evaluated before the run was stopped
        rate = evaluate_service.evaluate(
            [policy],
            EvaluateOptions(
                shift=config.target,
                episodes=config.eval_episodes,
                seed=config.eval_scenes,
                workers=config.workers,
                **envs,
            ),
            progress=progress,
            source="online",
        ).table[policy][config.target]
        low, high = rate.ci
        rows.append(
            {
                "round": i,
                "grasps": i * config.episodes,
                "checkpoint": policy,
                "success": rate.success_rate,
                "ci_low": low,
                "ci_high": high,
                "episodes": rate.episodes,
            }
        )
        workspace.atomic_write_json(path, rows)
        if progress:
            print(f"round {i}: {i * config.episodes} grasps, success on {config.target} {rate}")
    return OnlineResult(run_dir, rows)
