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
    features:features                   supervised features ([supervised], nsl features) -> checkpoint S-features

Train tags: ``ft-SHIFT-nK-kSTEPS-sSEED`` (fine-tune from the base on the first K
target episodes; ``scratch-...``, ``new_head-...``, ``scratch_target-...`` for the
baselines; ``supervised-...`` and ``supervised_frozen-...`` start from the supervised features;
``no_target-kSTEPS-sSEED``, the base fine-tuned on base data alone),
``cI-SHIFT-...`` (continual stage I >= 2, from stage I-1),
``curve-METHOD-...`` and ``es-...`` (runs that record a success curve).

The graph is a ``networkx.DiGraph`` (edge: dependency -> dependant); the
scheduler runs it in topological order.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import networkx as nx

from nsl.errors import ConfigError

from .plan import SUPERVISED_BASELINES, Plan

BASE_POLICY = "base"  # the policy/checkpoint name of the plan's base checkpoint in unit names
FEATURES_POLICY = "features"  # the supervised features' checkpoint (a features unit makes it)


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
    """A shift's name as part of a dataset or checkpoint name: engine:pybullet+harsh_lighting@2 ->
    engine-pybullet-harsh-lighting-2."""
    return shift.replace("+", "-").replace("@", "-").replace("_", "-").replace(":", "-")


def train_tag(
    method: str,
    shift: str,
    episodes: int,
    steps: int,
    seed: int,
    prefix: str | None = None,
    collection: int | None = None,
) -> str:
    """A training run's tag; ``collection``: the collection seed of a target collection other than the plan's."""
    more = "" if collection is None else f"-c{collection}"
    return f"{prefix or method}-{slug(shift)}-n{episodes}-k{steps}-s{seed}{more}"


@dataclass(frozen=True)
class EarlyStopUnit:
    """One long fine-tune of [early_stop]: its train tag, shift, tier, seed and base datasets (empty: all)."""

    tag: str
    shift: str
    episodes: int
    seed: int
    base: tuple[str, ...] = ()


def early_stop_runs(plan: Plan) -> list[EarlyStopUnit]:
    """Every long fine-tune of the plan's [early_stop], in order: its shifts at its tier, then its extra runs, each
    with every seed (the first is the one the report's early-stopping table reads)."""
    es = plan.early_stop
    if es is None:
        return []
    out = []
    wanted = [(s, es.episodes, ()) for s in es.all_shifts] + [(r.shift, r.episodes, tuple(r.base)) for r in es.runs]
    for shift, episodes, base in wanted:
        for seed in es.all_seeds:
            tag = train_tag("ft", shift, episodes, es.steps, seed, prefix="es")
            if base:
                tag += "-b-" + "-".join(slug(b) for b in base)
            out.append(EarlyStopUnit(tag, shift, episodes, seed, base))
    return out


def top_tier_tags(plan: Plan, shift: str) -> dict[int, list[str]]:
    """The top tier's fine-tune tags on a shift, by target collection (collection seed -> one tag per seed)."""
    f, primary = plan.finetune, plan.collect.seed
    return {
        c: [train_tag("ft", shift, f.tiers[-1], f.steps, s, collection=None if c == primary else c) for s in f.seeds]
        for c in f.collections_of(primary)
    }


def online_tag(method: str, ratio: float, shift: str, round_: int, episodes: int, steps: int, seed: int) -> str:
    """The train tag of online round ``round_`` (1-based): ``online-METHOD-pPERCENT-SHIFT-rI-kSTEPS-sSEED``.

    Round 1 at the fine-tuning mix (half target data) is the offline fine-tune of Table 5.2 on the base policy's
    first ``episodes`` (its tag, so a plan with both trains it once)."""
    if round_ == 1 and ratio == 0.5:
        return train_tag(method, shift, episodes, steps, seed)
    return f"online-{method}-p{round(100 * ratio)}-{slug(shift)}-r{round_}-k{steps}-s{seed}"


def online_runs(plan: Plan) -> list[tuple[str, float]]:
    """The online runs of a plan as (round 1's method, target share): Fig. 5.10's methods at ``ratio``, then
    Fig. 5.11's ratios with ``ft`` (a run both need is one run)."""
    o = plan.online
    if o is None:
        return []
    return list(dict.fromkeys([*((m, o.ratio) for m in o.methods), *(("ft", r) for r in o.ratios)]))


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
    def collect(self, shift: str, policy: str, episodes: int, seed: int | None = None, named: bool = False) -> str:
        """A collection by ``policy`` in ``shift``; ``named``: one of the top tier's other target collections,
        named by its seed (``collect:SHIFT:base:cSEED``)."""
        c = self.plan.collect
        deps = () if policy == BASE_POLICY else (f"train:{policy}",)
        more = f"-c{seed}" if named else ""
        return self._add(
            Unit(
                f"collect:{shift}:{policy}" + (f":c{seed}" if named else ""),
                "collect",
                {
                    "dataset": f"{self.study}-{slug(shift)}-by-{slug(policy)}{more}",
                    "shift": shift,
                    "policy": policy,
                    "policy_ref": self.ref(policy),
                    "episodes": episodes,
                    "seed": c.seed if seed is None else seed,
                    "epsilon": c.epsilon,
                    "batch": c.batch,
                },
                deps,
            )
        )

    def target_data(
        self, shift: str, episodes: int, policy: str = BASE_POLICY, collection: int | None = None
    ) -> tuple[str, int]:
        """(collect unit, tier) for the first ``episodes`` episodes the policy collects in the shift;
        ``collection``: the seed of another of the base's target collections than the plan's."""
        size = self.plan.collect.episodes if policy == BASE_POLICY else episodes
        if collection is not None:
            return self.collect(shift, policy, size, seed=collection, named=True), episodes
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
        more: Sequence[tuple[str, int]] = (),
        share: float = 0.5,
        base: Sequence[str] = (),
        shrink_perturb: Sequence[float] | None = None,
    ) -> str:
        """A training run on the first K episodes of ``data`` (None: base data alone), mixed with base data if
        ``mixed``: the target data at ``share`` of each batch; ``more`` target data (online rounds) share it with
        ``data`` in proportion to their episodes; ``base`` names the base datasets of its base half (empty: all,
        each at its weight; named ones share the half in proportion to their weights)."""
        deps = [*self.base_deps]
        target, extra = None, []
        if data is not None:
            parts = [data, *more]
            total = sum(tier for _, tier in parts)
            deps = [*(collect_unit for collect_unit, _ in parts), *deps]
            targets = [
                {
                    "collect": collect_unit,
                    "dataset": self.units[collect_unit].params["dataset"],
                    "tier": tier,
                    "weight": (share if mixed else 1.0) * (tier / total if more else 1.0),
                }
                for collect_unit, tier in parts
            ]
            target, extra = targets[0], targets[1:]
        if init == FEATURES_POLICY:
            deps.append(self.features())
        elif init is not None and init != BASE_POLICY:
            deps.append(f"train:{init}")
        base_share = 1.0 if target is None else 1.0 - share
        sources = self.base
        if base:
            chosen = [b for b in self.base if b.dataset in base]
            total = sum(b.weight for b in chosen)
            sources = [replace(b, weight=b.weight / total) for b in chosen]
        mix = base_mix(sources, base_share) if (mixed or target is None) and base_share > 0 else []
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
                    **({"more_targets": extra} if extra else {}),  # online rounds: every round's data so far
                    "checkpoint_every": self.plan.checkpoint_every,
                    "monitor": None if monitor is None else dict(monitor),
                    **({"shrink_perturb": list(shrink_perturb)} if shrink_perturb else {}),
                    # fp32 is left out, so the units of plans made before the setting keep their parameters
                    **({} if self.plan.precision == "fp32" else {"precision": self.plan.precision}),
                    **({} if self.plan.learner == "qtopt" else {"learner": self.plan.learner}),
                    **({} if self.plan.device == "auto" else {"device": self.plan.device}),
                },
                tuple(deps),
            )
        )

    def features(self) -> str:
        """The supervised features (the plan's [supervised]), in the base's architecture and recipe."""
        sv = self.plan.supervised
        assert sv is not None  # plan.py sets it whenever a supervised baseline is asked for
        return self._add(
            Unit(
                f"features:{FEATURES_POLICY}",
                "features",
                {
                    "checkpoint": f"{self.study}-{FEATURES_POLICY}",
                    "like_ref": self.plan.base,
                    "classes": sv.classes,
                    "frames": sv.frames,
                    "steps": sv.steps,
                    "seed": sv.seed,
                    "encoder": sv.encoder,
                    **({} if sv.label == "classes" else {"label": sv.label}),  # a classifier's units are unchanged
                },
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
    def _online(self) -> None:
        """Online fine-tuning in rounds (Figs. 5.10 and 5.11): round i's policy collects, round i+1 fine-tunes on
        every round's data so far.  Round 1 trains on the base policy's own collection (the tiers' data)."""
        o = self.plan.online
        assert o is not None
        for method, ratio in online_runs(self.plan):
            prev, collected = BASE_POLICY, []
            for i in range(1, o.rounds + 1):
                if i == 1:
                    collected.append(self.target_data(o.shift, o.episodes))
                else:  # the previous round's policy collects on fresh scenes
                    seed = self.plan.collect.seed + i - 1
                    collected.append((self.collect(o.shift, prev, o.episodes, seed=seed), o.episodes))
                tag = online_tag(method, ratio, o.shift, i, o.episodes, o.steps, o.seed)
                self.train(
                    tag,
                    o.shift,
                    collected[0],
                    more=collected[1:],
                    share=ratio,
                    method=method if i == 1 else "ft",
                    init=prev,
                    steps=o.steps,
                    seed=o.seed,
                )
                self.evaluate(tag, o.shift)
                prev = tag

    def build(self) -> dict[str, Unit]:
        p = self.plan
        challenge = ["base", *p.shifts]
        extra = [
            *(p.continual.sequence if p.continual else ()),
            *([p.curves.shift] if p.curves else ()),
            *(r.shift for r in early_stop_runs(p)),
            *([p.online.shift] if p.online else ()),
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
            for coll in f.collections_of(p.collect.seed)[1:]:  # the top tier on independent target collections
                for seed in f.seeds:
                    tag = train_tag("ft", shift, top, f.steps, seed, collection=coll)
                    data = self.target_data(shift, top, collection=coll)
                    self.train(tag, shift, data, method="ft", init=BASE_POLICY, steps=f.steps, seed=seed)
                    self.evaluate(tag, shift)
                    self.evaluate(tag, "base")
            for seed in f.seeds_of_baselines():
                for method in (m for m in f.baselines if m != "no_target"):
                    tag = train_tag(method, shift, top, f.steps, seed)
                    self.train(
                        tag,
                        shift,
                        self.target_data(shift, top),
                        method="scratch" if method == "scratch_target" else SUPERVISED_BASELINES.get(method, method),
                        init=FEATURES_POLICY if method in SUPERVISED_BASELINES else BASE_POLICY,
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
            for seed in f.seeds_of_baselines():
                tag = no_target_tag(f.steps, seed)
                self.train(tag, "base", None, method="ft", init=BASE_POLICY, steps=f.steps, seed=seed)
                for shift in ["base", *p.shifts]:
                    self.evaluate(tag, shift)
        if p.continual is not None:
            self._continual()
        if p.plasticity is not None:
            self._plasticity()
        if self.plan.efficiency is not None:
            self._efficiency()
        if p.online is not None:
            self._online()
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
            monitor = {  # its criteria choose a step: selection scenes
                "every": es.every,
                "episodes": es.eval_episodes,
                "base_episodes": es.eval_episodes,
                "seed": p.eval.selection_seed,
                "holdout": es.holdout,
                # FQE is fitted at every point only when a criterion needs it (the others come with every curve)
                **({"criterion": "fqe"} if "fqe" in es.criteria else {}),
            }
            for run in early_stop_runs(p):
                self.train(
                    run.tag,
                    run.shift,
                    self.target_data(run.shift, run.episodes),
                    method="ft",
                    init=BASE_POLICY,
                    steps=es.steps,
                    seed=run.seed,
                    monitor=monitor,
                    base=run.base,
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

    def _plasticity(self) -> None:
        """The 2x2 of plasticity or data, and the shrink-and-perturb arm; each evaluated on the shift and the base."""
        pl = self.plan.plasticity
        assert pl is not None
        for tag, init, collector, seed, arm in plasticity_runs(self.plan):
            data = self.target_data(pl.shift, pl.episodes, collector)
            sp = pl.shrink_perturb if arm == "stage-sp/base" else None
            self.train(tag, pl.shift, data, method="ft", init=init, steps=pl.steps, seed=seed, shrink_perturb=sp)
            self.evaluate(tag, pl.shift)
            self.evaluate(tag, "base")

    def _efficiency(self) -> None:
        """FT and scratch at every tier of each shift, on the reporting scenes; scratch with its selection curve."""
        p, ef = self.plan, self.plan.efficiency
        assert ef is not None
        for run in efficiency_runs(p):
            scratch = run.method != "ft"
            monitor = None
            if scratch and ef.curve_every:
                monitor = {
                    "every": ef.curve_every,
                    "episodes": ef.curve_episodes,
                    "base_episodes": 0,  # the shift only: scratch has no base task to keep
                    "seed": p.eval.selection_seed,
                    "holdout": None,
                }
            self.train(
                run.tag,
                run.shift,
                self.target_data(run.shift, run.tier),
                method="scratch" if scratch else "ft",
                init=BASE_POLICY,  # scratch re-initialises the base's architecture
                steps=ef.scratch_steps if scratch else ef.ft_steps,
                seed=run.seed,
                monitor=monitor,
                mixed=run.method != "scratch_target",
            )
            self.evaluate(run.tag, run.shift)


class EfficiencyRun(NamedTuple):
    tag: str  # the train tag
    shift: str
    tier: int  # target episodes
    method: str  # one of EFFICIENCY_METHODS
    seed: int


def efficiency_runs(plan: Plan) -> list[EfficiencyRun]:
    """Every run of the plan's [efficiency], shift by shift, method by method, tier by tier.  FT's tags are the
    fine-tuning tiers' own (a plan's [finetune] run with the same steps is shared); scratch's carry ``eff-``."""
    ef = plan.efficiency
    if ef is None:
        return []
    out = []
    for shift in ef.shifts:
        for method in ef.methods:
            steps = ef.ft_steps if method == "ft" else ef.scratch_steps
            prefix = None if method == "ft" else f"eff-{method.replace('_', '-')}"
            for tier in ef.tiers:
                for seed in ef.seeds:
                    tag = train_tag(method, shift, tier, steps, seed, prefix)
                    out.append(EfficiencyRun(tag, shift, tier, method, seed))
    return out


PLASTICITY_ARMS = ("base/base", "base/stage", "stage/base", "stage/stage", "stage-sp/base")  # start/data


class PlasticityRun(NamedTuple):
    tag: str  # the train tag
    init: str  # the start policy
    collector: str  # the policy whose episodes it fine-tunes on
    seed: int
    arm: str  # one of PLASTICITY_ARMS


def plasticity_runs(plan: Plan) -> list[PlasticityRun]:
    """(train tag, start policy, collecting policy, seed, arm) of every run of the plan's [plasticity], arm by arm
    (:data:`PLASTICITY_ARMS`).  The base on its own episodes is the single-step fine-tune (its tag is shared)."""
    pl = plan.plasticity
    if pl is None:
        return []
    stage = continual_tags(plan)[pl.stage - 1]
    out = []
    for arm in PLASTICITY_ARMS:
        start, data = arm.split("/")
        if start == "stage-sp" and not pl.shrink_perturb:
            continue
        init = BASE_POLICY if start == "base" else stage
        collector = BASE_POLICY if data == "base" else stage
        for seed in pl.seeds:
            if arm == "base/base":
                tag = train_tag("ft", pl.shift, pl.episodes, pl.steps, seed)
            elif arm == "stage/stage" and _is_next_stage(plan, seed):
                tag = continual_tags(plan)[pl.stage]  # the sequence's own next stage is this run
            else:
                label = f"c{pl.stage}" + ("sp" if start == "stage-sp" else "") if start != "base" else "base"
                by = "base" if data == "base" else f"c{pl.stage}"
                tag = f"pl-{label}-{by}-{slug(pl.shift)}-n{pl.episodes}-k{pl.steps}-s{seed}"
            out.append(PlasticityRun(tag, init, collector, seed, arm))
    return out


def _is_next_stage(plan: Plan, seed: int) -> bool:
    pl, c = plan.plasticity, plan.continual
    assert pl is not None and c is not None
    same = (pl.episodes, pl.steps, seed) == (c.episodes, c.steps, c.seeds[0])
    return same and pl.stage < len(c.sequence) and c.sequence[pl.stage] == pl.shift


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
