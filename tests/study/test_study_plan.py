"""Plans are checked before any work: a bad plan is refused in one line and creates no unit output."""

from __future__ import annotations

import pytest

from nsl.collectors import STUDY_SHIFTS
from nsl.errors import ConfigError, UnknownReferenceError
from nsl.study import SHIPPED, build_units, load_plan, unit_graph
from nsl.study.units import BaseSource, order
from tests.conftest import run_cli

from .conftest import MINI_PLAN


def _write(tmp_path, text: str, name: str = "bad"):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def _outputs(home) -> list[str]:
    """Everything a unit could have created: datasets, runs, checkpoints, study folders.

    Resolving ``ckpt:base`` registers the checkpoint shipped with nsl (``checkpoints/base``): not a unit output.
    """
    return sorted(
        str(p.relative_to(home))
        for sub in ("datasets", "runs", "checkpoints", "studies")
        if (home / sub).exists()
        for p in (home / sub).rglob("*")
        if not str(p.relative_to(home)).startswith("checkpoints/base")
    )


@pytest.mark.parametrize(
    "change, message",
    [
        (
            ('shifts = ["harsh_lighting", "offset_gripper"]', 'shifts = ["harsh_lighting", "offset_griper"]'),
            "plan shifts: unknown shift 'offset_griper'; did you mean 'offset_gripper'",
        ),
        (
            ("tiers = [4, 8]", "tiers = [4, 8, 16]"),
            "plan finetune.tiers has tier 16 above the collection size collect.episodes = 8",
        ),
        (('baselines = ["scratch"', 'baselines = ["scratch", "imagenet"'), "unknown method 'imagenet'"),
        (('methods = ["ft"]', 'methods = ["ft", "pnn2"]'), "unknown method 'pnn2'"),
        (
            ('criteria = ["eval", "softopc", "auc", "td"]', 'criteria = ["eval", "opc"]'),
            "unknown stopping criterion 'opc'",
        ),
        (
            ('source = "plan"\n', 'source = "checkpoint"\n'),
            "base data grasp-base-oracle@v1 (sha256:34692b25313d...) of ckpt:base is not in $NSL_HOME and the plan "
            "has no recipe",
        ),
        (
            ("[eval]\nepisodes = 4", "[eval]\nepisodes = 4\nepisode = 5"),
            "plan [eval] has unknown setting(s) ['episode']",
        ),
        (
            ("[eval]\nepisodes = 4\nseed = 2000", "[eval]\nepisodes = 4\nseed = 3000"),
            "plan eval.seed and eval.selection_seed are both 3000: the same scenes would choose and report",
        ),
        (
            ('baselines = ["scratch"', 'baselines = ["scratch", "no_targets"'),
            "unknown method 'no_targets'; did you mean 'no_target'",
        ),
    ],
)
def test_bad_plan_is_refused_in_one_line_before_any_work(tmp_path, nsl_home, capsys, change, message):
    old, new = change
    assert old in MINI_PLAN
    path = _write(tmp_path, MINI_PLAN.replace(old, new))
    assert run_cli("study", "run", str(path)) == 2
    err = capsys.readouterr().err
    assert err.startswith("nsl: error: ") and message in err and err.count("\n") == 1, err
    assert _outputs(nsl_home) == []


def test_missing_base_data_is_refused_when_the_plan_cannot_collect_it(tmp_path, nsl_home):
    text = MINI_PLAN.replace('source = "plan"\n', 'source = "checkpoint"\n')
    with pytest.raises(UnknownReferenceError, match="scripts/collect_base_data.sh"):
        run_cli("--debug", "study", "run", str(_write(tmp_path, text)))
    assert _outputs(nsl_home) == []


def test_a_recipe_for_recorded_base_data_must_match_the_record(tmp_path, nsl_home):
    """With the base's own data as source, a recipe of another size is refused (its hash could not match)."""
    text = MINI_PLAN.replace('source = "plan"\n', 'source = "checkpoint"\n').replace(
        'name = "mini-base-oracle"', 'name = "grasp-base-oracle"'
    )
    for name, policy, seed in (("grasp-base-noisy", "oracle:1.0", 2), ("grasp-base-random", "random", 3)):
        text = text.replace(
            "[collect]",
            f'[[base_data.datasets]]\nname = "{name}"\npolicy = "{policy}"\n'
            f"seed = {seed}\nepisodes = 2000\n\n[collect]",
        )
    with pytest.raises(ConfigError, match="has episodes = 12, but ckpt:base was trained on 4000"):
        run_cli("--debug", "study", "run", str(_write(tmp_path, text)))
    assert _outputs(nsl_home) == []


def test_a_study_name_is_bound_to_its_plan(tmp_path, mini_run, capsys):
    path = _write(tmp_path, MINI_PLAN.replace("steps = 10\nseeds = [0]", "steps = 12\nseeds = [0]"), "other")
    assert run_cli("study", "run", str(path), "--name", "mini") == 2
    assert "study 'mini' exists with a different plan" in capsys.readouterr().err


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_plans_parse_and_build_a_graph(name):
    plan = load_plan(name)
    assert plan.name == name
    base = [
        BaseSource(
            d.name,
            1 / len(plan.base_data.datasets),
            None,
            d.episodes,
            {
                "shift": d.shift,
                "policy": d.policy,
                "policy_ref": d.policy,
                "episodes": d.episodes,
                "seed": d.seed,
                "epsilon": 0.0,
                "batch": 8,
            },
        )
        for d in plan.base_data.datasets
    ]
    units = build_units(plan, name, base)
    graph = unit_graph(units)
    names = order(graph)
    assert names.index(f"base-data:{plan.base_data.datasets[0].name}") < names.index(
        next(n for n in names if n.startswith("train:"))
    )
    if name != "tiny":
        # the shipped base's scripted data, at the weights its training gave them (see the plans' comment)
        assert plan.base_data.source == "plan"
        from nsl.learners import load_checkpoint
        from nsl.study.actions import resolve_checkpoint

        recorded = {
            src["ref"].split("@")[0]: src["weight"]
            for src in load_checkpoint(resolve_checkpoint("ckpt:base").path).config["data"]["sources"]
        }
        assert {d.name: d.weight for d in plan.base_data.datasets} == pytest.approx(
            {n: w for n, w in recorded.items() if n.startswith("grasp-base-")}, abs=1e-3
        )
        own = {  # the shifts of their own
            "cross-engine": ("engine:pybullet",),
            "plasticity": (STUDY_SHIFTS[-1],),
            "efficiency": (STUDY_SHIFTS[0], STUDY_SHIFTS[-1]),
        }
        assert plan.shifts == own.get(name, STUDY_SHIFTS)
        if name == "efficiency":  # the calibrated severities, tiers to everything the base collects, FT's at 800
            assert plan.efficiency.shifts == plan.shifts and plan.efficiency.tiers[-1] == plan.collect.episodes
            assert plan.finetune.tiers == (plan.efficiency.reference,)
        if name == "plasticity":  # the 2x2 on the sequence's last stage, started from the stage before it
            assert plan.continual.sequence == STUDY_SHIFTS and plan.plasticity.shift == STUDY_SHIFTS[-1]
    if name in ("full", "paper"):
        assert plan.collect.episodes == 800 and plan.finetune.tiers == (25, 50, 100, 200, 400, 800)
        assert len(plan.shifts) == 5 and len(plan.continual.sequence) == 5


def _plan_with_base_data(name: str, episodes: int, verify: bool = True):
    from nsl.study.plan import parse_plan

    return parse_plan(
        {
            "name": "verify",
            "base": "ckpt:base",
            "shifts": ["harsh_lighting"],
            "base_data": {
                "source": "plan",
                "verify": verify,
                "datasets": [{"name": name, "policy": "oracle:0.5", "seed": 1, "episodes": episodes}],
            },
        }
    )


def test_plan_base_data_the_base_records_must_reproduce_its_hash(tmp_path, monkeypatch):
    """The scripted data the shipped base was trained on is collected again by the plan and hash-checked."""
    import json
    from pathlib import Path

    from nsl.catalog import Catalog
    from nsl.errors import CorruptDataError
    from nsl.services.collect import CollectConfig, collect
    from nsl.study.actions import base_sources

    monkeypatch.setenv("NSL_HOME", str(tmp_path))
    with Catalog() as cat:
        base = Path(cat.resolve_checkpoint("ckpt:base").path)
    recorded = {s["ref"].split("@")[0]: s for s in json.loads((base / "config.json").read_text())["data"]["sources"]}
    oracle = recorded["grasp-base-oracle"]
    (src,) = base_sources(_plan_with_base_data("grasp-base-oracle", oracle["episodes"]))
    assert src.hash == oracle["version_hash"]  # the collect unit must reproduce it
    (src,) = base_sources(_plan_with_base_data("grasp-base-oracle", oracle["episodes"], verify=False))
    assert src.hash is None
    (src,) = base_sources(_plan_with_base_data("tiny-base-oracle", 16))  # data the base never saw: nothing to check
    assert src.hash is None
    # the workspace holds other data under the recorded name: refused before any work, in one line
    collect(
        CollectConfig(shift="base", episodes=2, policy="oracle:0.5", data="grasp-base-oracle", seed=1), progress=False
    )
    with pytest.raises(CorruptDataError, match="no version with the hash ckpt:base records") as err:
        base_sources(_plan_with_base_data("grasp-base-oracle", oracle["episodes"]))
    assert "\n" not in str(err.value)


def test_the_shipped_plans_verify_their_base_data():
    from nsl.study.plan import SHIPPED, load_plan

    assert all(load_plan(name).base_data.verify for name in SHIPPED)
