"""``nsl efficiency``: sample efficiency: fine-tune on each dataset tier and evaluate (Table 5.2, Fig. 5.6).

For every target dataset (one row per shift) it evaluates the starting
checkpoint on the dataset's shift (the tier-0 "base" cell), then, for each
tier size K, fine-tunes the starting checkpoint on the first K target
episodes mixed 50/50 with the base data (the study's recipe) and evaluates
the result on the same scenes.  With ``--scratch`` it also trains from
scratch on the largest tier's mix (a comparison column).  The results go to
RUN/tiers.json after every cell, so an interrupted run resumes at the first
missing cell (training resumes inside it); ``nsl report RUN`` plots them.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass

from nsl.commands._options import add_parser, add_seed, add_workers


@dataclass(frozen=True)
class EfficiencyConfig:
    """One sample-efficiency run; saved as RUN/config.json."""

    data: tuple[str, ...]  # target datasets NAME[@vN], one row (shift) each
    sizes: tuple[int, ...]  # tier sizes in target episodes (attempts)
    init: str  # checkpoint every fine-tune starts from
    base_data: str  # base dataset mixed 50/50 into every fine-tune
    steps: int = 2000  # gradient steps per fine-tune (the fine-tuning recipe's, nsl.learners.FINE_TUNE_STEPS)
    eval_episodes: int = 100  # evaluation episodes per cell (scene seeds 1000, i: the same for every cell)
    workers: int = 1
    seed: int = 0
    scratch: bool = False  # also train from scratch on the largest tier (comparison column)


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(sub, "efficiency", help="fine-tune on each dataset tier and evaluate: success vs target attempts",
                   description=__doc__.split("\n\n", 1)[1].strip(),
                   epilog="example: nsl efficiency --data grasp-harsh --sizes 25,50,100,200,400,800 "
                          "--init ckpt:base --base-data grasp-base --name efficiency-harsh")
    p.add_argument("--data", action="append", required=True, metavar="REF",
                   help="target dataset NAME[@vN] whose first-K tiers are used; repeat for one row per shift")
    p.add_argument("--sizes", default="25,50,100,200,400,800",
                   help="comma-separated tier sizes (target episodes); sizes above a dataset's size are skipped")
    p.add_argument("--init", default="ckpt:base", help="checkpoint every fine-tune starts from")
    p.add_argument("--base-data", default="grasp-base", metavar="REF",
                   help="base dataset mixed 50/50 into each fine-tune")
    p.add_argument("--name", default="efficiency", help="run name (folder under $NSL_HOME/runs, checkpoint prefix)")
    p.add_argument("--steps", type=int, default=2000, help="gradient steps per fine-tune (the fine-tuning recipe's)")
    p.add_argument("--eval-episodes", type=int, default=100, help="evaluation episodes per cell")
    add_workers(p, help="simulator processes for evaluation")
    add_seed(p, help="training seed of every fine-tune")
    p.add_argument("--scratch", action="store_true",
                   help="also train from scratch on the largest tier's mix (a comparison column)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from nsl.errors import ConfigError

    try:
        sizes = tuple(int(s) for s in args.sizes.split(",") if s.strip())
    except ValueError:
        raise ConfigError(f"--sizes {args.sizes!r} must be comma-separated integers, e.g. 25,50,100") from None
    efficiency(data=args.data, sizes=sizes, init=args.init, base_data=args.base_data, name=args.name,
               steps=args.steps, eval_episodes=args.eval_episodes, workers=args.workers, seed=args.seed,
               scratch=args.scratch)
    print(f"plots and tables: nsl report {args.name}")
    return 0


def efficiency(*, data: list[str], sizes: tuple[int, ...], init: str = "ckpt:base", base_data: str = "grasp-base",
               name: str = "efficiency", steps: int = 2000, eval_episodes: int = 100, workers: int = 1,
               seed: int = 0, scratch: bool = False):
    """Run (or resume) a sample-efficiency sweep; returns the TierResults written to RUN/tiers.json."""
    from nsl import workspace
    from nsl.catalog import Catalog
    from nsl.commands.train import view_shift
    from nsl.datasets import api
    from nsl.errors import ConfigError
    from nsl.eval import TIERS_FILE, TierResults, TierRow
    from nsl.commands._refs import resolve_init

    # Validate everything before any work starts.
    if not sizes or any(k < 1 for k in sizes):
        raise ConfigError(f"--sizes {','.join(map(str, sizes))!r} must be positive episode counts")
    if steps < 1 or eval_episodes < 1:
        raise ConfigError("--steps and --eval-episodes must be at least 1")
    with Catalog() as cat:
        start = resolve_init(cat, init)
    api.open_view(base_data)
    targets = []  # (pinned ref NAME@vN, shift, tier sizes that fit)
    for ref in data:
        view = api.open_view(ref)
        if view.num_episodes != view.version.num_episodes:
            raise ConfigError(f"--data {ref!r} is a tier; give the whole dataset (NAME or NAME@vN); "
                              "--sizes sets the tiers")
        fits = tuple(sorted({k for k in sizes if k <= view.num_episodes}))
        if not fits:
            raise ConfigError(f"--data {ref!r} holds {view.num_episodes} episodes, fewer than every size in --sizes")
        targets.append((view.version.ref, view_shift(view), fits))
    shifts = [s for _, s, _ in targets]
    if len(set(shifts)) != len(shifts):
        raise ConfigError(f"--data gives two datasets of one shift ({shifts}); give one dataset per shift")

    cfg = EfficiencyConfig(tuple(r for r, _, _ in targets), tuple(sorted(set(sizes))), init, base_data, steps,
                           eval_episodes, workers, seed, scratch)
    run_dir = workspace.runs_dir() / name
    run_dir.mkdir(parents=True, exist_ok=True)
    cfg_path = run_dir / "config.json"
    if cfg_path.exists() and json.loads(cfg_path.read_text()) != json.loads(json.dumps(asdict(cfg))):
        raise ConfigError(f"run {name!r} exists with a different configuration ({cfg_path}); "
                          "use another --name or the same options to resume")
    workspace.atomic_write_json(cfg_path, asdict(cfg))

    path = run_dir / TIERS_FILE
    rows: dict[str, TierRow] = dict(TierResults.load(path).rows) if path.exists() else {}

    def save(shift: str, row: TierRow) -> None:
        rows[shift] = row
        TierResults(dict(rows)).save(path)

    policy = f"ckpt:{start.id}"
    for ref, shift, fits in targets:
        row = rows.get(shift, TierRow(None, {}, {}))
        if row.base is None:
            row = TierRow(_evaluate(policy, shift, cfg), row.tiers, row.comparisons)
            save(shift, row)
        for k in fits:
            if k in (row.tiers or {}):
                print(f"{shift} tier {k} done earlier; skipping")
                continue
            ckpt = _fine_tune(name, ref, shift, k, policy, cfg)
            row = TierRow(row.base, {**(row.tiers or {}), k: _evaluate(ckpt, shift, cfg)}, row.comparisons)
            save(shift, row)
            print(f"{shift} tier {k}: {row.tiers[k].percent()} (base {row.base.percent()})")
        if cfg.scratch and "scratch" not in (row.comparisons or {}):
            ckpt = _fine_tune(name, ref, shift, fits[-1], None, cfg)
            row = TierRow(row.base, row.tiers, {**(row.comparisons or {}), "scratch": _evaluate(ckpt, shift, cfg)})
            save(shift, row)
    return TierResults(dict(rows))


def _fine_tune(run: str, ref: str, shift: str, k: int, init: str | None, cfg: EfficiencyConfig) -> str:
    """Train on the first ``k`` episodes of ``ref`` mixed 50/50 with the base data; returns ``ckpt:ID``."""
    from nsl.commands.train import train

    name = f"{run}-{_slug(shift)}-{k}" if init else f"{run}-{_slug(shift)}-scratch-{k}"
    entry = train(data=[f"{cfg.base_data}=0.5", f"{ref}:{k}=0.5"], init=init, steps=cfg.steps, name=name,
                  seed=cfg.seed, target_shift=shift)
    return f"ckpt:{entry.id}"


def _evaluate(policy: str, shift: str, cfg: EfficiencyConfig):
    from nsl.commands.eval import evaluate
    from nsl.eval import Rate

    result = evaluate([policy], shift=shift, episodes=cfg.eval_episodes, workers=cfg.workers, source="efficiency")
    (rate,) = result["table"][policy].values()
    return Rate.of(rate)


def _slug(shift: str) -> str:
    return shift.replace("+", "-").replace("@", "-").replace("_", "-")
