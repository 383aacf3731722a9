"""The unit graph: deterministic names, shared units, dependencies before dependants."""

from __future__ import annotations

import tomllib

from nsl.study.plan import parse_plan
from nsl.study.units import BaseSource, build_units, order, unit_graph

from .conftest import MINI_PLAN


def _units(text: str = MINI_PLAN):
    plan = parse_plan(tomllib.loads(text), default_name="mini")
    base = [
        BaseSource(
            "mini-base-oracle",
            1.0,
            None,
            12,
            {
                "shift": "base",
                "policy": "oracle:0.5",
                "policy_ref": "oracle:0.5",
                "episodes": 12,
                "seed": 1,
                "epsilon": 0.0,
                "batch": 8,
            },
        )
    ]
    return plan, build_units(plan, "mini", base)


def test_names_are_derived_from_the_plan_and_experiments_share_units():
    plan, units = _units()
    again = _units()[1]
    assert list(units) == list(again) and all(units[n] == again[n] for n in units)
    # the first continual stage is the single-step fine-tune of its shift at the same size: one unit
    stage1 = units["train:ft-harsh-lighting-n8-k10-s0"]
    assert stage1.params["init"] == "base" and stage1.params["target"]["tier"] == 8
    # one base-policy collection per shift; tiers, curves and early stopping are views of it
    collects = sorted(n for n in units if n.startswith("collect:"))
    assert collects == [
        "collect:harsh_lighting:base",
        "collect:offset_gripper:base",
        "collect:offset_gripper:ft-harsh-lighting-n8-k10-s0",
    ]
    tiers = {
        u.params["target"]["tier"]
        for u in units.values()
        if u.kind == "train" and u.params["target"]["collect"] == "collect:harsh_lighting:base"
    }
    assert tiers == {4, 8}
    # stage 2 fine-tunes stage 1 on data stage 1 collected
    s2 = units["train:c2-offset-gripper-n8-k10-s0"]
    assert s2.params["init"] == "ft-harsh-lighting-n8-k10-s0"
    assert set(s2.deps) == {
        "collect:offset_gripper:ft-harsh-lighting-n8-k10-s0",
        "base-data:mini-base-oracle",
        "train:ft-harsh-lighting-n8-k10-s0",
    }
    # the base policy is evaluated once per task, whichever tables need it
    assert sorted(n for n in units if n.startswith("eval:base:")) == [
        "eval:base:base",
        "eval:base:harsh_lighting",
        "eval:base:offset_gripper",
    ]
    # batches: half base data, half target data
    assert [m["weight"] for m in stage1.params["base"]] == [0.5] and stage1.params["target"]["weight"] == 0.5


def test_topological_order_puts_every_dependency_first():
    _, units = _units()
    names = order(unit_graph(units))
    assert sorted(names) == sorted(units)
    pos = {n: i for i, n in enumerate(names)}
    assert all(pos[d] < pos[n] for n in names for d in units[n].deps)
