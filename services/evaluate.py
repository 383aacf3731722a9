"""Evaluate policies on shifts: success with 95% Wilson intervals, paired comparisons, stored in the catalog.

Episode ``i`` uses scene ``(seed, i)`` on every shift and for every policy, so
policies evaluated with the same seed see identical scenes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .options import EvaluateOptions

__all__ = ["EvaluateOptions", "EvaluationResult", "evaluate", "store_evaluation"]


@dataclass(frozen=True)
class EvaluationResult:
    """The outcome of :func:`evaluate`: the rates per policy and shift, and what it stored in the catalog."""

    config: Any  # the EvalConfig of every evaluation
    outcomes: dict  # {ref: {shift: [bool per episode]}}
    table: dict  # {ref: {shift: SuccessRate}}
    paired: dict  # {shift: PairedComparison}, with exactly two refs
    stored: dict  # {ref: catalog id} of the checkpoints whose evaluations were stored
    precision: str = "fp32"  # how checkpoint policies acted: fp32 or bf16 (CPU), PRECISION/cuda/N (a GPU, N a call)
    source: str | None = None  # recorded with each catalogued evaluation (e.g. "study")

    def __getitem__(self, key: str) -> Any:  # result["table"], as the dict it replaces
        return getattr(self, key)


def evaluate(
    refs: list[str],
    options: EvaluateOptions = EvaluateOptions(),
    *,
    progress: bool = True,
    source: str | None = None,
    cluster: str | None = None,
    register: bool = True,
) -> EvaluationResult:
    """Evaluate policy references on shifts; checkpoint results go to the catalog.

    ``refs`` are policies (``random``, ``oracle[:NOISE]``, ``ckpt:...``);
    ``options`` are those of ``nsl eval``; ``source`` is recorded with each
    catalogued evaluation (e.g. "continual"); ``cluster`` runs the scenes on
    Ray (``--cluster``; None: ``$NSL_CLUSTER`` or local).  The paired
    comparison is made for exactly two refs.  ``register=False`` stores
    nothing (``stored`` is empty): :func:`store_evaluation` does it later, in
    the process that writes the catalog (a study's driver).
    """
    from nsl.collectors import EnvConfig, parse_shift_list
    from nsl.errors import ConfigError
    from nsl.eval import EvalConfig, compare_paired, evaluate_outcomes, success_rate_from_outcomes

    from .refs import policy_factory

    o = options
    shift, severity, episodes, workers, num_envs, split, seed = (
        o.shift,
        o.severity,
        o.episodes,
        o.workers,
        o.num_envs,
        o.split,
        o.seed,
    )

    if episodes < 1:
        raise ConfigError(f"--episodes {episodes} must be at least 1")
    if workers < 1 or num_envs < 1:
        raise ConfigError(f"--workers {workers} and --num-envs {num_envs} must be at least 1")
    if not refs:
        raise ConfigError("no policy to evaluate; give --checkpoint REF or --policy REF")
    shifts = parse_shift_list(shift, severity, o.engine)
    config = EvalConfig(episodes=episodes, split=split, seed=seed, workers=workers, batch=num_envs)

    from nsl.learners.device import resolve_device
    from nsl.learners.precision import resolve_precision

    device = resolve_device(o.device)
    precision = resolve_precision(o.precision, device)
    factories = {  # validate all first
        ref: policy_factory(ref, EnvConfig(), precision=precision, device=device) for ref in refs
    }
    if device != "cpu":  # batched acting: the episodes depend on the batch, so the record names it
        precision = f"{precision}/{device}/{num_envs}"
    from nsl.cluster import open_executor

    with open_executor(cluster) as ex:  # local processes, or scene chunks as Ray tasks (same outcomes)
        outcomes = {
            ref: evaluate_outcomes(make, shifts, config, progress=progress, runner=ex.runner)
            for ref, make in factories.items()
        }
    table = {ref: {s: success_rate_from_outcomes(s, out) for s, out in res.items()} for ref, res in outcomes.items()}
    paired = {}
    if len(refs) == 2:
        a, b = refs
        paired = {s: compare_paired(outcomes[a][s], outcomes[b][s], a, b) for s in outcomes[a]}
    result = EvaluationResult(config, outcomes, table, paired, {}, precision, source)
    return store_evaluation(result) if register else result


def store_evaluation(result: EvaluationResult) -> EvaluationResult:
    """Record a result's checkpoint evaluations in the catalog (idempotent); returns it with ``stored`` filled."""
    from dataclasses import replace

    stored = _store(result.table, result.config, result.source, result.precision, result.outcomes)
    return replace(result, stored=stored)


def _store(table, config, source: str | None, precision: str, outcomes: dict) -> dict[str, str]:
    """Record checkpoint evaluations in the catalog; returns ``{ref: checkpoint id}``."""
    refs = [r for r in table if r.startswith("ckpt:") or r == "base"]
    if not refs:
        return {}
    from nsl import code_version
    from nsl.catalog import Catalog

    from .refs import resolve_init

    extra = {
        "eval": config.to_dict(),
        "code_version": code_version(),
        **({"source": source} if source else {}),
        **({"precision": precision} if precision != "fp32" else {}),
    }
    stored = {}
    with Catalog() as cat:
        for ref in refs:
            entry = resolve_init(cat, ref)
            stored[ref] = entry.id
            for shift, r in table[ref].items():
                cat.add_evaluation(
                    entry.id,
                    shift,
                    episodes=r.episodes,
                    successes=r.successes,
                    seed=config.seed,
                    split=config.split,
                    ci=r.ci,
                    # episode i's success on scene (seed, i), so that two evaluations on the same scenes pair up
                    extra={**extra, "outcomes": "".join("1" if o else "0" for o in outcomes[ref][shift])},
                    precision=precision,
                )
            cat.write_model_card(entry.id)
    return stored
