"""Sample efficiency: fine-tune on each dataset tier and evaluate (Table 5.2, Fig. 5.6).

For every target dataset (one row per shift) it evaluates the starting
checkpoint on the dataset's shift (the tier-0 "base" cell), then, for each
tier size K, fine-tunes the starting checkpoint on the first K target
episodes mixed 50/50 with the base data (the study's recipe) and evaluates
the result on the same scenes.  With ``scratch`` it also trains from scratch
on the largest tier's mix (a comparison column).  The results go to
RUN/tiers.json after every cell, so an interrupted run resumes at the first
missing cell (training resumes inside it); ``nsl report RUN`` plots them.
"""

from __future__ import annotations

from dataclasses import asdict

from . import evaluate as evaluate_service
from . import train as train_service
from .continual import slug
from .options import EfficiencyConfig, EvaluateOptions

__all__ = ["EfficiencyConfig", "efficiency"]


def efficiency(config: EfficiencyConfig, name: str = "efficiency", *, progress: bool = True, wait: bool = False):
    """Run (or resume) a sample-efficiency sweep as run ``name``; returns the TierResults written to RUN/tiers.json.

    ``config.data`` names whole target datasets; they are pinned to their versions (``NAME@vN``) in the saved
    config.  Holds run ``name``'s writer lock: while another process runs it this raises LockedError naming it,
    or with ``wait`` waits for it.
    """
    from nsl.locks import run_lock

    with run_lock(name, wait=wait):
        return _efficiency(config, name, progress)


def _efficiency(config: EfficiencyConfig, name: str, progress: bool):
    from nsl.catalog import Catalog
    from nsl.datasets import api
    from nsl.errors import ConfigError
    from nsl.eval import TIERS_FILE, TierResults, TierRow

    from .refs import open_run, resolve_init

    data, sizes, init, base_data, steps, eval_episodes = (
        config.data,
        config.sizes,
        config.init,
        config.base_data,
        config.steps,
        config.eval_episodes,
    )

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
            raise ConfigError(
                f"--data {ref!r} is a tier; give the whole dataset (NAME or NAME@vN); --sizes sets the tiers"
            )
        fits = tuple(sorted({k for k in sizes if k <= view.num_episodes}))
        if not fits:
            raise ConfigError(f"--data {ref!r} holds {view.num_episodes} episodes, fewer than every size in --sizes")
        targets.append((view.version.ref, train_service.view_shift(view), fits))
    shifts = [s for _, s, _ in targets]
    if len(set(shifts)) != len(shifts):
        raise ConfigError(f"--data gives two datasets of one shift ({shifts}); give one dataset per shift")

    cfg = EfficiencyConfig(
        **{**asdict(config), "data": tuple(r for r, _, _ in targets), "sizes": tuple(sorted(set(sizes)))}
    )
    run_dir = open_run(name, cfg)

    path = run_dir / TIERS_FILE
    rows: dict[str, TierRow] = dict(TierResults.load(path).rows) if path.exists() else {}

    def save(shift: str, row: TierRow) -> None:
        rows[shift] = row
        TierResults(dict(rows)).save(path)

    policy = f"ckpt:{start.id}"
    for ref, shift, fits in targets:
        row = rows.get(shift, TierRow(None, {}, {}))
        if row.base is None:
            row = TierRow(_evaluate(policy, shift, cfg, progress), row.tiers, row.comparisons)
            save(shift, row)
        for k in fits:
            if k in (row.tiers or {}):
                print(f"{shift} tier {k} done earlier; skipping")
                continue
            ckpt = _fine_tune(name, ref, shift, k, policy, cfg, progress)
            row = TierRow(row.base, {**(row.tiers or {}), k: _evaluate(ckpt, shift, cfg, progress)}, row.comparisons)
            save(shift, row)
            assert row.base is not None and row.tiers is not None  # both set above
            print(f"{shift} tier {k}: {row.tiers[k].percent()} (base {row.base.percent()})")
        if cfg.scratch and "scratch" not in (row.comparisons or {}):
            ckpt = _fine_tune(name, ref, shift, fits[-1], None, cfg, progress)
            row = TierRow(
                row.base, row.tiers, {**(row.comparisons or {}), "scratch": _evaluate(ckpt, shift, cfg, progress)}
            )
            save(shift, row)
    return TierResults(dict(rows))


def _fine_tune(run: str, ref: str, shift: str, k: int, init: str | None, cfg: EfficiencyConfig, progress: bool) -> str:
    """Train on the first ``k`` episodes of ``ref`` mixed 50/50 with the base data; returns ``ckpt:ID``."""
    name = f"{run}-{slug(shift)}-{k}" if init else f"{run}-{slug(shift)}-scratch-{k}"
    result = train_service.fine_tune_half_half(
        cfg.base_data, f"{ref}:{k}", init, name, steps=cfg.steps, seed=cfg.seed, shift=shift, progress=progress
    )
    return f"ckpt:{result.id}"


def _evaluate(policy: str, shift: str, cfg: EfficiencyConfig, progress: bool):
    from nsl.eval import Rate

    result = evaluate_service.evaluate(
        [policy],
        EvaluateOptions(shift=shift, episodes=cfg.eval_episodes, workers=cfg.workers),
        progress=progress,
        source="efficiency",
    )
    (rate,) = result.table[policy].values()
    return Rate.of(rate)
