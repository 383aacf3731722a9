"""The curriculum core on hand-made matrices: arborescences checked against brute force, ties, scratch, bad input."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from nsl.curriculum import (
    SCRATCH,
    TransferMatrix,
    advantage,
    build_curriculum,
    load_matrix,
    matrix_from_dict,
    plot_curriculum,
    rank_correlation,
    save_matrix,
)
from nsl.errors import ConfigError, CorruptDataError, UnknownReferenceError


def _matrix(tasks, values, base=None):
    """``values[src][dst]``; every ordered pair not given is 0.5."""
    adv = {(s, d): values.get(s, {}).get(d, 0.5) for s in tasks for d in tasks if s != d}
    return TransferMatrix(tuple(tasks), adv, base=base)


def _brute_force(m: TransferMatrix, tasks):
    """Every parent assignment that forms an arborescence rooted at scratch -> {parents: total advantage}."""
    out = {}
    for choice in itertools.product(*[[SCRATCH, *[s for s in tasks if s != t]] for t in tasks]):
        parent = dict(zip(tasks, choice))
        ok = True
        for t in tasks:  # following parents must reach scratch without a cycle
            seen, v = set(), t
            while v != SCRATCH and v not in seen:
                seen.add(v)
                v = parent[v]
            ok &= v == SCRATCH
        if ok:
            out[tuple(choice)] = sum(m.get(parent[t], t) for t in tasks)
    return out


def test_known_optimum_is_a_chain_through_the_best_transfers():
    m = _matrix(["a", "b", "c"], {"a": {"b": 3.0, "c": 1.5}, "b": {"c": 2.5}})
    cur = build_curriculum(m)
    assert dict(cur.optimal.parent) == {"a": SCRATCH, "b": "a", "c": "b"}
    assert cur.optimal.cost == pytest.approx(-(1.0 + 3.0 + 2.5))
    assert cur.optimal.order(cur.tasks) == ["a", "b", "c"]
    # pessimal: every in-edge of the least advantage (0.5) that still forms a tree rooted at scratch
    assert cur.pessimal.cost == pytest.approx(-(1.0 + 0.5 + 0.5))
    assert cur.from_scratch == -3.0
    assert cur.from_base is None  # the matrix names no base task


def test_optimal_and_pessimal_match_brute_force_on_random_matrices():
    rng = np.random.default_rng(0)
    tasks = ["t0", "t1", "t2", "t3"]
    for _ in range(20):
        vals = {s: {d: float(rng.choice([0.0, 0.3, 0.8, 1.0, 1.4, 2.0, 3.1])) for d in tasks if d != s} for s in tasks}
        m = _matrix(tasks, vals)
        totals = _brute_force(m, tasks)
        cur = build_curriculum(m)
        assert -cur.optimal.cost == pytest.approx(max(totals.values()))
        assert -cur.pessimal.cost == pytest.approx(min(totals.values()))
        assert tuple(cur.optimal.parent[t] for t in tasks) in totals  # a real arborescence


def test_a_task_with_no_helpful_source_is_learned_from_scratch():
    m = _matrix(["a", "b", "c"], {"a": {"b": 2.0, "c": 0.4}, "b": {"a": 1.2, "c": 0.9}})
    cur = build_curriculum(m)
    assert cur.optimal.parent["c"] == SCRATCH  # every A(x -> c) < 1
    assert cur.optimal.advantage["c"] == 1.0
    # b is best from a (2.0); then a cannot come from b (cycle): a from scratch
    assert dict(cur.optimal.parent) == {"a": SCRATCH, "b": "a", "c": SCRATCH}


def test_scratch_edges_are_used_when_everything_transfers_badly():
    m = _matrix(["a", "b", "c"], {})  # every A = 0.5 < 1
    cur = build_curriculum(m)
    assert set(cur.optimal.parent.values()) == {SCRATCH}
    assert cur.optimal.cost == cur.from_scratch == -3.0
    assert set(cur.pessimal.parent.values()) != {SCRATCH}  # the pessimal tree takes the 0.5 edges


def test_ties_are_broken_deterministically_by_scratch_then_task_order():
    equal = _matrix(["a", "b", "c"], {s: {d: 1.0 for d in "abc"} for s in "abc"})
    assert set(build_curriculum(equal).optimal.parent.values()) == {SCRATCH}  # a tie with scratch: from scratch
    tie = {"a": {"c": 2.0}, "b": {"c": 2.0}}
    assert build_curriculum(_matrix(["a", "b", "c"], tie)).optimal.parent["c"] == "a"
    assert build_curriculum(_matrix(["b", "a", "c"], tie)).optimal.parent["c"] == "b"  # the matrix's task order
    # two symmetric trees (a then b, or b then a): the first task in order comes from scratch
    cyc = _matrix(["a", "b"], {"a": {"b": 5.0}, "b": {"a": 5.0}})
    for _ in range(3):
        assert dict(build_curriculum(cyc).optimal.parent) == {"a": SCRATCH, "b": "a"}
    # differences below 1e-6 count as ties
    near = _matrix(["a", "b", "c"], {"a": {"c": 2.0}, "b": {"c": 2.0 + 1e-9}})
    assert build_curriculum(near).optimal.parent["c"] == "a"


def test_costs_from_base_and_subsets_of_tasks():
    m = _matrix(["base", "x", "y"], {"base": {"x": 2.0, "y": 1.5}, "x": {"y": 3.0}}, base="base")
    cur = build_curriculum(m)
    assert cur.from_base == pytest.approx(-(1.0 + 2.0 + 1.5))
    assert cur.optimal.cost == pytest.approx(-(1.0 + 2.0 + 3.0))
    assert cur.optimal.cost <= cur.from_base <= cur.from_scratch
    sub = build_curriculum(m, ["y", "x"])  # without the base: no all-from-base cost; tasks in matrix order
    assert sub.tasks == ("x", "y") and sub.from_base is None
    assert dict(sub.optimal.parent) == {"x": SCRATCH, "y": "x"}


@pytest.mark.parametrize(
    "data, message",
    [
        (
            {
                "tasks": ["a", "b", "c"],
                "advantage": {"a": {"b": 1.0, "c": 1.0}, "b": {"a": 1.0, "c": 1.0}, "c": {"a": 1.0}},
            },
            r"no entry A\(c -> b\) \(1 missing\)",
        ),
        (
            {"tasks": ["a", "b"], "advantage": {"a": {"b": 1.0}, "b": {"a": 1.0}, "z": {"a": 1.0}}},
            "not square: entry A\\(z -> a\\) names task 'z'",
        ),
        ({"tasks": ["a", "b"], "advantage": {"a": {"b": -0.5}, "b": {"a": 1.0}}}, r"A\(a -> b\) = -0.5 must be"),
        ({"tasks": ["a", "b"], "advantage": {"a": {"b": float("nan")}, "b": {"a": 1.0}}}, "must be a finite number"),
        ({"tasks": ["a", "scratch"], "advantage": {}}, "names the from-scratch root"),
        ({"tasks": "a b", "advantage": {}}, "'tasks' must be a list"),
    ],
)
def test_bad_matrices_are_refused_in_one_line(data, message):
    with pytest.raises(ConfigError, match=message) as e:
        matrix_from_dict(data, "m.json")
    assert "\n" not in str(e.value) and str(e.value).startswith("m.json")


def test_unknown_and_unmeasured_tasks_are_refused():
    m = TransferMatrix(
        ("a", "b", "c"),
        {("a", "b"): 1.0, ("b", "a"): 1.0, ("a", "c"): None, ("c", "a"): 2.0, ("b", "c"): 1.0, ("c", "b"): 1.0},
    )
    with pytest.raises(UnknownReferenceError, match="task 'd' is not in the transfer matrix; its tasks: a, b, c"):
        build_curriculum(m, ["a", "d"])
    with pytest.raises(ConfigError, match=r"no measurement of A\(a -> c\)"):
        build_curriculum(m)
    assert build_curriculum(m, ["a", "b"]).optimal.cost == -2.0  # the subset needs no unmeasured entry
    with pytest.raises(ConfigError, match="repeat a task"):
        build_curriculum(m, ["a", "a"])


def test_matrix_file_round_trip_and_bad_files(tmp_path):
    m = TransferMatrix(
        ("base", "x"),
        {("base", "x"): 1.7, ("x", "base"): None},
        {("base", "x"): (1.1, 2.3)},
        base="base",
        meta={"note": "hand-made"},
    )
    path = save_matrix(m, tmp_path / "matrix.json")
    back = load_matrix(path)
    assert back == m
    assert "| base | - | 1.70 [1.10, 2.30] |" in back.markdown()
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(CorruptDataError, match="not valid JSON"):
        load_matrix(tmp_path / "bad.json")
    (tmp_path / "future.json").write_text(
        json.dumps({"format": "nsl.transfer-matrix", "version": 9, "tasks": [], "advantage": {}})
    )
    with pytest.raises(CorruptDataError, match="up to version 1"):
        load_matrix(tmp_path / "future.json")
    with pytest.raises(ConfigError, match="does not exist; `nsl transfer run PLAN` writes one"):
        load_matrix(tmp_path / "none.json")


def test_advantage_is_paired_by_seed_with_a_floor_and_a_t_interval():
    a = advantage({0: 0.6, 1: 0.4}, {0: 0.3, 1: 0.2}, floor=0.05)
    assert a.per_seed == {0: pytest.approx(2.0), 1: pytest.approx(2.0)} and a.value == pytest.approx(2.0)
    assert a.interval == (pytest.approx(2.0), pytest.approx(2.0))  # no spread over seeds
    b = advantage({0: 0.6, 1: 0.3}, {0: 0.3, 1: 0.3}, floor=0.05)
    assert b.value == pytest.approx(1.5)
    half = 12.706 * math.sqrt(0.5) / math.sqrt(2)  # t(0.975, 1) * sd / sqrt(n); sd of (2, 1) = sqrt(0.5)
    assert b.interval[1] == pytest.approx(1.5 + half, rel=1e-3) and b.interval[0] == 0.0  # clipped at 0
    c = advantage({0: 0.2}, {0: 0.0, 1: 0.5}, floor=0.1)  # seed 1 has no fine-tune: unpaired, left out
    assert c.value == pytest.approx(2.0) and c.floored == (0,) and c.interval is None
    assert advantage({}, {0: 0.2}, floor=0.1).value is None
    with pytest.raises(ConfigError, match="out of range"):
        advantage({0: 1.5}, {0: 0.5}, floor=0.1)
    with pytest.raises(ConfigError, match="floor"):
        advantage({0: 0.5}, {0: 0.5}, floor=0.0)


def test_rank_correlation_over_pairs_and_within_targets():
    adv = {("a", "x"): 1.0, ("b", "x"): 2.0, ("c", "x"): 3.0, ("a", "y"): 0.5, ("b", "y"): 0.7, ("c", "y"): 0.6}
    same = rank_correlation(dict(adv), adv)
    assert same.rho == pytest.approx(1.0) and same.n == 6 and same.within_target == pytest.approx(1.0)
    flipped = rank_correlation({p: -v for p, v in adv.items()}, adv)
    assert flipped.rho == pytest.approx(-1.0)
    partial = rank_correlation({("a", "x"): 0.1, ("b", "x"): 0.2, ("z", "z2"): 0.3}, adv)
    assert partial.n == 2 and partial.rho is None and "undefined (2 pairs" in str(partial)


def test_the_picture_is_a_png_of_both_trees(tmp_path):
    from PIL import Image

    m = _matrix(["base", "x", "y"], {"base": {"x": 2.0, "y": 1.5}, "x": {"y": 3.0}}, base="base")
    path = plot_curriculum(build_curriculum(m), tmp_path / "sub" / "tree.png")
    with Image.open(path) as im:
        assert im.format == "PNG" and im.size[0] > 600
