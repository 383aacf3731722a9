"""``nsl transfer``, ``nsl curriculum`` and ``nsl catalog suggest-base`` on the mini study, through the real CLI."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from nsl.catalog import Catalog
from nsl.study import SHIPPED_TRANSFER, build_units, load_plan, load_transfer_plan
from nsl.study.transfer import build_transfer_units
from nsl.study.units import BaseSource, unit_graph
from tests.conftest import run_cli

# its tests share the mini plan's run: one xdist worker takes them all (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("mini_run")

# Two tasks of the mini study (tests/study/conftest.py): the base task (its data collected here) and harsh lighting.
MINI_TRANSFER = """
name = "xmini"
study = "mini"
steps = 4
every = 2
eval_episodes = 3
eval_seed = 2000
seeds = [0]
checkpoint_every = 2
proxy_episodes = 12

[[tasks]]
shift = "base"
checkpoint = "ckpt:base"
data = "xmini-base-by-base"
episodes = 6
collect = { policy = "ckpt:base", seed = 5, epsilon = 0.1 }

[[tasks]]
shift = "harsh_lighting"
checkpoint = "ckpt:mini-ft-harsh-lighting-n8-k10-s0@latest"
data = "mini-harsh-lighting-by-base"
episodes = 8
"""
PAIRS = [("base", "harsh_lighting"), ("harsh_lighting", "base")]


@pytest.fixture
def xmini(mini_run, tmp_path_factory, capsys):
    """The mini transfer run once through the CLI, in the mini study's workspace."""
    folder = mini_run / "transfers" / "xmini"
    if not (folder / "matrix.json").is_file():
        path = tmp_path_factory.mktemp("xplans") / "xmini.toml"
        path.write_text(MINI_TRANSFER)
        assert run_cli("transfer", "run", str(path), "--quiet") == 0
        out = capsys.readouterr().out
        assert "transfer xmini: finished; 6 done, 0 left" in out and "(2 of 2 pairs measured)" in out
    return folder


def _auc(run_dir):
    """AUC of a run's curve.csv computed here: trapezoid over steps 0, 2, 4, divided by 4."""
    import csv

    rows = list(csv.DictReader(open(run_dir / "curve.csv")))
    steps = [int(r["step"]) for r in rows]
    succ = [float(r["target_success"]) for r in rows]
    assert steps == [0, 2, 4] and all(int(r["target_episodes"]) == 3 for r in rows)
    assert all(r["base_success"] == "" for r in rows)  # the base task is not evaluated in transfer runs
    return ((succ[0] + succ[1]) + (succ[1] + succ[2])) / 4


def test_transfer_measures_every_pair_with_catalogued_runs(xmini, mini_run):
    m = json.loads((xmini / "matrix.json").read_text())
    assert m["format"] == "nsl.transfer-matrix" and m["tasks"] == ["base", "harsh_lighting"] and m["base"] == "base"
    runs = mini_run / "runs"
    floor = 1 / 3
    for src, dst in PAIRS:
        ft = _auc(
            runs / f"xmini-ft-{src.replace('_', '-')}-to-{dst.replace('_', '-')}-n{6 if dst == 'base' else 8}-k4-s0"
        )
        scratch = _auc(runs / f"xmini-scratch-{dst.replace('_', '-')}-n{6 if dst == 'base' else 8}-k4-s0")
        assert m["meta"]["scratch_auc"][dst]["0"] == pytest.approx(scratch)
        assert m["advantage"][src][dst] == pytest.approx(ft / max(scratch, floor))
        assert m["meta"]["entries"][src][dst]["floored"] == ([0] if scratch < floor else [])
    assert m["interval"] == {}  # one seed: no interval over seeds
    with Catalog() as cat:
        ft = cat.resolve_checkpoint("ckpt:xmini-ft-harsh-lighting-to-base-n6-k4-s0@latest")
        harsh = cat.resolve_checkpoint("ckpt:mini-ft-harsh-lighting-n8-k10-s0@latest")
        assert ft.step == 4 and ft.parent == harsh.id and ft.shift == "base"
        assert {(u.dataset, u.tier, u.weight) for u in ft.data} == {
            ("mini-base-oracle", 12, 0.5),
            ("xmini-base-by-base", 6, 0.5),
        }  # 50/50
        assert ft.config["training"]["lr"] == pytest.approx(0.25 * 3e-4)  # the study's fine-tuning lr, not 25% of 25%
        scratch = cat.resolve_checkpoint("ckpt:xmini-scratch-base-n6-k4-s0@latest")
        assert scratch.config["training"]["lr"] == pytest.approx(3e-4) and scratch.config["method"] == "scratch"
        assert len(cat.resolve_data("data:xmini-base-by-base").dataset.files) > 0  # collected by its recipe
    assert m["meta"]["checkpoints"]["harsh_lighting"]["id"] == harsh.id
    text = (xmini / "matrix.md").read_text()
    # Two tasks give at most two (source, target) pairs: too few for a rank correlation. (A pair whose target
    # episodes all succeed, or all fail, has no Q-ranking AUC and drops out.)
    assert "## Advantage A(row -> column)" in text and re.search(r"Spearman rho: undefined \([12] pairs", text)
    assert (xmini / "curriculum.png").stat().st_size > 1000


def test_running_again_resumes_nothing_and_keeps_the_matrix(xmini, mini_run, tmp_path, capsys):
    before = (xmini / "matrix.json").read_text()
    path = tmp_path / "xmini.toml"
    path.write_text(MINI_TRANSFER)
    assert run_cli("transfer", "run", str(path), "--quiet") == 0
    assert (xmini / "matrix.json").read_text() == before
    assert run_cli("transfer", "status", "xmini", "--json") == 0
    status = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert status["state"] == "finished" and all(u["state"] == "done" for u in status["units"].values())
    # under another name every training unit is left (the collected data is shared); nothing is written
    assert run_cli("transfer", "run", str(path), "--name", "xest", "--estimate", "--workers", "2") == 0
    out = capsys.readouterr().out
    assert "for 4 units (train " in out
    assert re.search(r"xest: about \d+ minutes on 2 unit slots \(critical path \d+ minutes, \d+ units\)", out)
    assert not (mini_run / "transfers" / "xest").exists()
    other = tmp_path / "other.toml"
    other.write_text(MINI_TRANSFER.replace("steps = 4", "steps = 6"))
    assert run_cli("transfer", "run", str(other)) == 2
    assert "transfer 'xmini' exists with a different plan" in capsys.readouterr().err


def test_curriculum_reads_the_transfer_by_name(xmini, capsys):
    assert run_cli("curriculum", "--transfer", "xmini", "--json") == 0
    out = json.loads(capsys.readouterr().out)
    a = json.loads((xmini / "matrix.json").read_text())["advantage"]
    # the three curricula of two tasks: both from scratch, harsh lighting from base, base from harsh lighting
    totals = [2.0, 1.0 + a["base"]["harsh_lighting"], 1.0 + a["harsh_lighting"]["base"]]
    assert out["optimal"]["cost"] == pytest.approx(-max(totals)) and out["pessimal"]["cost"] == pytest.approx(
        -min(totals)
    )
    assert out["from_scratch"] == -2.0 and out["from_base"] == pytest.approx(-totals[1])
    assert out["picture"].endswith("transfers/xmini/curriculum.png")


def test_suggest_base_ranks_measured_transfer_first_then_the_proxy(xmini, mini_run, capsys):
    from nsl import keys
    from nsl.datasets import api
    from nsl.eval import q_ranking_auc
    from nsl.learners import load_policy

    cands = [
        "ckpt:base",
        "ckpt:mini-ft-harsh-lighting-n8-k10-s0@latest",
        "ckpt:mini-ft-offset-gripper-n8-k10-s0@latest",
    ]
    argv = [
        "catalog",
        "suggest-base",
        "--shift",
        "base",
        "--data",
        "mini-base-oracle",
        "--episodes",
        "12",
        "--transfer",
        "xmini",
        "--json",
    ]
    for c in cands:
        argv += ["--checkpoint", c]
    assert run_cli(*argv) == 0
    out = json.loads(capsys.readouterr().out)
    ranked = out["candidates"]
    m = json.loads((xmini / "matrix.json").read_text())
    # harsh lighting's checkpoint has a measured A(harsh_lighting -> base): it comes first, with that value
    assert ranked[0]["ref"].startswith("ckpt:mini-ft-harsh-lighting-n8-k10-s0@") and ranked[0]["basis"] == "measured"
    assert ranked[0]["measured"] == pytest.approx(m["advantage"]["harsh_lighting"]["base"])
    # the others by the proxy: the Q-ranking AUC of success labels, recomputed here from the checkpoints
    arrays = api.open_view("mini-base-oracle:12").episodes_arrays()
    ep = arrays[keys.EPISODE_INDEX]
    labels = np.array([arrays[keys.SUCCESS][ep == e].any() for e in ep])
    assert labels.any() and not labels.all()
    expected = {}
    with Catalog() as cat:
        for c in cands[::2]:
            e = cat.resolve_checkpoint(c)
            q = load_policy(e.path).q_values(
                {"image": arrays[keys.OBS_IMAGE], "state": arrays[keys.OBS_STATE]}, arrays[keys.ACTION]
            )
            expected[f"ckpt:{e.ref}"] = q_ranking_auc(q, labels)
    rest = ranked[1:]
    assert [r["basis"] for r in rest] == ["proxy", "proxy"]
    assert {r["ref"]: r["proxy"] for r in rest} == pytest.approx(expected)
    assert rest[0]["proxy"] >= rest[1]["proxy"]
    assert out["rank_correlation"] == m["meta"]["rank_correlation"]["auc"]


def test_curriculum_on_a_hand_made_matrix_file(tmp_path, capsys):
    path = tmp_path / "m.json"
    path.write_text(
        json.dumps(
            {
                "tasks": ["base", "harsh", "offset"],
                "base": "base",
                "advantage": {
                    "base": {"harsh": 2.0, "offset": 1.5},
                    "harsh": {"base": 0.5, "offset": 3.0},
                    "offset": {"base": 0.8, "harsh": 0.9},
                },
            }
        )
    )
    assert run_cli("curriculum", "--matrix", str(path)) == 0
    out = capsys.readouterr().out
    assert "optimal curriculum (predicted cost -6.00):" in out
    assert [ln.split()[0:3] for ln in out.splitlines()[1:4]] == [
        ["base", "from", "scratch"],
        ["harsh", "from", "base"],
        ["offset", "from", "harsh"],
    ]
    assert "all from the base (base)         -4.50" in out and "all from scratch                 -3.00" in out
    assert (tmp_path / "curriculum.png").stat().st_size > 1000
    assert (
        run_cli("curriculum", "harsh", "offset", "--matrix", str(path), "--json", "--out", str(tmp_path / "t.png")) == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["from_base"] is None and out["optimal"]["edges"][1] == {
        "from": "harsh",
        "to": "offset",
        "advantage": 3.0,
        "cost": -3.0,
    }
    assert run_cli("curriculum", "harsh", "transparent", "--matrix", str(path)) == 2
    err = capsys.readouterr().err
    assert err == "nsl: error: task 'transparent' is not in the transfer matrix; its tasks: base, harsh, offset\n"


@pytest.mark.parametrize(
    "change, message",
    [
        (('shift = "harsh_lighting"', 'shift = "harsh_lightning"'), "unknown shift 'harsh_lightning'"),
        (("every = 2", "every = 3"), "every = 3 must divide steps = 4"),
        (('shift = "harsh_lighting"', 'shift = "base"'), "tasks repeat the shift 'base'"),
        (('study = "mini"\n', ""), "transfer plan [top level] lacks ['study']"),
        (('checkpoint = "ckpt:base"', 'checkpoint = "base"'), "checkpoint = 'base' must be a checkpoint reference"),
        (("seeds = [0]", "seeds = [0, 0]"), "seeds = [0, 0] must be a non-empty list of distinct seeds"),
        (("episodes = 8\n", "episodes = 8\ntier = 4\n"), "[tasks[1]] has unknown setting(s) ['tier']"),
        (('data = "mini-harsh-lighting-by-base"', 'data = "mini-harsh-lighting-by-base:4"'), "must be a dataset name"),
        (('study = "mini"', 'study = "nostudy"'), "study = 'nostudy': no study named 'nostudy'"),
    ],
)
def test_bad_transfer_plans_are_refused_in_one_line(tmp_path, nsl_home, capsys, change, message):
    old, new = change
    assert old in MINI_TRANSFER
    path = tmp_path / "bad.toml"
    path.write_text(MINI_TRANSFER.replace(old, new, 1))
    assert run_cli("transfer", "run", str(path)) == 2
    err = capsys.readouterr().err
    assert err.startswith("nsl: error: ") and message in err and err.count("\n") == 1, err
    assert not (nsl_home / "transfers").exists() and not (nsl_home / "runs").exists()


@pytest.mark.parametrize(
    "change, message",
    [
        (
            ("mini-ft-harsh-lighting-n8-k10-s0", "mini-ft-harsh-lighting-n8-k99-s0"),
            "transfer task harsh_lighting: checkpoint ckpt:mini-ft-harsh-lighting-n8-k99-s0@latest is not catalogued",
        ),
        (("episodes = 8\n", "episodes = 9\n"), "dataset mini-harsh-lighting-by-base@v1 has 8 episodes, fewer than"),
    ],
)
def test_transfer_plans_are_checked_against_the_workspace(mini_run, tmp_path, capsys, change, message):
    path = tmp_path / "bad.toml"
    path.write_text(MINI_TRANSFER.replace(*change).replace('name = "xmini"', 'name = "xbad"'))
    assert run_cli("transfer", "run", str(path)) == 2
    err = capsys.readouterr().err
    assert message.replace("@v1", "") in err.replace("@v1", "") and err.count("\n") == 1, err
    assert not (mini_run / "transfers" / "xbad").exists()


@pytest.mark.parametrize("name, study", [("small", "full"), ("tiny", "tiny")])
def test_shipped_transfer_plans_use_what_their_study_makes(name, study):
    assert name in SHIPPED_TRANSFER
    plan, splan = load_transfer_plan(name), load_plan(study)
    assert plan.study == study and plan.name == f"transfer-{name}"
    made = build_units(splan, study, [])
    ckpts = {f"ckpt:{u.params['checkpoint']}@latest" for u in made.values() if u.kind == "train"}
    data = {u.params["dataset"]: u.params["episodes"] for u in made.values() if u.kind == "collect"}
    assert set(plan.task_names) == {"base", *splan.shifts}
    for t in plan.tasks:
        if t.shift == "base":
            assert t.checkpoint == "ckpt:base" and t.collect is not None
            continue
        assert t.checkpoint in ckpts and data[t.data] >= t.episodes
    units = build_transfer_units(plan, "ckpt:base", [BaseSource("b", 1.0, None, 10)], 7.5e-5)
    n = len(plan.tasks)
    assert sum(u.kind == "train" for u in units.values()) == n * n * len(plan.seeds)  # n(n-1) fine-tunes + n scratch
    unit_graph(units)
