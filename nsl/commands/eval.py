"""``nsl eval``: success rates per shift with 95% Wilson intervals, stored in the catalog."""

from __future__ import annotations

import argparse
import json

from nsl.commands._options import add_env_batch_size, add_json, add_parser, add_seed, add_workers


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub, "eval", help="success rate of checkpoints or scripted policies per shift, with 95%% intervals",
        description="Evaluate on test objects. Episode i uses scene seed (--seed, i) on every shift and for every "
                    "policy, so policies evaluated with the same seed see identical scenes; with two policies a "
                    "paired comparison (McNemar's exact test) is printed too. Checkpoint results are stored in the "
                    "catalog (they drive ckpt:NAME@best).")
    who = p.add_mutually_exclusive_group()
    who.add_argument("--checkpoint", default=None, metavar="REF[,REF]",
                     help="comma-separated checkpoint refs, e.g. ckpt:base,ckpt:harsh@best")
    who.add_argument("--policy", default=None, metavar="REF[,REF]",
                     help="comma-separated policies: random | oracle[:NOISE] | ckpt:NAME (default: oracle)")
    p.add_argument("--shift", default="base", help="comma-separated shift specs, or 'all' (base and the five at "
                   "severity 1), or 'study' (base and the five at the severities calibrated to ckpt:base)")
    p.add_argument("--severity", type=float, default=None, help="severity for shifts given without @X")
    p.add_argument("--episodes", type=int, default=100, help="episodes per shift")
    add_workers(p)
    add_env_batch_size(p, default=8)
    p.add_argument("--split", default="test", choices=["train", "test"], help="object split")
    add_seed(p, default=1000, help="scene seed: episode i is scene (seed, i), the same for every policy")
    out = p.add_mutually_exclusive_group()
    add_json(out, 'the results ({"results": {SHIFT: {...}}}, or per policy under "policies")')
    out.add_argument("--markdown", action="store_true", help="print a Markdown table")
    from nsl.cluster import add_option

    add_option(p)  # --cluster local|ray|auto|ray://HOST:PORT
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    text = args.checkpoint if args.checkpoint else (args.policy or "oracle")
    refs = [r.strip() for r in text.split(",") if r.strip()]
    if args.checkpoint:
        refs = [r if r.startswith("ckpt:") else f"ckpt:{r}" for r in refs]
    result = evaluate(refs, shift=args.shift, severity=args.severity, episodes=args.episodes, workers=args.workers,
                      batch_size=args.batch_size, split=args.split, seed=args.seed, progress=not args.json,
                      cluster=args.cluster)
    table, comparisons = result["table"], result["paired"]
    if args.json:
        per = {ref: {"results": {k: v.to_dict() for k, v in res.items()}} for ref, res in table.items()}
        out = {"config": result["config"].to_dict(), **(per[refs[0]] if len(refs) == 1 else {"policies": per})}
        if len(refs) == 1:
            out["policy"] = refs[0]
        if comparisons:
            out["paired"] = {s: c.to_dict() for s, c in comparisons.items()}
        print(json.dumps(out, sort_keys=True))
        return 0
    if args.markdown:
        from nsl.eval import markdown_table

        print(markdown_table(table))
    else:
        for ref, results in table.items():
            for name, r in results.items():
                print(f"{ref:<20} {name:<24} {r}")
    for s, c in comparisons.items():
        print(f"paired on {s}: {c}")
    return 0


def evaluate(refs: list[str], *, shift: str = "base", severity: float | None = None, episodes: int = 100,
             workers: int = 1, batch_size: int = 8, split: str = "test", seed: int = 1000, progress: bool = True,
             source: str | None = None, cluster: str | None = None) -> dict:
    """Evaluate policy references on shifts; checkpoint results go to the catalog.

    ``refs`` are policies (``random``, ``oracle[:NOISE]``, ``ckpt:...``); the
    other keyword arguments are those of ``nsl eval``, and ``source`` is
    recorded with each catalogued evaluation (e.g. "continual"); ``cluster``
    runs the scenes on Ray (``--cluster``; None: ``$NSL_CLUSTER`` or local).  Returns
    ``{"config": EvalConfig, "outcomes": {ref: {shift: [bool]}}, "table": {ref:
    {shift: SuccessRate}}, "paired": {shift: PairedComparison}}`` (paired only
    for two refs).
    """
    from nsl.collectors import EnvConfig, parse_shift_list
    from nsl.errors import ConfigError
    from nsl.eval import EvalConfig, compare_paired, evaluate_outcomes, success_rate_from_outcomes
    from nsl.commands._refs import policy_factory

    if episodes < 1:
        raise ConfigError(f"--episodes {episodes} must be at least 1")
    if workers < 1 or batch_size < 1:
        raise ConfigError(f"--workers {workers} and --batch-size {batch_size} must be at least 1")
    if not refs:
        raise ConfigError("no policy to evaluate; give --checkpoint REF or --policy REF")
    shifts = parse_shift_list(shift, severity)
    config = EvalConfig(episodes=episodes, split=split, seed=seed, workers=workers, batch=batch_size)
    factories = {ref: policy_factory(ref, EnvConfig()) for ref in refs}  # validate all before any work
    from nsl.cluster import open_executor

    with open_executor(cluster) as ex:  # local processes, or scene chunks as Ray tasks (same outcomes)
        outcomes = {ref: evaluate_outcomes(make, shifts, config, progress=progress, runner=ex.runner)
                    for ref, make in factories.items()}
    table = {ref: {s: success_rate_from_outcomes(s, o) for s, o in res.items()} for ref, res in outcomes.items()}
    _store(table, config, source)
    paired = {}
    if len(refs) == 2:
        a, b = refs
        paired = {s: compare_paired(outcomes[a][s], outcomes[b][s], a, b) for s in outcomes[a]}
    return {"config": config, "outcomes": outcomes, "table": table, "paired": paired}


def _store(table, config, source: str | None) -> None:
    """Record checkpoint evaluations in the catalog."""
    refs = [r for r in table if r.startswith("ckpt:") or r == "base"]
    if not refs:
        return
    from nsl import code_version
    from nsl.catalog import Catalog
    from nsl.commands._refs import resolve_init

    extra = {"eval": config.to_dict(), "code_version": code_version(), **({"source": source} if source else {})}
    with Catalog() as cat:
        for ref in refs:
            entry = resolve_init(cat, ref)
            for shift, r in table[ref].items():
                cat.add_evaluation(entry.id, shift, episodes=r.episodes, successes=r.successes, seed=config.seed,
                                   split=config.split, ci=r.ci, extra=extra)
            cat.write_model_card(entry.id)
