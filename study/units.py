"""The study's unit graph: every collection, training run and evaluation, with its dependencies.

A unit is one job whose output is an ordinary catalogued thing: a dataset
version (``collect``), a checkpoint run (``train``) or an evaluation record
(``eval``).  Its name is derived from what it does, so two experiments that
need the same job share one unit: the first continual stage *is* the
single-step fine-tune of its shift, and the base policy's evaluations serve
the challenge table, the tiers table and stage 0 of the continual matrix.

Names (``S`` is the study name; datasets and checkpoints are prefixed with it)::

    base-data:NAME                      collect a missing base-task dataset again (hash-checked)
    collect:SHIFT:POLICY                POLICY ('base' or a train tag) collects in SHIFT -> dataset S-shift-by-policy
    train:TAG                           a training run -> checkpoint S-TAG
    eval:POLICY:SHIFT                   an evaluation of a checkpoint on SHIFT (plan's episodes and scene seed)

Train tags: ``ft-SHIFT-nK-kSTEPS-sSEED`` (fine-tune from the base on the first K
target episodes; ``scratch-...``, ``new_head-...``, ``scratch_target-...`` for the
baselines, and ``no_target-kSTEPS-sSEED``, the base fine-tuned on base data alone),
``cI-SHIFT-...`` (continual stage I >= 2, from stage I-1),
``curve-METHOD-...`` and ``es-...`` (runs that record a success curve).

The graph is a ``networkx.DiGraph`` (edge: dependency -> dependant); the
scheduler runs it in topological order.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import networkx as nx

from nsl.errors import ConfigError

from .plan import Plan

BASE_POLICY = "base"  # the policy/checkpoint name of the plan's base checkpoint in unit names


@dataclass(frozen=True)
class BaseSource:
    """One base-task dataset as the study uses it."""

    dataset: str
    weight: float  # share within the base half of each batch (the weights sum to 1)
    hash: str | None = None  # the version hash the base checkpoint records (None: not checked)
    episodes: int | None = None
    recipe: Mapping[str, Any] | None = None  # collect settings when the workspace lacks it (a unit collects it)


@dataclass(frozen=True)
class Unit:
    name: str
    kind: str  # collect | train | eval
    params: Mapping[str, Any] = field(default_factory=dict)
    deps: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        return self.name.split(":", 1)[1]


def slug(shift: str) -> str:
    return shift.replace("+", "-").replace("@", "-").replace("_", "-")


def train_tag(method: str, shift: str, episodes: int, steps: int, seed: int, prefix: str | None = None) -> str:
    return f"{prefix or method}-{slug(shift)}-n{episodes}-k{steps}-s{seed}"


def no_target_tag(steps: int, seed: int) -> str:
    """The ``no_target`` baseline's train tag: one run per seed serves every shift."""
    return f"no_target-k{steps}-s{seed}"


def base_data_units(base: list[BaseSource]) -> list[Unit]:
    """A collect unit for each base dataset with a recipe (done at once when the workspace holds it)."""
    return [
        Unit(f"base-data:{b.dataset}", "collect", {"dataset": b.dataset, "expect_hash": b.hash, **b.recipe})
        for b in base
        if b.recipe is not None
    ]


def base_mix(base: list[BaseSource], share: float = 0.5) -> list[dict[str, Any]]:
    """The base part of every batch (a train unit's ``base`` parameter): each dataset at ``share`` of its weight."""
    return [{"dataset": b.dataset, "hash": b.hash, "episodes": b.episodes, "weight": share * b.weight} for b in base]


class _Builder:
    def __init__(self, plan: Plan, study: str, base: list[BaseSource]):
        self.plan, self.study, self.base = plan, study, base
        self.units: dict[str, Unit] = {}
        self.base_deps = tuple(u.name for u in base_data_units(base))
        for u in base_data_units(base):
            self._add(u)

    def _add(self, unit: Unit) -> str:
        old = self.units.get(unit.name)
        if old is not None and (dict(old.params), old.deps) != (dict(unit.params), unit.deps):
            raise ConfigError(
                f"two experiments of the plan need unit {unit.name} with different settings; "
                "this is a bug in the unit graph, please report it"
            )
        self.units[unit.name] = unit
        return unit.name

    def ref(self, policy: str) -> str:
        """The catalog reference of a policy name ('base' or a train tag)."""
        return self.plan.base if policy == BASE_POLICY else f"ckpt:{self.study}-{policy}@latest"

    # -- units ---------------------------------------------------------------------------------------------------
    def collect(self, shift: str, policy: str, episodes: int) -> str:
        c = self.plan.collect
        deps = () if policy == BASE_POLICY else (f"train:{policy}",)
        return self._add(
            Unit(
                f"collect:{shift}:{policy}",
                "collect",
                {
                    "dataset": f"{self.study}-{slug(shift)}-by-{slug(policy)}",
                    "shift": shift,
                    "policy": policy,
                    "policy_ref": self.ref(policy),
                    "episodes": episodes,
                    "seed": c.seed,
                    "epsilon": c.epsilon,
                    "batch": c.batch,
                },
                deps,
            )
        )

    def target_data(self, shift: str, episodes: int, policy: str = BASE_POLICY) -> tuple[str, int]:
        """(collect unit, tier) for the first ``episodes`` episodes the policy collects in the shift."""
        size = self.plan.collect.episodes if policy == BASE_POLICY else episodes
        return self.collect(shift, policy, size), episodes

    def train(
        self,
        tag: str,
        shift: str,
        data: tuple[str, int] | None,
        *,
        method: str,
        init: str | None,
        steps: int,
        seed: int,
        monitor: Mapping[str, Any] | None = None,
        mixed: bool = True,
    ) -> str:
        """A training run on the first K episodes of ``data`` (None: base data alone), 50/50 with base data if
        ``mixed``."""
        deps = [*self.base_deps]
        target = None
        if data is not None:
            collect_unit, tier = data
            deps.insert(0, collect_unit)
            target = {
                "collect": collect_unit,
                "dataset": self.units[collect_unit].params["dataset"],
                "tier": tier,
                "weight": 0.5 if mixed else 1.0,
            }
        if init is not None and init != BASE_POLICY:
            deps.append(f"train:{init}")
        mix = base_mix(self.base, 1.0 if target is None else 0.5) if mixed or target is None else []
        return self._add(
            Unit(
                f"train:{tag}",
                "train",
                {
                    "checkpoint": f"{self.study}-{tag}",
                    "shift": shift,
                    "method": method,
                    "init": init,
                    "init_ref": None if init is None else self.ref(init),
                    "steps": steps,
                    "seed": seed,
                    "base": mix,
                    "target": target,
                    "checkpoint_every": self.plan.checkpoint_every,
                    "monitor": None if monitor is None else dict(monitor),
                    # fp32 is left out, so the units of plans made before the setting keep their parameters
                    **({} if self.plan.precision == "fp32" else {"precision": self.plan.precision}),
                    **({} if self.plan.learner == "qtopt" else {"learner": self.plan.learner}),
                },
                tuple(deps),
            )
        )

    def evaluate(self, policy: str, shift: str) -> str:
        """An evaluation on the plan's reporting scenes."""
        e = self.plan.eval
        deps = () if policy == BASE_POLICY else (f"train:{policy}",)
        return self._add(
            Unit(
                f"eval:{policy}:{shift}",
                "eval",
                {
                    "policy": policy,
                    "checkpoint_ref": self.ref(policy),
                    "shift": shift,
                    "episodes": e.episodes,
                    "seed": e.seed,
                },
                deps,
            )
        )

    # -- experiments ---------------------------------------------------------------------------------------------
    def build(self) -> dict[str, Unit]:
        p = self.plan
        challenge = ["base", *p.shifts]
        extra = [
            *(p.continual.sequence if p.continual else ()),
            *([p.curves.shift] if p.curves else ()),
            *([p.early_stop.shift] if p.early_stop else ()),
        ]
        for s in [*challenge, *[s for s in extra if s not in challenge]]:
            self.evaluate(BASE_POLICY, s)  # Table 5.1, tier 0 of Table 5.2, stage 0 of Table 5.3
        f = p.finetune
        top = f.tiers[-1]
        for shift in p.shifts:
            for k in f.tiers:
                for seed in f.seeds_of(k):
                    tag = train_tag("ft", shift, k, f.steps, seed)
                    self.train(
                        tag, shift, self.target_data(shift, k), method="ft", init=BASE_POLICY, steps=f.steps, seed=seed
                    )
                    self.evaluate(tag, shift)
                    self.evaluate(tag, "base")
                    if k == top and f.cross_shift:  # the top tier on the other shifts: what it forgets of them
                        for other in p.shifts:
                            self.evaluate(tag, other)
            for seed in f.seeds:
                for method in (m for m in f.baselines if m != "no_target"):
                    tag = train_tag(method, shift, top, f.steps, seed)
                    self.train(
                        tag,
                        shift,
                        self.target_data(shift, top),
                        method="scratch" if method == "scratch_target" else method,
                        init=BASE_POLICY,
                        steps=f.steps,
                        seed=seed,
                        mixed=method != "scratch_target",
                    )
                    self.evaluate(tag, shift)
                    self.evaluate(tag, "base")
        if f.base_task:  # Table 5.2's validation row: the base fine-tuned on its own base-task episodes
            for k in f.tiers:
                for seed in f.seeds_of(k):
                    tag = train_tag("ft", "base", k, f.steps, seed)
                    self.train(
                        tag,
                        "base",
                        self.target_data("base", k),
                        method="ft",
                        init=BASE_POLICY,
                        steps=f.steps,
                        seed=seed,
                    )
                    self.evaluate(tag, "base")
        if "no_target" in f.baselines:
            for seed in f.seeds:
                tag = no_target_tag(f.steps, seed)
                self.train(tag, "base", None, method="ft", init=BASE_POLICY, steps=f.steps, seed=seed)
                for shift in ["base", *p.shifts]:
                    self.evaluate(tag, shift)
        if p.continual is not None:
            self._continual()
        if p.curves is not None:
            cv = p.curves
            for method in cv.methods:
                for seed in cv.seeds:
                    tag = train_tag(method, cv.shift, cv.episodes, cv.steps, seed, prefix=f"curve-{method}")
                    self.train(
                        tag,
                        cv.shift,
                        self.target_data(cv.shift, cv.episodes),
                        method=method,
                        init=BASE_POLICY,
                        steps=cv.steps,
                        seed=seed,
                        monitor={
                            "every": cv.every,
                            "episodes": cv.eval_episodes,
                            "base_episodes": cv.eval_episodes,
                            "seed": p.eval.seed,
                            "holdout": None,
                        },
                    )
        if p.early_stop is not None:
            es = p.early_stop
            tag = train_tag("ft", es.shift, es.episodes, es.steps, es.seed, prefix="es")
            self.train(
                tag,
                es.shift,
                self.target_data(es.shift, es.episodes),
                method="ft",
                init=BASE_POLICY,
                steps=es.steps,
                seed=es.seed,
                monitor={  # its criteria choose a step: selection scenes
                    "every": es.every,
                    "episodes": es.eval_episodes,
                    "base_episodes": es.eval_episodes,
                    "seed": p.eval.selection_seed,
                    "holdout": es.holdout,
                },
            )
        return self.units

    def _continual(self) -> None:
        s = self.plan.continual
        tasks = ["base", *s.sequence]
        for seed in s.seeds:
            policy = BASE_POLICY
            for shift, tag in zip(s.sequence, continual_tags(self.plan, seed)):
                data = self.target_data(shift, s.episodes, policy)
                self.train(tag, shift, data, method="ft", init=policy, steps=s.steps, seed=seed)
                for t in tasks:
                    self.evaluate(tag, t)
                # single-step comparison: fine-tune the base on the base policy's episodes of this shift
                single = train_tag("ft", shift, s.episodes, s.steps, seed)
                self.train(
                    single,
                    shift,
                    self.target_data(shift, s.episodes),
                    method="ft",
                    init=BASE_POLICY,
                    steps=s.steps,
                    seed=seed,
                )
                self.evaluate(single, shift)
                policy = tag


def continual_tags(plan: Plan, seed: int | None = None) -> list[str]:
    """The train tag of every continual stage of one seed's sequence (default: the first seed), in order."""
    s = plan.continual
    if s is None:
        return []
    seed = s.seeds[0] if seed is None else seed
    return [
        train_tag("ft", shift, s.episodes, s.steps, seed, prefix=None if i == 1 else f"c{i}")
        for i, shift in enumerate(s.sequence, 1)
    ]


def build_units(plan: Plan, study: str, base: list[BaseSource]) -> dict[str, Unit]:
    """Every unit of the plan, by name."""
    return _Builder(plan, study, base).build()


def unit_graph(units: Mapping[str, Unit] | Iterable[Unit]) -> nx.DiGraph:
    """A DAG with one node per unit (attribute ``unit``) and an edge from each dependency to its dependant."""
    items = list(units.values()) if isinstance(units, Mapping) else list(units)
    g = nx.DiGraph()
    for u in items:
        g.add_node(u.name, unit=u)
    for u in items:
        for d in u.deps:
            if d not in g:
                raise ConfigError(f"unit {u.name} depends on {d}, which is not in the graph")
            g.add_edge(d, u.name)
    if not nx.is_directed_acyclic_graph(g):
        raise ConfigError(f"the unit graph has a cycle: {nx.find_cycle(g)}")
    return g


def order(graph: nx.DiGraph) -> list[str]:
    """A deterministic topological order (ties broken by name)."""
    return list(nx.lexicographical_topological_sort(graph))
