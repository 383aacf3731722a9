"""The report's tables and findings on hand-made records with known answers."""

from __future__ import annotations

import tomllib

import pytest

from nsl.study.plan import parse_plan
from nsl.study.report import (
    Count,
    challenge_table,
    continual_table,
    diff_interval,
    early_stop_table,
    findings,
    render,
    tiers_table,
)

from .conftest import MINI_PLAN


def c(successes: int, episodes: int = 100) -> dict:
    return {"successes": successes, "episodes": episodes}


def _curve(points):
    """Curve rows: (step, target successes, base successes, softopc, auc) out of 100 episodes each."""
    rows = []
    for step, t, b, softopc, auc in points:
        rows.append(
            {
                "step": step,
                "target_success": t / 100,
                "target_episodes": 100,
                "base_success": b / 100,
                "base_episodes": 100,
                "softopc": softopc,
                "auc": auc,
                "td_error": None,
            }
        )
    return rows


def records(**changes) -> dict:
    plan = parse_plan(tomllib.loads(MINI_PLAN), default_name="mini").to_dict()
    rec = {
        "study": "mini",
        "plan": plan,
        "base_policy": {"base": c(80), "harsh_lighting": c(20), "offset_gripper": c(75)},
        "finetune": {
            "harsh_lighting": {
                "tiers": {"4": [c(40)], "8": [c(70)]},
                "tiers_base": {"4": [c(80)], "8": [c(78)]},
                "baselines": {"scratch": [c(10)]},
                "baselines_base": {"scratch": [c(5)]},
            },
            "offset_gripper": {
                "tiers": {"4": [c(75)], "8": [c(85)]},
                "tiers_base": {"4": [c(79)], "8": [c(81)]},
                "baselines": {"scratch": [c(60)]},
                "baselines_base": {"scratch": [c(30)]},
            },
        },
        "continual": {
            "tasks": ["base", "harsh_lighting", "offset_gripper"],
            "stages": ["base policy", "harsh_lighting", "offset_gripper"],
            "cells": [[c(80), c(20), c(75)], [c(78), c(70), c(70)], [c(72), c(66), c(84)]],
            "single": {"harsh_lighting": c(70), "offset_gripper": c(80)},
        },
        "curves": {"ft": {"0": _curve([(0, 20, 80, None, None), (5, 50, 78, None, None), (10, 60, 77, None, None)])}},
        "early_stop": _curve([(0, 75, 80, 0.01, 0.55), (5, 90, 79, 0.05, 0.70), (10, 70, 70, 0.08, 0.60)]),
    }
    rec.update(changes)
    return rec


def test_newcombe_interval_contains_the_difference_and_matches_a_known_value():
    d, lo, hi = diff_interval(
        Count(56, 70), Count(48, 80)
    )  # Newcombe 1998, Table II example (h): 0.2, [0.0524, 0.3339]
    assert d == pytest.approx(0.2)
    assert lo == pytest.approx(0.0524, abs=5e-4) and hi == pytest.approx(0.3339, abs=5e-4)


def test_tables_have_one_row_per_task_and_the_study_beside_ours():
    rec = records()
    rows = [r for r in challenge_table(rec).splitlines()[2:]]
    assert len(rows) == 3
    assert rows[1].startswith("| harsh lighting | 20% [") and "| -60 [" in rows[1] and rows[1].endswith("| 31% | -55 |")
    tiers = tiers_table(rec).splitlines()
    assert tiers[0] == "| challenge |  | base policy | 4 | 8 | scratch (8) |"
    assert len(tiers) == 2 + 4 and tiers[3].startswith("|  | study | 32% | - | - | 4% |")
    cont = continual_table(rec).splitlines()
    assert len(cont) == 2 + 3
    # stage 1 (harsh lighting) on its own task 70% vs base policy 20%: +50; vs single (70%): +0; final 66%
    assert "| harsh lighting | 70% [" in cont[2] and "| +50 [" in cont[2] and "| +0 [" in cont[2]
    assert cont[2].endswith("| 63% | +0 |")


def test_findings_on_known_inputs():
    f = {x.key: x for x in findings(records())}
    # (a) offset gripper drops only 5 points (80 -> 75): fails, with the numbers
    assert f["a"].holds is False and "offset gripper +5 [" in f["a"].ours
    # (b) gains at tier 8: +50 and +10 -> mean +30 >= +27; reaches 80% base-task success on 1 of 2 (>= 2/5 of 2)
    assert f["b"].holds is True and "mean +30 points" in f["b"].ours and "on 1 of 2" in f["b"].ours
    # (c) FT - scratch: +60 and +25 -> not every shift >= 30
    assert f["c"].holds is False and "offset gripper +25 [" in f["c"].ours
    # (d) base task 80% -> 72%: lost 8 points > 5
    assert f["d"].holds is False and "lost +8 [" in f["d"].ours
    # (e) best at step 5 (90%); softopc picks 10 (70%, 20 below), auc picks 5 (0 below); td made no choice
    assert f["e"].holds is True and "auc: step 5" in f["e"].ours and "td: no choice" in f["e"].ours


def test_findings_that_cannot_be_measured_say_so():
    rec = records(early_stop=_curve([(0, 75, 80, None, None), (5, 90, 79, None, None)]))
    rec["base_policy"]["offset_gripper"] = None
    f = {x.key: x for x in findings(rec)}
    assert f["a"].holds is None and f["e"].holds is None and f["e"].verdict == "not measured"
    assert "softopc: no choice" in f["e"].ours
    table = early_stop_table(rec)
    assert "| td | no choice | - | - | - |" in table and "| softopc | no choice |" in table


def test_render_states_the_epsilon_and_every_section():
    text = render(records(), {"units": {"a": {"state": "done", "seconds": 60}}}, {})
    assert "**epsilon 0.1**" in text
    for heading in (
        "## Findings",
        "## Challenge table (Table 5.1)",
        "## Fine-tuning by data size (Table 5.2)",
        "## The continual sequence (Table 5.3)",
        "## Method curves",
        "## Overfitting and early stopping",
    ):
        assert heading in text


def test_a_study_in_progress_reports_what_it_has():
    rec = records()
    rec["base_policy"] = dict.fromkeys(rec["base_policy"])
    for row in rec["finetune"].values():
        for part in row.values():
            for k in part:
                part[k] = [None]
    rec["continual"]["cells"] = [[None] * 3 for _ in range(3)]
    rec["continual"]["single"] = dict.fromkeys(rec["continual"]["single"])
    rec["curves"] = {"ft": {"0": None}}
    rec["early_stop"] = None
    assert all(f.holds is None for f in findings(rec))
    text = render(rec, None, {})
    assert "(no continual results yet)" in text and "(no early-stopping curve yet)" in text
    assert "| harsh lighting | ours | - | - | - | - |" in text


def test_a_calibrated_severity_keeps_the_study_figures_beside_ours():
    plan = tomllib.loads(MINI_PLAN.replace('"offset_gripper"]', '"offset_gripper@0.35"]', 1))
    rec = records(
        plan=parse_plan(plan, default_name="mini").to_dict(),
        base_policy={"base": c(80), "harsh_lighting": c(20), "offset_gripper@0.35": c(40)},
    )
    rec["finetune"] = {"offset_gripper@0.35" if k == "offset_gripper" else k: v for k, v in rec["finetune"].items()}
    row = challenge_table(rec).splitlines()[-1]
    assert row.startswith("| offset gripper@0.35 | 40% [") and row.endswith("| 47% | -39 |")
    tiers = tiers_table(rec).splitlines()
    assert tiers[-1].startswith("|  | study | 43% |")  # the study's offset-gripper row under the calibrated shift
    (a,) = [x for x in findings(rec) if x.key == "a"]
    assert a.study.startswith("drops of harsh lighting 55; offset gripper 39 points")
