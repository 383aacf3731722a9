"""The report's tables and findings on hand-made records with known answers."""

from __future__ import annotations

import copy
import tomllib

import pytest

from nsl.study import reference as ref
from nsl.study.plan import parse_plan
from nsl.study.report import (
    Count,
    challenge_table,
    continual_table,
    diff_interval,
    early_stop_table,
    findings,
    render,
    tiers_base_table,
    tiers_table,
)

from .conftest import MINI_PLAN


def c(successes: int, episodes: int = 100) -> dict:
    return {"successes": successes, "episodes": episodes}


def _curve(points, episodes: int = 100):
    """Curve rows: (step, target successes, base successes, softopc, auc) out of ``episodes`` episodes each."""
    rows = []
    for step, t, b, softopc, auc in points:
        rows.append(
            {
                "step": step,
                "target_success": t / episodes,
                "target_episodes": episodes,
                "base_success": b / episodes,
                "base_episodes": episodes,
                "softopc": softopc,
                "auc": auc,
                "td_error": None,
            }
        )
    return rows


# The hand-made records below hold one baseline and no cross-shift evaluations.
RECORDS_PLAN = MINI_PLAN.replace(
    'baselines = ["scratch", "scratch_target", "no_target", "supervised"]', 'baselines = ["scratch"]'
).replace("cross_shift = true\n", "")


def records(**changes) -> dict:
    plan = parse_plan(tomllib.loads(RECORDS_PLAN), default_name="mini").to_dict()
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
    # the study's own stage, and against its single-step baseline: the best tier of Table 5.2 (and the 800 tier)
    assert cont[2].endswith("| 63% | +0 (vs 63% at 800); +0 vs 800's 63% |")
    assert "study: own stage, each on its own task (Fig. 5.5)" in cont[0]


def test_findings_on_known_inputs():
    f = {x.key: x for x in findings(records())}
    # (a) offset gripper drops only 5 points (80 -> 75): fails, with the numbers
    assert f["a"].holds is False and "offset gripper +5 [" in f["a"].ours
    # (b) gains at tier 8: +50 and +10 -> mean +30; the study's on these shifts: (63-32 + 98-43) / 2 = +43, with
    # N=50 per cell sd sqrt((.63*.37 + .32*.68 + .98*.02 + .43*.57) / 50) / 2 = 6.0 points -> [+31.3, +54.7];
    # ours [+21.4, +37.6]: the difference's interval [-27.5, +0.9] holds 0 -> not resolvable
    assert f["b"].holds is None and f["b"].verdict == "not resolvable"
    assert "mean +30 points" in f["b"].ours and "on 1 of 2" in f["b"].ours
    assert "+43.0 [+31.3, +54.7]" in f["b"].ours and "ours +30.0 [+21.4, +37.6]" in f["b"].ours
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
    # the Table 5.2 paragraph reads in order, from the recipe to the baselines to the table
    assert "ImageNet column), the trunk trained and frozen." in text and "the trunk  Success" not in text


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


# The `full` plan's shifts, in its order (which is not the order of the reference tables).
FULL_SHIFTS = (
    "harsh_lighting@2",
    "transparent_objects@0.8",
    "checkerboard_backing@0.4",
    "extend_gripper@2",
    "offset_gripper@0.25",
)


def shift_records(shifts) -> dict:
    """The hand-made records with the plan's shifts replaced (each shift gets harsh lighting's fine-tune row)."""
    plan = tomllib.loads(MINI_PLAN)
    plan["shifts"] = list(shifts)
    row = records()["finetune"]["harsh_lighting"]
    return records(
        plan=parse_plan(plan, default_name="mini").to_dict(),
        base_policy={"base": c(80), **{s: c(40) for s in shifts}},
        finetune={s: copy.deepcopy(row) for s in shifts},
    )


@pytest.mark.parametrize("shifts", [FULL_SHIFTS, FULL_SHIFTS[::-1], ("offset_gripper", "checkerboard_backing@0.4")])
def test_every_findings_study_column_walks_the_reference_in_the_plans_shift_order(shifts):
    f = {x.key: x for x in findings(shift_records(shifts))}
    names = [s.split("@")[0] for s in shifts]
    pretty = [n.replace("_", " ") for n in names]
    top = ref.TIERS[-1]
    # (a) Table 5.1: 86% minus each challenge, and their range
    drops = [ref.BASE_TASK - ref.CHALLENGE[n] for n in names]
    listed = "; ".join(f"{p} {d}" for p, d in zip(pretty, drops, strict=True))
    assert f["a"].study == f"drops of {listed} points ({min(drops)}-{max(drops)})"
    # (b) Table 5.2: 800 attempts minus the base policy, then who reached the base task's 86%
    gains = [ref.FINETUNE[n][top] - ref.FINETUNE[n]["base"] for n in names]
    listed = "; ".join(f"{p} {g:+d}" for p, g in zip(pretty, gains, strict=True))
    assert f["b"].study.startswith(f"gains at {top} attempts: {listed} points (mean {sum(gains) / len(gains):+.0f}")
    reached = [p for p, n in zip(pretty, names, strict=True) if ref.FINETUNE[n][top] >= ref.BASE_TASK]
    reached_text = f"{len(reached)} of {len(names)} reached its base-task {ref.BASE_TASK}% ({', '.join(reached)})"
    assert reached_text in f["b"].study
    # (c) Table 5.2: 800 attempts minus scratch (the mini plan's top tier is 8, so the study's tier is named)
    over = ", ".join(f"{ref.FINETUNE[n][top] - ref.FINETUNE[n]['scratch']:+d}" for n in names)
    assert f["c"].study == f"{over} points (at {top} attempts)"
    # (d) Table 5.3's text; (e) Fig. 5.7, on the study's own shift
    assert f["d"].study == ref.NO_FORGETTING
    assert ref.EARLY_STOP in f["e"].study and f"{ref.EARLY_STOP_SHIFT.replace('_', ' ')}, 400 attempts" in f["e"].study


def test_the_full_plans_study_columns_are_the_studys_figures_in_plan_order():
    f = {x.key: x for x in findings(shift_records(FULL_SHIFTS))}
    assert f["a"].study.endswith("extend gripper 10; offset gripper 39 points (10-55)")
    assert "harsh lighting +31; transparent objects +17; checkerboard backing +40" in f["b"].study
    assert "(mean +27); 2 of 5 reached its base-task 86% (checkerboard backing, offset gripper)" in f["b"].study
    assert f["c"].study.startswith("+59, +39, +90, +69, +61 points")
    # a plan with some of the shifts: the study's mean over these, and its own over the five
    f = {x.key: x for x in findings(records())}
    assert "harsh lighting +31; offset gripper +55 points (mean +43; +27 over its 5 shifts)" in f["b"].study


def test_the_base_task_table_keeps_the_studys_base_task_fine_tune_apart():
    table = tiers_base_table(records())
    rows = [r for r in table.splitlines() if r.startswith("|")]
    assert len(rows) == 2 + 2 and not any("study" in r for r in rows)
    note = table.splitlines()[-1]
    study = ref.FINETUNE["base"]
    assert "a fine-tune on base-task data" in note and "not comparable to this table" in note
    assert f"(base policy {study['base']}%, 25: {study[25]}%," in note and f"800: {study[800]}%" in note
    assert note in render(records(), None, {})


def test_early_stopping_says_when_the_scenes_cannot_resolve_a_difference():
    # 50 scenes per point: best 62% at step 5; SoftOPC and AUC choose step 10 at 54%, 8 points below: noise
    curve = [(0, 28, 44, 0.01, 0.5), (5, 31, 44, 0.02, 0.55), (10, 27, 40, 0.08, 0.70)]
    (e,) = [x for x in findings(records(early_stop=_curve(curve, episodes=50))) if x.key == "e"]
    assert e.holds is None and "(50 scenes per point)" in e.ours
    assert "softopc: step 10, 54% [" in e.ours and "8 [-11, +26] points below: not resolvable at 50 scenes" in e.ours
    assert e.ours.endswith("the differences cannot be resolved at 50 scenes per point")
    # 100 scenes, 20 points below: resolvably more than 5 points below on every criterion -> fails
    curve = [(0, 75, 80, 0.01, 0.5), (5, 90, 79, 0.02, 0.55), (10, 70, 70, 0.08, 0.70)]
    (e,) = [x for x in findings(records(early_stop=_curve(curve))) if x.key == "e"]
    assert e.holds is False and e.ours.count("20 [+9, +31] points below: more than 5 points below") == 2
    # 2,000 scenes, 0.2 points below: resolvably within 5 points -> holds
    curve = [(0, 1500, 1600, 0.01, 0.5), (5, 1800, 1600, 0.02, 0.55), (10, 1796, 1600, 0.08, 0.70)]
    (e,) = [x for x in findings(records(early_stop=_curve(curve, episodes=2000))) if x.key == "e"]
    assert e.holds is True and "points below: within 5 points" in e.ours and "(2000 scenes per point)" in e.ours


def test_seed_means_come_with_a_t_interval_and_the_cross_shift_table_finds_forgetting():
    from nsl.study.report import cross_shift_table, seed_mean, seeds_cell

    # three seeds of 100 scenes: 60, 70, 80% -> mean 70, t(2) 4.303 * 10 / sqrt(3) = 24.8 points
    mean, half = seed_mean([c(60), c(70), c(80)])
    assert mean == pytest.approx(0.70) and half == pytest.approx(4.3027 * 0.10 / 3**0.5, rel=1e-3)
    assert seeds_cell([c(60), c(70), c(80)]) == "70% ±25 (seeds only)"  # no per-scene outcomes recorded
    assert seeds_cell([c(70)]) == "70% [60-78]" and seeds_cell([c(70), None]) == "-"
    rec = records()
    rec["plan"]["finetune"]["cross_shift"] = True
    rec["finetune"]["harsh_lighting"]["cross_shift"] = {"harsh_lighting": [c(70)], "offset_gripper": [c(45)]}
    rec["finetune"]["offset_gripper"]["cross_shift"] = {"harsh_lighting": [c(10)], "offset_gripper": [c(85)]}
    rows = cross_shift_table(rec).splitlines()
    assert rows[2].startswith("| base policy | 20% [") and rows[3].startswith("| harsh lighting | 70% [")
    assert "45% [" in rows[3] and "(-30 [" in rows[3]  # offset gripper: 75% -> 45%
    f = {x.key: x for x in findings(rec)}["f"]
    # off the diagonal: harsh -> offset -30, offset -> harsh -10: mean -20
    assert f.holds is True and f.ours.startswith("-20.0 points on average over 2")


def test_cells_with_outcomes_on_the_same_scenes_get_the_paired_interval():
    from nsl.study.report import Count, diff_interval, pooled

    # 100 scenes: the fine-tune succeeds wherever the base does, and on 20 more
    base = Count(50, 100, "1" * 50 + "0" * 50)
    tuned = Count(70, 100, "1" * 70 + "0" * 30)
    d, lo, hi = diff_interval(tuned, base)
    _, lo_ind, hi_ind = diff_interval(Count(70, 100), Count(50, 100))
    assert d == pytest.approx(0.20) and lo_ind < lo < 0.20 < hi < hi_ind  # pairing narrows the interval
    # three seeds pooled against one evaluation of the same scenes: the base's scenes repeat per seed
    seeds = pooled([tuned.to_dict()] * 3)
    assert seeds is not None and len(seeds.outcomes) == 300
    d3, lo3, hi3 = diff_interval(seeds, base)
    assert d3 == pytest.approx(0.20) and lo3 > lo
    # one cell without outcomes, or scenes that do not line up: the independent interval
    assert diff_interval(Count(70, 100), base)[1:] == (lo_ind, hi_ind)
    assert diff_interval(Count(70, 100, "1" * 70 + "0" * 30), Count(50, 80, "1" * 50 + "0" * 30))[1] < lo


def test_finding_b_gives_the_mean_gain_over_seeds_with_its_t_interval():
    from nsl.study.report import mean_gain_over_seeds

    rec = records()
    assert mean_gain_over_seeds(rec, "8") is None  # one seed: no interval over seeds
    assert " seeds " not in {x.key: x for x in findings(rec)}["b"].ours
    # harsh 20% -> 70, 60, 80 (gains 50, 40, 60); offset 75% -> 85, 85, 75 (gains 10, 10, 0)
    rec["finetune"]["harsh_lighting"]["tiers"]["8"] = [c(70), c(60), c(80)]
    rec["finetune"]["offset_gripper"]["tiers"]["8"] = [c(85), c(85), c(75)]
    m, half, k = mean_gain_over_seeds(rec, "8")
    # per seed five-shift means 30, 25, 30 -> mean 28.3, sd 2.89, t(2) 4.303: half-width 7.17 points
    assert k == 3 and m == pytest.approx(0.2833, abs=1e-4) and half == pytest.approx(0.0717, abs=1e-4)
    b = {x.key: x for x in findings(rec)}["b"]
    assert b.ours.startswith("mean +28 points [+21.2, +35.5] (mean over 3 seeds +28.3, 95% t interval) (harsh")


def test_the_continual_sequence_with_seeds_gives_seed_means_and_finding_d_their_t_interval():
    rec = records()
    # three sequences: each seed's stages on (base, harsh, offset); the pooled cells are their sums
    seeds = [
        [[c(78), c(70), c(70)], [c(72), c(66), c(84)]],
        [[c(80), c(60), c(72)], [c(80), c(64), c(80)]],
        [[c(76), c(80), c(68)], [c(76), c(68), c(88)]],
    ]
    rec["continual"]["seeds"] = seeds
    rec["continual"]["single_seeds"] = {"harsh_lighting": [c(70), c(72), c(68)], "offset_gripper": [c(80)] * 3}
    rec["continual"]["cells"] = [
        [c(240, 300), c(60, 300), c(225, 300)],
        [c(234, 300), c(210, 300), c(210, 300)],
        [c(228, 300), c(198, 300), c(252, 300)],
    ]
    rec["base_policy"]["base"] = c(240, 300)
    rows = continual_table(rec).splitlines()
    # harsh lighting's own stage: 70, 60, 80 -> 70% ±25; its final: 66, 64, 68 -> 66% ±5
    assert rows[2].startswith("| harsh lighting | 70% ±25 (seeds only) |") and "| 66% ±5 (seeds only) |" in rows[2]
    d = {x.key: x for x in findings(rec)}["d"]
    # the base task: 80% before; after the last stage 72, 80, 76 -> lost 8, 0, 4: mean 4.0, t half-width 9.9
    assert d.holds is True and "(mean over 3 seeds +4.0 [-5.9, +13.9], 95% t interval)" in d.ours


def test_the_weight_change_table_and_plot_give_each_layer_per_shift(tmp_path):
    from PIL import Image

    from nsl.study.report import plot_weight_change, weight_change_table

    records = {
        "weight_change": {
            "harsh_lighting": {"conv.0": 2.5, "head.0": 0.75},
            "offset_gripper": {"conv.0": 1.0, "head.0": 3.0},
        }
    }
    rows = [ln.split("|")[1:-1] for ln in weight_change_table(records).splitlines()[2:]]
    assert [[c.strip() for c in r] for r in rows] == [["conv.0", "2.50", "1.00"], ["head.0", "0.75", "3.00"]]
    png = plot_weight_change(records, tmp_path / "wc.png")
    assert Image.open(png).size[0] > 400
    assert "no weight changes yet" in weight_change_table({})


def test_finding_g_compares_rl_pre_training_with_supervised_features_trained_and_frozen():
    plan = parse_plan(
        tomllib.loads(
            RECORDS_PLAN.replace(
                'baselines = ["scratch"]', 'baselines = ["scratch", "supervised", "supervised_frozen"]'
            )
        ),
        default_name="mini",
    ).to_dict()
    rec = records(plan=plan)
    rows = rec["finetune"]
    rows["harsh_lighting"]["baselines"].update(supervised=[c(30)], supervised_frozen=[c(5)])
    rows["offset_gripper"]["baselines"].update(supervised=[c(80)], supervised_frozen=[c(20)])
    g = {f.key: f for f in findings(rec)}["g"]
    # offset gripper: 85% against 80% on 100 scenes cannot be told apart, so the claim fails to hold everywhere
    assert g.holds is False
    assert g.ours.startswith("harsh lighting RL 70% [") and "trained 30% [" in g.ours and "frozen 5% [" in g.ours
    assert g.study.startswith("harsh lighting 63% against 2%, offset gripper 98% against 47%; frozen 0%")
    rows["offset_gripper"]["baselines"]["supervised"] = [c(40)]
    assert {f.key: f for f in findings(rec)}["g"].holds is True
    # the features' own accuracy joins our side of the finding once recorded
    rec["features"] = {"classes": 899, "heldout_accuracy": 0.002, "train_accuracy": 0.034, "chance": 1 / 899,
                       "final_loss": 6.22}  # fmt: skip
    assert {f.key: f for f in findings(rec)}["g"].ours.endswith(
        "The supervised trunk classifies 0.2% of held-out frames of the 899 train objects (chance 0.11%; 3.4% of "
        "its training frames, final loss 6.22)."
    )
    # a trunk trained on the pose label: its held-out error against predicting the mean
    rec["features"] = {"pose_labels": ["u", "v", "h"], "heldout_pose_error_ratio": 0.31,
                       "heldout_pose_error_ratios": [0.2, 0.25, 0.48], "train_pose_error_ratio": 0.12,
                       "final_loss": 0.2}  # fmt: skip
    assert {f.key: f for f in findings(rec)}["g"].ours.endswith(
        "The supervised trunk locates the object relative to the camera on held-out frames with 0.31 of the squared "
        "error of predicting the mean (u 0.20, v 0.25, h 0.48; 0.12 on its training frames; at most 0.5 counts as "
        "learned)."
    )
    del rows["offset_gripper"]["baselines"]["supervised_frozen"]
    assert {f.key: f for f in findings(rec)}["g"].holds is None  # not measured everywhere yet
    table = tiers_table(rec).splitlines()
    assert table[0].endswith("| supervised (8) | supervised_frozen (8) |")
    assert table[3].endswith("| 2% | 0% |")  # the study's ImageNet column and its frozen 0%


def test_online_table_findings_and_plot_from_hand_made_rounds(tmp_path):
    from nsl.study.report import online_table, plot_online

    plan = parse_plan(tomllib.loads(RECORDS_PLAN), default_name="mini").to_dict()

    def run(method, ratio, successes):
        return {"method": method, "ratio": ratio, "grasps": [0, 4, 8], "success": [c(s) for s in successes]}

    online = {
        "ft@0.5": run("ft", 0.5, [20, 60, 78]),
        "new_head@0.5": run("new_head", 0.5, [20, 25, 30]),
        "ft@0.99": run("ft", 0.99, [20, 75, 80]),
    }
    rec = records(plan=plan, online=online)
    f = {x.key: x for x in findings(rec)}
    # ft ends at 78%, inside the base's interval (80% of 100); a new head at 30%, resolvably below
    assert f["h"].holds is True and "first within its interval after 8 grasps" in f["h"].ours
    assert f["h"].study.startswith("with all parameters the base's level after about 5,000 grasps")
    # 99% against 1% target data is not in the plan's records: only one ratio run of the sweep
    assert "i" not in f
    online["ft@0.01"] = run("ft", 0.01, [20, 30, 35])
    plan["online"]["ratios"] = [0.01, 0.99]
    i = {x.key: x for x in findings(rec)}["i"]
    assert i.holds is True and i.ours.startswith("over rounds 1-2: 99% target data 78% [")
    online["new_head@0.5"] = run("new_head", 0.5, [20, 70, 77])
    assert {x.key: x for x in findings(rec)}["h"].holds is False
    table = online_table(rec).splitlines()
    assert table[0] == "| round 1's method | target share | 0 grasps | 4 grasps | 8 grasps |"
    assert table[2].startswith("| ft | 50% | 20% [") and len(table) == 6
    assert plot_online(rec, tmp_path / "online.png").stat().st_size > 1000


def test_finding_j_asks_whether_every_shift_moves_the_conv_layers_more_than_the_base_task():
    wc = {
        "harsh_lighting": {"columns.0.convs.0": 2.0, "columns.0.convs.1": 1.5, "columns.0.out": 0.5},
        "offset_gripper": {"columns.0.convs.0": 1.4, "columns.0.convs.1": 0.8, "columns.0.out": 3.0},
    }
    j = {f.key: f for f in findings(records(weight_change=wc))}["j"]
    assert j.holds is True  # conv means 1.75 and 1.10: both above the base-task fine-tune's 1
    assert "harsh lighting 1.75x, offset gripper 1.10x" in j.ours and "offset gripper" in j.study
    wc["offset_gripper"]["columns.0.convs.0"] = 1.0  # conv mean 0.90: the head moved, the convs less than 1
    assert {f.key: f for f in findings(records(weight_change=wc))}["j"].holds is False
    assert {f.key: f for f in findings(records())}["j"].holds is None  # no weight changes recorded yet


def test_a_pooled_cell_counts_each_scene_once():
    """Three seeds with the same outcomes on 100 scenes against the base: the old pairing (the base repeated three
    times, 300 pairs) was narrower than one seed's 100 pairs; now the interval is about one seed's."""
    from nsl.stats import newcombe_paired_interval, paired_counts
    from nsl.study.report import Count, diff_interval, mean_curve, pooled, rate_interval

    ft = "1" * 70 + "0" * 30
    base = "1" * 50 + "0" * 50
    one = {"successes": 70, "episodes": 100, "outcomes": ft}
    cell = pooled([one, one, one])
    assert cell.runs == 3 and cell.scenes == 100 and cell.to_dict()["runs"] == 3
    d, lo, hi = diff_interval(cell, Count(50, 100, base))
    single = newcombe_paired_interval(*paired_counts(ft, base))
    triple = newcombe_paired_interval(*paired_counts(ft * 3, base * 3))
    assert d == pytest.approx(0.20)
    assert hi - lo > 0.85 * (single[1] - single[0]) > triple[1] - triple[0]
    # a pooled rate: 3 x 100 outcomes, but 100 scenes
    lo_r, hi_r = rate_interval(cell)
    assert hi_r - lo_r > 0.85 * (wilson(70, 100)[1] - wilson(70, 100)[0])
    # the method curves: ten seeds at 18 of 30 scenes -> Wilson over 30 scenes, about [42-75]
    rows = [{"step": 0, "target_success": 0.6, "target_episodes": 30}]
    pts = mean_curve({str(s): rows for s in range(10)}, "target")
    assert pts[0][1].pct() == "60% [42-75]"


def wilson(k, n):
    from nsl.stats import wilson_interval

    return wilson_interval(k, n)


def test_the_headline_covers_collections_seeds_and_scenes_and_judges_finding_b_against_the_source():
    """Two shifts, 2 target collections x 3 seeds on 100 scenes with per-scene outcomes: the report's headline is
    ``hierarchical_mean_gain`` of exactly those outcomes, its section names what it covers, and finding (b) uses
    it against the study's binomial interval."""
    import numpy as np

    from nsl.stats import compare_intervals, hierarchical_gain, hierarchical_mean_gain
    from nsl.study.report import headline_gain, shift_gain
    from nsl.study.report.findings import study_gain_interval

    rng = np.random.default_rng(7)

    def cell(p):
        o = (rng.random(100) < p).astype(int)
        return {"successes": int(o.sum()), "episodes": 100, "outcomes": "".join(map(str, o))}

    rec = records()
    rec["plan"]["finetune"]["seeds"] = [0, 1, 2]
    rec["plan"]["finetune"]["collections"] = [rec["plan"]["collect"]["seed"], 77]
    levels = {
        "harsh_lighting": (0.2, [[0.70, 0.72, 0.66], [0.60, 0.62, 0.64]]),
        "offset_gripper": (0.75, [[0.85] * 3, [0.80] * 3]),
    }
    for shift, (b, colls) in levels.items():
        rec["base_policy"][shift] = cell(b)
        row = rec["finetune"][shift]
        row["tiers"]["8"] = [cell(p) for p in colls[0]]
        row["collections"] = {"77": [cell(p) for p in colls[1]]}
    head = headline_gain(rec)
    ft = np.array(
        [
            [[[ch == "1" for ch in d["outcomes"]] for d in g] for g in (r["tiers"]["8"], r["collections"]["77"])]
            for r in rec["finetune"].values()
        ],
        dtype=np.int8,
    )
    base = np.array([[ch == "1" for ch in rec["base_policy"][s]["outcomes"]] for s in levels], dtype=np.int8)
    want = hierarchical_mean_gain(ft, base)
    assert (head.mean, head.low, head.high) == (want.mean, want.low, want.high)
    assert head.mean == pytest.approx(np.mean([hierarchical_gain(ft[k], base[k]).mean for k in range(2)]))
    assert head.covers() == "2 shifts, 100 scenes, 3 seeds, 2 collections" and head.low < head.mean < head.high
    b = {x.key: x for x in findings(rec)}["b"]
    assert f"mean {100 * head.mean:+.1f} points [{100 * head.low:+.1f}, {100 * head.high:+.1f}]" in b.ours
    assert "against the study's binomial interval" in b.ours and "hierarchical, over 2 shifts" in b.ours
    source = study_gain_interval(rec["plan"]["shifts"])
    assert b.verdict == compare_intervals((head.mean, head.low, head.high), source)
    text = render(rec, None, {})
    assert "## The headline" in text and "2 independent target collections (collection seeds 5, 77)" in text
    # a missing run's outcomes: no headline mean, that shift's row says so, the measured shift keeps its row
    rec["finetune"]["offset_gripper"]["collections"]["77"][0] = c(80)
    text = render(rec, None, {})
    harsh = shift_gain(rec, "harsh_lighting")
    assert headline_gain(rec) is None and "waits for every shift (1 of 2)" in text
    assert f"{100 * harsh.mean:+.1f} [{100 * harsh.low:+.1f}, {100 * harsh.high:+.1f}] (100 scenes" in text
    offset = next(line for line in text.splitlines() if line.startswith("| offset gripper |") and "measured" in line)
    assert offset.endswith("| - | not measured yet | - |")
    for row in rec["finetune"].values():  # no outcomes at all: no headline section
        row["tiers"]["8"] = [c(70)] * 3
    assert "## The headline" not in render(rec, None, {})


def test_the_plasticity_table_gives_each_arm_and_the_paired_contrasts():
    from nsl.study.report import plasticity_table

    text = RECORDS_PLAN + '\n[plasticity]\nshift = "offset_gripper"\nstage = 1\nepisodes = 8\nsteps = 10\n'
    rec = records(plan=parse_plan(tomllib.loads(text), default_name="mini").to_dict())
    assert plasticity_table(rec) == ""  # nothing measured yet

    def cell(k: int, n: int = 200) -> dict:  # the first k of n scenes succeed
        return {"successes": k, "episodes": n, "outcomes": "1" * k + "0" * (n - k)}

    # the stage policy as a start costs 20 points whatever the data; its data costs nothing
    rates = {"base/base": 140, "base/stage": 140, "stage/base": 100, "stage/stage": 100, "stage-sp/base": 130}
    rec["plasticity"] = {a: {"shift": [cell(k)] * 3, "base": [cell(160)] * 3} for a, k in rates.items()}
    lines = plasticity_table(rec).splitlines()
    assert lines[2].startswith("| the base | the base's | 70.0% [") and "| 80.0% [" in lines[2]
    assert lines[4].startswith("| the stage 1 policy | the base's | 50.0% [")
    assert lines[6].startswith("| the stage 1 policy, shrunk and perturbed (0.8, 0.01) | the base's | 65.0% [")
    contrasts = {row.split(" | ")[0].strip("| "): row.split(" | ")[1] for row in lines[10:]}
    assert contrasts["start: the base - the stage policy, on the base's episodes"].startswith("+20.0 [")
    assert contrasts["data: the stage 1 policy's - the base's episodes, from the base"] == "+0.0 [+0.0, +0.0] |"
    assert contrasts["shrink and perturb - the stage policy as it is, on the base's episodes"].startswith("+15.0 [")
    assert "## Plasticity or data (finding (d))" in render(rec, None, {})
    del rec["plasticity"]["stage/stage"]  # an arm not measured leaves its row and its contrasts out
    assert "from the stage policy" not in plasticity_table(rec)


def test_the_efficiency_table_finds_the_smallest_tier_where_scratch_reaches_ft():
    from nsl.study.report import efficiency_table

    section = '\n[efficiency]\nshifts = ["harsh_lighting"]\ntiers = [4, 8]\nseeds = [0, 1]\nreference = 8\n'
    rec = records(plan=parse_plan(tomllib.loads(RECORDS_PLAN + section), default_name="mini").to_dict())
    assert efficiency_table(rec) == ""  # nothing measured yet

    def cell(k: int, n: int = 200) -> dict:  # the first k of n scenes succeed
        return {"successes": k, "episodes": n, "outcomes": "1" * k + "0" * (n - k)}

    curve = [
        {"step": 0, "target_success": 0.1},
        {"step": 10, "target_success": 0.3},
        {"step": 20, "target_success": 0.25},
    ]
    rec["efficiency"] = {
        "harsh_lighting": {
            "ft": {"tiers": {"4": [cell(100)] * 2, "8": [cell(140)] * 2}, "curves": {}},
            # scratch is 40 points short with half the data and level with FT at the reference tier
            "scratch": {"tiers": {"4": [cell(60)] * 2, "8": [cell(140)] * 2}, "curves": {"4": [curve, curve]}},
            "scratch_target": {"tiers": {"4": [cell(20)] * 2, "8": [cell(40)] * 2}, "curves": {"8": [None, None]}},
        }
    }
    text = efficiency_table(rec)
    lines = text.splitlines()
    assert lines[0] == "**harsh_lighting**"
    assert lines[4].startswith("| 4 | 50.0% [") and "| 30.0% [" in lines[4] and "| 10.0% [" in lines[4]
    assert "| scratch (base half) | 4 | 10 10 | -5.0 |" in text  # its best at step 10, its last 5 points lower
    assert "- scratch (base half) reaches FT at 8 episodes with 8 (+0.0 [" in text
    assert "1x FT's target data; FT needs 100% of it" in text
    assert "- scratch (target only) does not reach FT at 8 episodes by 8." in text
    assert "## Target data needed from scratch (finding (c))" in render(rec, None, {})
    rec["efficiency"]["harsh_lighting"]["ft"]["tiers"]["8"][1] = None  # FT's reference unmeasured: no verdict
    assert "reaches FT" not in efficiency_table(rec) and "does not reach" not in efficiency_table(rec)


def test_gather_reads_every_efficiency_run_and_scratchs_curves():
    from types import SimpleNamespace

    from nsl.eval.records import CurveRow, Rate
    from nsl.study.plan import load_plan
    from nsl.study.report.gather import gather

    plan = load_plan("efficiency")
    seen = []

    def evaluation(ref, shift, episodes, seed):
        seen.append((ref, shift, episodes, seed))
        return SimpleNamespace(successes=3, episodes=episodes, extra={"outcomes": "1" * 3 + "0" * (episodes - 3)})

    def read_curve_file(name):
        return [CurveRow(0, target=Rate(0.1, 200)), CurveRow(2000, target=Rate(0.4, 200))] if "-n25-" in name else None

    eff = gather(plan, "efficiency", evaluation, read_curve_file)["efficiency"]
    assert set(eff) == {"harsh_lighting@2", "offset_gripper@0.25"}
    offset = eff["offset_gripper@0.25"]
    assert set(offset) == {"ft", "scratch", "scratch_target"}
    assert list(offset["scratch"]["tiers"]) == ["25", "100", "400", "800", "1600", "3200"]
    assert all(len(cells) == 3 and cells[0]["successes"] == 3 for cells in offset["scratch_target"]["tiers"].values())
    assert offset["ft"]["curves"] == {}  # FT keeps no curve
    assert (
        offset["scratch"]["curves"]["25"][0][-1]["target_success"] == 0.4
        and offset["scratch"]["curves"]["100"] == [None] * 3
    )
    assert (
        "ckpt:efficiency-eff-scratch-offset-gripper-0.25-n3200-k8000-s2@latest",
        "offset_gripper@0.25",
        500,
        51425,
    ) in seen
