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
    # one base-policy collection per shift (and of the base task: finetune.base_task); tiers, curves and early
    # stopping are views of it (online rounds after the first collect with their own policies)
    collects = sorted(n for n in units if n.startswith("collect:") and "online" not in n and "n4" not in n)
    assert collects == [
        "collect:base:base",
        "collect:harsh_lighting:base",
        "collect:offset_gripper:base",
        "collect:offset_gripper:ft-harsh-lighting-n8-k10-s0",
    ]
    tiers = {
        u.params["target"]["tier"]
        for u in units.values()
        if u.kind == "train" and (u.params["target"] or {}).get("collect") == "collect:harsh_lighting:base"
    }
    assert tiers == {4, 8}
    assert {u.params["target"]["tier"] for n, u in units.items() if n.startswith("train:ft-base-")} == {4, 8}
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


def test_baselines_that_separate_the_causes_cross_shift_evaluations_and_seeds():
    text = MINI_PLAN.replace("seeds = [0]\nbaselines", "seeds = [0, 1]\ntier_seeds = [0]\nbaselines").replace(
        "episodes = 8\nsteps = 10\n\n[curves]", "episodes = 8\nsteps = 10\nseed = 3\n\n[curves]"
    )
    plan, units = _units(text)
    trains = {n for n in units if n.startswith("train:ft-harsh-lighting-n")}
    # the top tier has both seeds, the lower tier only tier_seeds; the continual seed 3 adds its own single step
    assert trains == {
        "train:ft-harsh-lighting-n4-k10-s0",
        "train:ft-harsh-lighting-n8-k10-s0",
        "train:ft-harsh-lighting-n8-k10-s1",
        "train:ft-harsh-lighting-n8-k10-s3",
    }
    # scratch: random initialisation, the same 50/50 mix; scratch_target: random initialisation, target data alone
    scratch, alone = (
        units["train:scratch-harsh-lighting-n8-k10-s1"],
        units["train:scratch_target-harsh-lighting-n8-k10-s1"],
    )
    assert scratch.params["method"] == alone.params["method"] == "scratch"
    assert scratch.params["target"]["weight"] == 0.5 and sum(b["weight"] for b in scratch.params["base"]) == 0.5
    assert alone.params["target"]["weight"] == 1.0 and alone.params["base"] == []
    # no_target: the base fine-tuned with the recipe on base data alone, once per seed, evaluated everywhere
    for seed in (0, 1):
        none = units[f"train:no_target-k10-s{seed}"]
        assert none.params["method"] == "ft" and none.params["init"] == "base" and none.params["target"] is None
        assert sum(b["weight"] for b in none.params["base"]) == 1.0
        assert not any(d.startswith("collect:") for d in none.deps)
        for task in ("base", "harsh_lighting", "offset_gripper"):
            assert f"eval:no_target-k10-s{seed}:{task}" in units
    # the top tier's fine-tunes on the other shift (forgetting of shifts); the lower tier only on its own
    assert "eval:ft-harsh-lighting-n8-k10-s1:offset_gripper" in units
    assert "eval:ft-harsh-lighting-n4-k10-s0:offset_gripper" not in units
    # the early-stopping criteria choose on selection scenes; every table reports on the reporting scenes
    es = next(u for n, u in units.items() if n.startswith("train:es-"))
    assert es.params["monitor"]["seed"] == plan.eval.selection_seed != plan.eval.seed
    assert {u.params["seed"] for u in units.values() if u.kind == "eval"} == {plan.eval.seed}
    # a legacy `seed = 3` under [continual] is seeds = [3]: the sequence's tags carry it
    assert plan.continual.seeds == (3,) and "train:c2-offset-gripper-n8-k10-s3" in units
    unit_graph(units)  # still a DAG


def test_independent_target_collections_train_the_top_tier_seeds_and_leave_the_rest_as_it_was():
    import pytest

    from nsl.errors import ConfigError
    from nsl.study.units import top_tier_tags

    text = MINI_PLAN.replace(
        "seeds = [0]\nbaselines", "seeds = [0, 1, 2]\nbaseline_seeds = [0]\ncollections = [5, 77]\nbaselines"
    )
    plan, units = _units(text)
    _, before = _units()
    # the plan's own collection keeps its unit, dataset and tags; the second is named by its collection seed
    assert before["collect:harsh_lighting:base"] == units["collect:harsh_lighting:base"]
    other = units["collect:harsh_lighting:base:c77"]
    assert other.params["seed"] == 77 and other.params["dataset"] == "mini-harsh-lighting-by-base-c77"
    assert other.params["episodes"] == plan.collect.episodes
    assert before["train:ft-harsh-lighting-n8-k10-s0"] == units["train:ft-harsh-lighting-n8-k10-s0"]
    for seed in (0, 1, 2):
        run = units[f"train:ft-harsh-lighting-n8-k10-s{seed}-c77"]
        assert run.params["target"]["collect"] == "collect:harsh_lighting:base:c77"
        assert run.params["target"]["tier"] == 8 and run.params["seed"] == seed
        assert f"eval:ft-harsh-lighting-n8-k10-s{seed}-c77:harsh_lighting" in units
    assert top_tier_tags(plan, "harsh_lighting") == {
        5: [f"ft-harsh-lighting-n8-k10-s{s}" for s in (0, 1, 2)],
        77: [f"ft-harsh-lighting-n8-k10-s{s}-c77" for s in (0, 1, 2)],
    }
    # the lower tiers and the baselines stay on the plan's collection; the baselines keep their seeds
    assert not any(n.startswith("train:ft-harsh-lighting-n4") and n.endswith("-c77") for n in units)
    assert "train:scratch-harsh-lighting-n8-k10-s0" in units and "train:scratch-harsh-lighting-n8-k10-s1" not in units
    assert "train:no_target-k10-s0" in units and "train:no_target-k10-s1" not in units
    unit_graph(units)
    with pytest.raises(ConfigError, match=r"collections = \[6, 77\] leaves out collect.seed = 5"):
        _units(text.replace("collections = [5, 77]", "collections = [6, 77]"))


def test_a_plan_saved_before_settings_were_added_is_still_the_same_plan():
    import json

    from nsl.study.driver import _same_plan

    plan, _ = _units()
    saved = json.loads(json.dumps(plan.to_dict()))  # as plan.json holds it
    for key in ("selection_seed",):
        saved["eval"].pop(key)
    for key in ("tier_seeds", "baseline_seeds", "collections"):
        saved["finetune"].pop(key)
    saved["continual"]["seed"] = saved["continual"].pop("seeds")[0]  # the older form
    assert _same_plan(saved, plan)
    saved["finetune"]["steps"] = 11
    assert not _same_plan(saved, plan)


def test_the_plans_precision_reaches_every_training_unit_and_fp32_leaves_the_units_as_they_were():
    import pytest

    from nsl.errors import ConfigError

    _, fp32 = _units()
    assert all("precision" not in u.params for u in fp32.values())
    _, auto = _units('precision = "auto"\n' + MINI_PLAN)
    assert {u.params["precision"] for u in auto.values() if u.kind == "train"} == {"auto"}
    assert all("precision" not in u.params for u in auto.values() if u.kind != "train")  # acting stays fp32
    with pytest.raises(ConfigError, match="plan precision = 'fp16' is unknown; use one of fp32, bf16, auto"):
        _units('precision = "fp16"\n' + MINI_PLAN)


def test_the_plans_device_reaches_every_training_unit_and_auto_leaves_the_units_as_they_were():
    import pytest

    from nsl.errors import ConfigError

    _, auto = _units()
    assert all("device" not in u.params for u in auto.values())
    _, cuda = _units('device = "cuda"\n' + MINI_PLAN)
    assert {u.params["device"] for u in cuda.values() if u.kind == "train"} == {"cuda"}
    assert all("device" not in u.params for u in cuda.values() if u.kind != "train")  # acting stays on the CPU
    with pytest.raises(ConfigError, match="plan device = 'gpu' is unknown; use one of cpu, cuda, auto"):
        _units('device = "gpu"\n' + MINI_PLAN)


def test_the_plans_learner_reaches_every_training_unit_and_qtopt_leaves_the_units_as_they_were():
    import pytest

    from nsl.errors import UnknownReferenceError

    _, qtopt = _units()
    assert all("learner" not in u.params for u in qtopt.values())
    _, iql = _units('learner = "iql:expectile=0.9"\n' + MINI_PLAN)
    assert {u.params["learner"] for u in iql.values() if u.kind == "train"} == {"iql:expectile=0.9"}
    assert all("learner" not in u.params for u in iql.values() if u.kind != "train")
    with pytest.raises(UnknownReferenceError, match="unknown learner 'sac'"):
        _units('learner = "sac"\n' + MINI_PLAN)


def test_the_estimate_counts_a_bf16_training_unit_at_the_measured_speed_up(monkeypatch):
    import pytest

    from nsl.learners import precision
    from nsl.study.estimate import BF16_STEP_SPEEDUP, unit_seconds

    _, fp32 = _units()
    _, auto = _units('precision = "auto"\n' + MINI_PLAN)
    name = "train:ft-harsh-lighting-n8-k10-s0"
    monkeypatch.setattr(precision, "bf16_supported", lambda: True)
    work = unit_seconds(fp32[name]) - 1.5  # the overhead of a unit
    assert unit_seconds(auto[name]) - 1.5 == pytest.approx(work / BF16_STEP_SPEEDUP)
    monkeypatch.setattr(precision, "bf16_supported", lambda: False)  # auto falls back to fp32
    assert unit_seconds(auto[name]) == unit_seconds(fp32[name])


def test_supervised_baselines_fine_tune_one_features_unit_trained_or_frozen(tmp_path):
    text = MINI_PLAN.replace('"no_target", "supervised"]', '"no_target", "supervised", "supervised_frozen"]')
    plan, units = _units(text)
    features = units["features:features"]
    assert features.kind == "features" and features.params["checkpoint"] == "mini-features"
    assert (features.params["classes"], features.params["frames"], features.params["steps"]) == (3, 3, 4)
    assert features.params["like_ref"] == plan.base  # the base's architecture and recipe
    assert "label" not in features.params  # a classifier's unit is what it was before the pose label
    _, posed = _units(text.replace("[supervised]\n", '[supervised]\nlabel = "pose"\n'))
    assert posed["features:features"].params["label"] == "pose"
    for baseline, method in (("supervised", "new_head"), ("supervised_frozen", "new_head_frozen")):
        u = units[f"train:{baseline}-offset-gripper-n8-k10-s0"]
        assert u.params["method"] == method and u.params["init_ref"] == "ckpt:mini-features@latest"
        assert "features:features" in u.deps and u.params["target"]["weight"] == 0.5
        assert f"eval:{baseline}-offset-gripper-n8-k10-s0:base" in units
    order(unit_graph(units))  # the features come before their fine-tunes
    # without the section, a supervised baseline takes the default features (all 899 objects)
    bare = parse_plan(tomllib.loads(text.replace("[supervised]\nclasses = 3\nframes = 3\nsteps = 4\n", "")))
    assert bare.supervised is not None and bare.supervised.classes == 0
    # and a plan without supervised baselines records no section (its identity is unchanged)
    plain = parse_plan(
        tomllib.loads(
            text.replace(', "supervised", "supervised_frozen"]', "]").replace(
                "[supervised]\nclasses = 3\nframes = 3\nsteps = 4\n", ""
            )
        )
    )
    assert "supervised" not in plain.to_dict()


def test_online_rounds_chain_collection_and_fine_tuning_over_every_rounds_data():
    text = MINI_PLAN.replace("rounds = 2\n", "rounds = 3\n")
    plan, units = _units(text)
    # round 1 at half target data is Table 5.2's fine-tune on the base policy's first 4 episodes: one unit
    r1 = units["train:ft-harsh-lighting-n4-k10-s0"]
    assert r1.params["method"] == "ft" and r1.params["target"]["tier"] == 4 and r1.params["init"] == "base"
    r2 = units["train:online-ft-p50-harsh-lighting-r2-k10-s0"]
    r3 = units["train:online-ft-p50-harsh-lighting-r3-k10-s0"]
    assert r2.params["init"] == "ft-harsh-lighting-n4-k10-s0" and r2.params["method"] == "ft"
    assert r3.params["init"] == "online-ft-p50-harsh-lighting-r2-k10-s0"
    # round 3 trains on the three rounds' data, which share half of each batch in proportion to their episodes
    c2, c3 = (
        units["collect:harsh_lighting:ft-harsh-lighting-n4-k10-s0"],
        units["collect:harsh_lighting:online-ft-p50-harsh-lighting-r2-k10-s0"],
    )
    assert (c2.params["seed"], c3.params["seed"]) == (plan.collect.seed + 1, plan.collect.seed + 2)
    assert c3.deps == ("train:online-ft-p50-harsh-lighting-r2-k10-s0",)
    targets = [r3.params["target"], *r3.params["more_targets"]]
    assert [t["dataset"] for t in targets] == [
        "mini-harsh-lighting-by-base",
        "mini-harsh-lighting-by-ft-harsh-lighting-n4-k10-s0",
        "mini-harsh-lighting-by-online-ft-p50-harsh-lighting-r2-k10-s0",
    ]
    assert [t["tier"] for t in targets] == [4, 4, 4]
    assert sum(t["weight"] for t in targets) == 0.5 and sum(b["weight"] for b in r3.params["base"]) == 0.5
    # a new head only in round 1; the ratio runs start with ft at their own share
    h1, h2 = (
        units["train:new_head-harsh-lighting-n4-k10-s0"],
        units["train:online-new_head-p50-harsh-lighting-r2-k10-s0"],
    )
    assert (h1.params["method"], h2.params["method"]) == ("new_head", "ft")
    q1 = units["train:online-ft-p99-harsh-lighting-r1-k10-s0"]
    assert q1.params["target"]["weight"] == 0.99 and abs(sum(b["weight"] for b in q1.params["base"]) - 0.01) < 1e-12
    for tag in ("online-ft-p99-harsh-lighting-r3-k10-s0", "online-new_head-p50-harsh-lighting-r3-k10-s0"):
        assert f"eval:{tag}:harsh_lighting" in units
    order(unit_graph(units))


def test_online_settings_are_checked_before_any_work():
    import pytest

    from nsl.errors import ConfigError

    for old, new, message in (
        ("episodes = 4\nsteps = 10\nmethods", "episodes = 9\nsteps = 10\nmethods", "above the collection size"),
        ('methods = ["ft", "new_head"]', 'methods = ["pnn"]', "start with ft or new_head"),
        ("ratios = [0.24, 0.99]", "ratios = [1.5]", "target data's share"),
    ):
        with pytest.raises(ConfigError, match=message):
            parse_plan(tomllib.loads(MINI_PLAN.replace(old, new)))


def test_the_engine_is_a_cell_of_the_study_like_a_shift():
    from .conftest import MICRO_PLAN

    text = MICRO_PLAN.replace('shifts = ["harsh_lighting"]', 'shifts = ["harsh_lighting", "engine:pybullet"]')
    plan, units = _units(text)
    assert plan.shifts[-1] == "engine:pybullet"
    collect = units["collect:engine:pybullet:base"]
    assert collect.params["shift"] == "engine:pybullet" and collect.params["dataset"] == "mini-engine-pybullet-by-base"
    assert "train:ft-engine-pybullet-n8-k10-s0" in units
    evals = {n for n in units if n.startswith("eval:ft-engine-pybullet-n8-k10-s0:")}
    assert evals == {"eval:ft-engine-pybullet-n8-k10-s0:base", "eval:ft-engine-pybullet-n8-k10-s0:engine:pybullet"}


def test_a_plan_of_the_engine_alone_tests_no_finding_of_the_source():
    from nsl.study.report.document import _findings

    (line,) = _findings({"plan": {"shifts": ["engine:pybullet"]}})
    assert line.startswith("None of this plan's shifts is one of the source's challenges")


def test_early_stopping_runs_every_shift_seed_and_extra_run_with_its_own_base_half():
    """[early_stop] with shifts, seeds and [[early_stop.runs]]: one long fine-tune each, evaluated on its shift and
    the base task; a run that names base datasets mixes only those into its base half; the single-run form keeps
    its unit."""
    import pytest

    from nsl.errors import ConfigError
    from nsl.study.units import early_stop_runs

    _, single = _units()
    assert [n for n in single if n.startswith("train:es-")] == ["train:es-offset-gripper-n8-k10-s0"]
    extra = """
shifts = ["offset_gripper", "harsh_lighting"]
seeds = [0, 1]

[[early_stop.runs]]
shift = "offset_gripper"
episodes = 4
base = ["mini-base-oracle"]
"""
    text = MINI_PLAN.replace("holdout = 0.25\n", "holdout = 0.25\n" + extra).replace('"auc", "td"]', '"qmean", "fqe"]')
    plan, units = _units(text)
    runs = early_stop_runs(plan)
    assert [r.tag for r in runs] == [
        "es-offset-gripper-n8-k10-s0",
        "es-offset-gripper-n8-k10-s1",
        "es-harsh-lighting-n8-k10-s0",
        "es-harsh-lighting-n8-k10-s1",
        "es-offset-gripper-n4-k10-s0-b-mini-base-oracle",
        "es-offset-gripper-n4-k10-s1-b-mini-base-oracle",
    ]
    for r in runs:
        u = units[f"train:{r.tag}"]
        assert (u.params["shift"], u.params["target"]["tier"], u.params["seed"]) == (r.shift, r.episodes, r.seed)
        assert u.params["monitor"]["criterion"] == "fqe" and u.params["monitor"]["holdout"] == 0.25
        assert sum(b["weight"] for b in u.params["base"]) == pytest.approx(0.5)
    assert {"eval:base:offset_gripper", "eval:base:harsh_lighting"} <= set(units)
    with pytest.raises(ConfigError, match=r"early_stop.runs.base names \['grasp-base-oracle'\]"):
        _units(text.replace('base = ["mini-base-oracle"]', 'base = ["grasp-base-oracle"]'))
    with pytest.raises(ConfigError, match="above the collection size"):
        _units(text.replace("episodes = 4\nbase", "episodes = 400\nbase"))


PLASTICITY = '\n[plasticity]\nshift = "offset_gripper"\nstage = 1\nepisodes = 8\nsteps = 10\nseeds = [0, 1]\n'


def test_plasticity_crosses_two_starts_with_two_collectors_and_adds_shrink_and_perturb():
    from nsl.study.units import plasticity_runs

    plan, units = _units(MINI_PLAN + PLASTICITY)
    runs = plasticity_runs(plan)
    stage1 = "ft-harsh-lighting-n8-k10-s0"  # the sequence's first stage (harsh lighting) is the second start
    assert len(runs) == 10  # four arms and shrink and perturb, two seeds each
    by = {(r.init, r.collector, r.tag.split("-")[1]) for r in runs}
    assert by >= {
        ("base", "base", "offset"),
        ("base", stage1, "base"),
        (stage1, "base", "c1"),
        (stage1, "base", "c1sp"),
    }
    # the base on its own episodes is the single-step fine-tune; the stage policy on its own, with the sequence's
    # seed, is the sequence's next stage: both run once however many experiments need them
    tags = [r.tag for r in runs]
    assert "ft-offset-gripper-n8-k10-s0" in tags and "c2-offset-gripper-n8-k10-s0" in tags
    sp = units["train:pl-c1sp-base-offset-gripper-n8-k10-s1"]
    assert sp.params["shrink_perturb"] == [0.8, 0.01] and sp.params["init_ref"].endswith(f"{stage1}@latest")
    assert f"train:{stage1}" in sp.deps
    own = units["train:pl-c1-c1-offset-gripper-n8-k10-s1"]
    assert own.params["target"]["dataset"] == f"mini-offset-gripper-by-{stage1}"
    assert "shrink_perturb" not in own.params
    for tag in tags:
        assert f"eval:{tag}:offset_gripper" in units and f"eval:{tag}:base" in units
    _, none = _units(MINI_PLAN + PLASTICITY.replace("seeds = [0, 1]\n", "seeds = [0, 1]\nshrink_perturb = []\n"))
    assert not any(n.startswith("train:pl-c1sp") for n in none)


def test_a_bad_plasticity_section_is_refused_in_one_line():
    import pytest

    from nsl.errors import ConfigError

    for change, message in (
        ("stage = 3", "plasticity.stage = 3 needs a continual sequence of at least 3 stages; this plan's has 2"),
        ("episodes = 9", "plasticity.episodes = 9 is above the collection size"),
        ("shrink_perturb = [1.5, 0.1]", "must be [alpha, sigma] with 0 < alpha <= 1"),
    ):
        key = change.split(" = ")[0]
        text = (
            MINI_PLAN
            + "\n".join(change if line.startswith(key + " ") else line for line in PLASTICITY.splitlines())
            + ("\n" + change if key == "shrink_perturb" else "")
            + "\n"
        )
        with pytest.raises(ConfigError, match=message.replace("[", r"\[")) as err:
            parse_plan(tomllib.loads(text), default_name="mini")
        assert "\n" not in str(err.value)


EFFICIENCY = (
    '\n[efficiency]\nshifts = ["harsh_lighting"]\ntiers = [4, 8]\nseeds = [0, 1]\nft_steps = 10\n'
    "scratch_steps = 20\ncurve_every = 10\ncurve_episodes = 3\nreference = 8\n"
)


def test_efficiency_trains_ft_and_both_scratches_at_every_tier_and_shares_fts_runs():
    from nsl.study.units import efficiency_runs

    plan, units = _units(MINI_PLAN + EFFICIENCY)
    runs = efficiency_runs(plan)
    assert len(runs) == 3 * 2 * 2  # methods x tiers x seeds
    # FT's runs are the fine-tuning tiers' own: the same unit as the plan's [finetune] at 8 episodes, 10 steps
    assert "ft-harsh-lighting-n8-k10-s0" in [r.tag for r in runs]
    ft = units["train:ft-harsh-lighting-n4-k10-s1"]
    assert ft.params["monitor"] is None and ft.params["target"]["tier"] == 4 and ft.params["method"] == "ft"
    scratch = units["train:eff-scratch-harsh-lighting-n8-k20-s1"]
    assert scratch.params["method"] == "scratch" and scratch.params["steps"] == 20 and scratch.params["base"]
    assert scratch.params["monitor"] == {
        "every": 10,
        "episodes": 3,
        "base_episodes": 0,
        "seed": plan.eval.selection_seed,
        "holdout": None,
    }
    alone = units["train:eff-scratch-target-harsh-lighting-n4-k20-s0"]
    assert alone.params["base"] == [] and alone.params["target"]["weight"] == 1.0
    for r in runs:
        assert f"eval:{r.tag}:harsh_lighting" in units
    _, flat = _units(MINI_PLAN + EFFICIENCY.replace("curve_every = 10", "curve_every = 0"))
    assert flat["train:eff-scratch-harsh-lighting-n8-k20-s1"].params["monitor"] is None


def test_a_bad_efficiency_section_is_refused_in_one_line():
    import pytest

    from nsl.errors import ConfigError

    for change, message in (
        ("tiers = [4, 16]", "efficiency.tiers go to 16 episodes, above the collection size collect.episodes = 8"),
        ("tiers = [8, 4]", "efficiency.tiers = [8, 4] must be increasing"),
        ("reference = 5", "efficiency.reference = 5 must be one of its tiers"),
        ('methods = ["scratch"]', "efficiency.methods needs ft"),
        ('methods = ["ft", "iql"]', "efficiency.methods has 'iql'"),
    ):
        key = change.split(" = ")[0]
        lines = [change if line.startswith(key + " ") else line for line in EFFICIENCY.splitlines()]
        if key == "methods":
            lines.append(change)
        with pytest.raises(ConfigError, match=message.replace("[", r"\[")) as err:
            parse_plan(tomllib.loads(MINI_PLAN + "\n".join(lines) + "\n"), default_name="mini")
        assert "\n" not in str(err.value)
