"""What a study will cost on this machine, from its unit graph and measured unit costs.

The figures below were measured on the project's 2-core machine with
``scripts/study_unit_costs.py`` (one unit at a time, ``--workers 1``, both
cores per unit) and with single ``nsl`` commands when the machine was quiet
(load average about 1); a busy machine is slower.  A unit's cost is a fixed
overhead plus its work: collected or evaluated episodes, and gradient steps by
method (a progressive network runs two columns with lateral connections).
Units that already have their output cost nothing.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

import networkx as nx

from .units import Unit

# Measured 2026-11-29 with scripts/study_unit_costs.py (one-shift cost plan, 100 steps, 50 evaluation episodes,
# 100 episodes collected by ckpt:base; load average 1.2-3.8) and single commands at load ~1; nsl environment v3,
# the shipped base, batch 64, CEM 64/6/2 targets.  Measured: 50 evaluation episodes 1.0-1.8 s per unit, 100
# checkpoint-policy episodes 3.2 s, 200 scripted episodes 7.3 s, 100 training steps 5.8 s (new_head), 19-26 s
# (ft, scratch: the first training unit also imports torch's compiler and decodes the datasets' images), 21 s
# (pnn, ft_pnn).  The rates below are rounded down from these, so that a busier machine still fits.
# Training in long study processes is slower than those short probes: the `full` study's 1,000-step fine-tunes
# logged 12-13 steps/s on a quiet machine (8-12 when shared), and `transfer-small`'s 200-step runs 10-13; in line
# with `nsl bench learner` (about 5 GFLOP per step at about 46 GFLOP/s).  Hence 11 steps/s.
UNIT_OVERHEAD_S = 1.5  # per unit run in-process: catalog, policy loading, sampler set-up
SCRIPTED_EPISODES_PER_S = 25.0  # oracle/random collection, 2 simulator processes
CHECKPOINT_EPISODES_PER_S = 25.0  # CEM-policy collection (with epsilon), 2 processes, 8 envs each
EVAL_EPISODES_PER_S = 35.0  # CEM-policy evaluation, 2 processes, 8 envs each
STEPS_PER_S = {"ft": 11.0, "new_head": 11.0, "new_head_frozen": 11.0, "scratch": 11.0, "pnn": 5.0, "ft_pnn": 5.0}
# Training units with precision bf16 (or auto on a CPU with bfloat16): the `full` study's bf16 fine-tunes took 73-80 s
# for 2,000 steps on one thread each (25-27 steps/s, two units at a time, AVX-512 BF16, no AMX), where its float32
# units had logged 12-13 steps/s; `nsl bench learner` gives 1.6-1.7x in alternating rounds.  Rounded down.
BF16_STEP_SPEEDUP = 1.8
# Supervised features (nsl features): one scene compiled per train object, then its frames rendered (80 frames of 20
# objects took 0.63 s here, while a test suite ran); classifier steps of 128 frames through the base's trunk, in
# float32 with the batch-norm classifier: the `online` plan's features unit (3,000 steps, 899 x 24 frames) took
# about 1,130 s beside another unit, so about 3 steps/s.
TRAIN_OBJECTS = 899
OBJECT_SCENE_S = 0.02
OBJECT_FRAME_S = 0.002
FEATURE_STEPS_PER_S = 3.0
IMAGE_CACHE_FRAMES_PER_S = 8_000.0  # first use of a dataset version: decode its PNG frames once
FRAMES_PER_EPISODE = 8


@dataclass(frozen=True)
class Estimate:
    seconds: float
    by_kind: Mapping[str, float]
    units: int

    def __str__(self) -> str:
        parts = ", ".join(f"{k} {v / 60:.0f}" for k, v in sorted(self.by_kind.items()))
        return f"about {self.seconds / 60:.0f} minutes for {self.units} units ({parts} minutes)"


def unit_seconds(unit: Unit) -> float:
    """The estimated seconds of one unit (see the module's figures)."""
    p = unit.params
    if unit.kind == "collect":
        rate = SCRIPTED_EPISODES_PER_S if not str(p["policy_ref"]).startswith("ckpt:") else CHECKPOINT_EPISODES_PER_S
        return UNIT_OVERHEAD_S + p["episodes"] / rate
    if unit.kind == "eval":
        return UNIT_OVERHEAD_S + p["episodes"] / EVAL_EPISODES_PER_S
    if unit.kind == "train":
        rate = STEPS_PER_S.get(p["method"], min(STEPS_PER_S.values()))
        if _bf16(p.get("precision", "fp32")):
            rate *= BF16_STEP_SPEEDUP
        seconds = UNIT_OVERHEAD_S + p["steps"] / rate
        m = p.get("monitor")
        if m:
            points = p["steps"] // m["every"] + 1
            seconds += points * (m["episodes"] + m["base_episodes"]) / EVAL_EPISODES_PER_S
        return seconds
    if unit.kind == "features":
        if p.get("encoder"):
            return UNIT_OVERHEAD_S
        objects = p["classes"] or TRAIN_OBJECTS
        render = objects * (OBJECT_SCENE_S + p["frames"] * OBJECT_FRAME_S)
        return UNIT_OVERHEAD_S + render + p["steps"] / FEATURE_STEPS_PER_S
    return UNIT_OVERHEAD_S


def _bf16(precision: str) -> bool:
    """Whether a training unit of this precision steps in bfloat16 on this machine."""
    if precision != "auto":
        return precision == "bf16"
    from nsl.learners.precision import bf16_supported

    return bf16_supported()


def estimate(units: Iterable[Unit], done: Iterable[str] = ()) -> Estimate:
    """Seconds for the units not in ``done``, in total and by kind."""
    skip = set(done)
    by_kind: dict[str, float] = {}
    n = 0
    cached: set[str] = set()
    for u in units:
        if u.name in skip:
            continue
        n += 1
        s = unit_seconds(u)
        if u.kind == "collect" and u.params["dataset"] not in cached:
            cached.add(u.params["dataset"])
            s += u.params["episodes"] * FRAMES_PER_EPISODE / IMAGE_CACHE_FRAMES_PER_S
        by_kind[u.kind] = by_kind.get(u.kind, 0.0) + s
    return Estimate(sum(by_kind.values()), by_kind, n)


@dataclass(frozen=True)
class Schedule:
    """The wall time of the units left on ``slots`` units at once, and the chain of units that bounds it."""

    slots: int
    seconds: float  # a list schedule: ready units start by critical path, as the scheduler starts them
    critical: float  # the costliest chain of dependent units: no number of slots finishes sooner
    path: tuple[str, ...]  # that chain, first unit first

    def __str__(self) -> str:
        return (
            f"about {self.seconds / 60:.0f} minutes on {self.slots} unit slots (critical path "
            f"{self.critical / 60:.0f} minutes, {len(self.path)} units)"
        )


def schedule(
    graph: nx.DiGraph, slots: int, done: Iterable[str] = (), cost: Callable[[Unit], float] = unit_seconds
) -> Schedule:
    """Simulate the scheduler on ``slots`` slots (local workers, or cluster CPUs over the CPUs a unit holds).

    Each unit's cost is :func:`unit_seconds`: one slot runs a unit as fast as this machine's ``--workers 1``
    does (the `full` study ran at that pace with two units at once on two cores: docs/study.md).
    """
    from .scheduler import critical_path

    if slots < 1:
        raise ValueError(f"slots {slots} must be at least 1")
    skip = set(done)
    g = graph.subgraph([n for n in graph if n not in skip]).copy()
    costs = {n: float(cost(g.nodes[n]["unit"])) for n in g}
    rank = critical_path(g, lambda u: costs[u.name])
    waiting = {n: g.in_degree(n) for n in g}
    ready = [(-rank[n], n) for n in g if waiting[n] == 0]
    heapq.heapify(ready)
    running: list[tuple[float, str]] = []
    now = 0.0
    while ready or running:
        while ready and len(running) < slots:
            _, n = heapq.heappop(ready)
            heapq.heappush(running, (now + costs[n], n))
        now, n = heapq.heappop(running)
        for s in g.successors(n):
            waiting[s] -= 1
            if waiting[s] == 0:
                heapq.heappush(ready, (-rank[s], s))
    path: list[str] = []
    node = max(g, key=lambda n: rank[n]) if len(g) else None
    while node is not None:
        path.append(node)
        node = max(g.successors(node), key=lambda n: rank[n], default=None)
    return Schedule(slots, now, rank[path[0]] if path else 0.0, tuple(path))
