"""``nsl continual``: fine-tune through a sequence of shifts and measure forgetting and transfer.

Each stage calls the functions behind the subcommands: ``collect`` with the
current policy in the stage's shift, then ``train`` fine-tuning the previous stage's
checkpoint on that data mixed 50/50 with the base data (the study's Table 5.3
protocol).  After every stage its checkpoint is evaluated on every task, base
included, and the performance matrix is saved; an interrupted run resumes at
the first unfinished stage (collection and training resume inside a stage).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass

from nsl.commands._options import add_parser, add_seed, add_workers


@dataclass(frozen=True)
class ContinualConfig:
    """One continual run; saved as RUN/config.json."""

    sequence: tuple[str, ...]  # shift specs, in training order
    init: str  # checkpoint the sequence starts from
    base_data: str  # base dataset mixed 50/50 into every stage
    episodes: int = 800  # target attempts collected per stage
    steps: int = 2000  # gradient steps per stage (the fine-tuning recipe's, nsl.learners.FINE_TUNE_STEPS)
    eval_episodes: int = 100  # evaluation episodes per task and stage
    epsilon: float = 0.1  # exploration during collection
    workers: int = 1
    seed: int = 0
    single: bool = False  # also fine-tune each shift in one step from init (the comparison column)


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub, "continual", help="fine-tune through a sequence of shifts; performance matrix, forgetting, transfer",
        description=__doc__.split("\n\n", 1)[1].strip())
    p.add_argument("--sequence", required=True,
                   help="comma-separated shifts, e.g. harsh_lighting,transparent_objects,checkerboard_backing,"
                        "extend_gripper,offset_gripper")
    p.add_argument("--init", default="ckpt:base", help="starting checkpoint")
    p.add_argument("--base-data", default="grasp-base", metavar="REF",
                   help="base dataset mixed 50/50 into every stage")
    p.add_argument("--name", default="continual", help="run name (folder under $NSL_HOME/runs, dataset prefix)")
    p.add_argument("--episodes", type=int, default=800, help="attempts collected per stage")
    p.add_argument("--steps", type=int, default=2000, help="gradient steps per stage (the fine-tuning recipe's)")
    p.add_argument("--eval-episodes", type=int, default=100, help="evaluation episodes per task and stage")
    p.add_argument("--epsilon", type=float, default=0.1, help="exploration during collection")
    add_workers(p, help="simulator processes for collection and evaluation")
    add_seed(p, help="seed of stage i's collection is seed + i; training uses seed")
    p.add_argument("--single", action="store_true", help="also fine-tune each shift in one step from --init")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from nsl import workspace
    from nsl.catalog import Catalog
    from nsl.collectors import parse_shift
    from nsl.datasets import api
    from nsl.errors import ConfigError
    from nsl.eval import PerformanceMatrix, continual_metrics
    from nsl.commands._refs import resolve_init

    # Validate everything before any work starts.
    names = [s.strip() for s in args.sequence.split(",") if s.strip()]
    specs = [parse_shift(n) for n in names]
    if len({s.name for s in specs}) != len(specs):
        raise ConfigError(f"--sequence {args.sequence!r} repeats a task; each shift may appear once")
    if any(not s.shifts for s in specs):
        raise ConfigError("--sequence holds 'base'; the base task is evaluated at every stage already")
    if args.episodes < 1 or args.steps < 1 or args.eval_episodes < 1:
        raise ConfigError("--episodes, --steps and --eval-episodes must be at least 1")
    with Catalog() as cat:
        init = resolve_init(cat, args.init)
    api.open_view(args.base_data)
    cfg = ContinualConfig(tuple(s.name for s in specs), args.init, args.base_data, args.episodes, args.steps,
                          args.eval_episodes, args.epsilon, args.workers, args.seed, args.single)
    run_dir = workspace.runs_dir() / args.name
    run_dir.mkdir(parents=True, exist_ok=True)
    cfg_path = run_dir / "config.json"
    if cfg_path.exists() and json.loads(cfg_path.read_text()) != json.loads(json.dumps(asdict(cfg))):
        raise ConfigError(f"run {args.name!r} exists with a different configuration ({cfg_path}); "
                          "use another --name or the same options to resume")
    workspace.atomic_write_json(cfg_path, asdict(cfg))

    tasks = ("base", *cfg.sequence)
    matrix_path = run_dir / "matrix.json"
    matrix = PerformanceMatrix.load(matrix_path) if matrix_path.exists() else \
        PerformanceMatrix(tasks=tasks, stages=(), success=())
    policy = f"ckpt:{init.id}"
    stage_names = ("init", *cfg.sequence)
    for i, stage in enumerate(stage_names):
        if i > 0:
            ckpt = _stage(args.name, i, stage, policy, cfg)
            policy = f"ckpt:{ckpt}"
        if i < len(matrix.stages):
            print(f"stage {i} ({stage}) done earlier; skipping")
            continue
        results = _evaluate(policy, tasks, cfg)
        matrix = matrix.with_stage(stage, results)
        matrix.save(matrix_path)
        print(f"stage {i} ({stage}): " + ", ".join(f"{t} {r}" for t, r in results.items()))
    if cfg.single and matrix.single is None:
        matrix = _single_step(args.name, matrix, cfg, init)
        matrix.save(matrix_path)
    metrics = continual_metrics(matrix)
    workspace.atomic_write_json(run_dir / "metrics.json", metrics.to_dict())
    print(metrics.markdown())
    print(f"plots and tables: nsl report {run_dir}")
    return 0


def _stage(run: str, i: int, shift: str, policy: str, cfg: ContinualConfig) -> str:
    """Collect in ``shift`` with ``policy``, fine-tune it 50/50 with base data; return the checkpoint id."""
    from nsl.commands.collect import collect
    from nsl.commands.train import train

    data, name = f"{run}-{_slug(shift)}", f"{run}-s{i}-{_slug(shift)}"
    collect(shift=shift, episodes=cfg.episodes, policy=policy, data=data, workers=cfg.workers, batch_size=8,
            seed=cfg.seed + i, epsilon=cfg.epsilon)
    return train(data=[f"{cfg.base_data}=0.5", f"{data}=0.5"], init=policy, steps=cfg.steps, name=name,
                 seed=cfg.seed, target_shift=shift).id


def _single_step(run: str, matrix, cfg: ContinualConfig, init) -> object:
    """Fine-tune ``init`` on each stage's data in one step (Table 5.3's single-step column)."""
    from nsl.commands.train import train

    single = {}
    for k, shift in enumerate(cfg.sequence):
        if k == 0:  # the first stage already is a single step from init (same data, seed and parent)
            single[shift] = matrix.rate(1, matrix.tasks.index(shift))
            continue
        data, name = f"{run}-{_slug(shift)}", f"{run}-single-{_slug(shift)}"
        ckpt = train(data=[f"{cfg.base_data}=0.5", f"{data}=0.5"], init=f"ckpt:{init.id}", steps=cfg.steps,
                     name=name, seed=cfg.seed, target_shift=shift).id
        single[shift] = _evaluate(f"ckpt:{ckpt}", (shift,), cfg)[shift]
    return type(matrix)(**{**matrix.__dict__, "single": {k: v.success_rate for k, v in single.items()}})


def _evaluate(policy: str, tasks, cfg: ContinualConfig) -> dict:
    """Success of ``policy`` on each task (the eval command's defaults otherwise), catalogued as "continual"."""
    from nsl.commands.eval import evaluate

    result = evaluate([policy], shift=",".join(tasks), episodes=cfg.eval_episodes, workers=cfg.workers,
                      source="continual")
    return result["table"][policy]


def _slug(shift: str) -> str:
    return shift.replace("+", "-").replace("@", "-").replace("_", "-")
