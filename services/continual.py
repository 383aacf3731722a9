"""Fine-tune through a sequence of shifts and measure forgetting and transfer (Table 5.3's protocol).

Each stage collects with the current policy in the stage's shift, then
fine-tunes the previous stage's checkpoint on that data mixed 50/50 with the
base data.  After every stage its checkpoint is evaluated on every task, base
included, and the performance matrix is saved; an interrupted run resumes at
the first unfinished stage (collection and training resume inside a stage).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from . import collect as collect_service
from . import evaluate as evaluate_service
from . import train as train_service
from .options import CollectConfig, ContinualConfig, EvaluateOptions

__all__ = ["ContinualConfig", "ContinualResult", "continual"]


@dataclass(frozen=True)
class ContinualResult:
    """A finished continual run: its folder, performance matrix and metrics, and each stage's checkpoint id."""

    run_dir: Path
    matrix: Any  # nsl.eval.PerformanceMatrix
    metrics: Any  # nsl.eval.ContinualMetrics
    checkpoints: dict[str, str]  # {stage shift: catalog id}


def continual(
    config: ContinualConfig, name: str = "continual", *, progress: bool = True, wait: bool = False
) -> ContinualResult:
    """Run (or resume) the sequence ``config.sequence`` as run ``name``.

    Holds run ``name``'s writer lock: while another process runs it this raises LockedError naming it, or with
    ``wait`` waits for it."""
    from nsl.locks import run_lock

    with run_lock(name, wait=wait):
        return _continual(config, name, progress)


def _continual(config: ContinualConfig, name: str, progress: bool) -> ContinualResult:
    from nsl import workspace
    from nsl.catalog import Catalog
    from nsl.collectors import parse_shift
    from nsl.datasets import api
    from nsl.errors import ConfigError
    from nsl.eval import PerformanceMatrix, continual_metrics

    from .refs import open_run, resolve_init

    # Validate everything before any work starts.
    specs = [parse_shift(n) for n in config.sequence]
    if not specs:
        raise ConfigError("--sequence is empty; name the shifts to train through, e.g. harsh_lighting,checkerboard")
    if len({s.name for s in specs}) != len(specs):
        raise ConfigError(f"--sequence {','.join(config.sequence)!r} repeats a task; each shift may appear once")
    if any(not s.shifts for s in specs):
        raise ConfigError("--sequence holds 'base'; the base task is evaluated at every stage already")
    if config.episodes < 1 or config.steps < 1 or config.eval_episodes < 1:
        raise ConfigError("--episodes, --steps and --eval-episodes must be at least 1")
    with Catalog() as cat:
        init = resolve_init(cat, config.init)
    api.open_view(config.base_data)
    cfg = replace(config, sequence=tuple(s.name for s in specs))
    run_dir = open_run(name, cfg)

    tasks = ("base", *cfg.sequence)
    matrix_path = run_dir / "matrix.json"
    matrix = (
        PerformanceMatrix.load(matrix_path)
        if matrix_path.exists()
        else PerformanceMatrix(tasks=tasks, stages=(), success=())
    )
    policy = f"ckpt:{init.id}"
    checkpoints = {}
    for i, stage in enumerate(("init", *cfg.sequence)):
        if i > 0:
            checkpoints[stage] = _stage(name, i, stage, policy, cfg, progress)
            policy = f"ckpt:{checkpoints[stage]}"
        if i < len(matrix.stages):
            print(f"stage {i} ({stage}) done earlier; skipping")
            continue
        results = _evaluate(policy, tasks, cfg, progress)
        matrix = matrix.with_stage(stage, results)
        matrix.save(matrix_path)
        print(f"stage {i} ({stage}): " + ", ".join(f"{t} {r}" for t, r in results.items()))
    if cfg.single and matrix.single is None:
        matrix = _single_step(name, matrix, cfg, init, progress)
        matrix.save(matrix_path)
    metrics = continual_metrics(matrix)
    workspace.atomic_write_json(run_dir / "metrics.json", metrics.to_dict())
    return ContinualResult(run_dir, matrix, metrics, checkpoints)


def _fine_tune(data: str, init: str, name: str, shift: str, cfg: ContinualConfig, progress: bool) -> str:
    """Fine-tune ``init`` on ``data`` mixed 50/50 with the base data; returns the checkpoint id."""
    result = train_service.fine_tune_half_half(
        cfg.base_data, data, init, name, steps=cfg.steps, seed=cfg.seed, shift=shift, progress=progress
    )
    assert result.id is not None  # registered (the default)
    return result.id


def _stage(run: str, i: int, shift: str, policy: str, cfg: ContinualConfig, progress: bool) -> str:
    """Collect in ``shift`` with ``policy``, fine-tune it 50/50 with base data; return the checkpoint id."""
    data, name = f"{run}-{slug(shift)}", f"{run}-s{i}-{slug(shift)}"
    collect_service.collect(
        CollectConfig(
            shift=shift,
            episodes=cfg.episodes,
            policy=policy,
            data=data,
            workers=cfg.workers,
            num_envs=8,
            seed=cfg.seed + i,
            epsilon=cfg.epsilon,
        ),
        progress=progress,
    )
    return _fine_tune(data, policy, name, shift, cfg, progress)


def _single_step(run: str, matrix, cfg: ContinualConfig, init, progress: bool):
    """Fine-tune ``init`` on each stage's data in one step (Table 5.3's single-step column)."""
    single = {}
    for k, shift in enumerate(cfg.sequence):
        if k == 0:  # the first stage already is a single step from init (same data, seed and parent)
            single[shift] = matrix.rate(1, matrix.tasks.index(shift))
            continue
        ckpt = _fine_tune(
            f"{run}-{slug(shift)}", f"ckpt:{init.id}", f"{run}-single-{slug(shift)}", shift, cfg, progress
        )
        single[shift] = _evaluate(f"ckpt:{ckpt}", (shift,), cfg, progress)[shift]
    return type(matrix)(**{**matrix.__dict__, "single": {k: v.success_rate for k, v in single.items()}})


def _evaluate(policy: str, tasks, cfg: ContinualConfig, progress: bool) -> dict:
    """Success of ``policy`` on each task (``nsl eval``'s defaults otherwise), catalogued as "continual"."""
    result = evaluate_service.evaluate(
        [policy],
        EvaluateOptions(shift=",".join(tasks), episodes=cfg.eval_episodes, workers=cfg.workers),
        progress=progress,
        source="continual",
    )
    return result.table[policy]


def slug(shift: str) -> str:
    """A shift spec as a name part: ``harsh_lighting@2`` -> ``harsh-lighting-2``."""
    return shift.replace("+", "-").replace("@", "-").replace("_", "-")
