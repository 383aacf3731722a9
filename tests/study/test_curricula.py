"""``nsl transfer curricula``: following a transfer's optimal and pessimal curricula for real."""

from __future__ import annotations

import json

import pytest

from nsl.curriculum import SCRATCH, matrix_from_dict
from nsl.study.curricula import CurriculaPlan, build_curricula_units, default_seeds, measure, path_to
from nsl.study.transfer import parse_transfer_plan
from nsl.study.units import BaseSource
from tests.conftest import run_cli
from tests.study.test_transfer import MINI_TRANSFER

# its tests share the mini plan's run: one xdist worker takes them all (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("mini_run")

THREE = {
    "name": "x3",
    "study": "s",
    "steps": 4,
    "every": 2,
    "eval_episodes": 10,
    "seeds": [0, 1],
    "tasks": [
        {"shift": "base", "checkpoint": "ckpt:base", "data": "d-base", "episodes": 6},
        {"shift": "harsh_lighting", "checkpoint": "ckpt:harsh", "data": "d-harsh", "episodes": 8},
        {"shift": "offset_gripper", "checkpoint": "ckpt:offset", "data": "d-offset", "episodes": 8},
    ],
}
CHAIN = {"base": SCRATCH, "harsh_lighting": "base", "offset_gripper": "harsh_lighting"}


def _units(trees, seeds=(2, 3)):
    plan = parse_transfer_plan(THREE)
    cplan = CurriculaPlan("x3", seeds, trees)
    return plan, cplan, build_curricula_units(plan, cplan, "ckpt:base", [BaseSource("b", 1.0)], 7.5e-5)


def test_default_seeds_replicate_with_seeds_the_matrix_did_not_use():
    assert default_seeds(parse_transfer_plan(THREE)) == (2, 3)
    assert path_to(CHAIN, "offset_gripper") == ["base", "harsh_lighting", "offset_gripper"]


def test_a_chain_fine_tunes_each_task_from_the_checkpoint_the_curriculum_made_for_its_parent():
    _, _, units = _units({"optimal": CHAIN, "pessimal": {t: SCRATCH for t in CHAIN}})
    trains = {n: u for n, u in units.items() if u.kind == "train"}
    for s in (2, 3):
        # depth 1 below the scratch child: from the parent's catalogued checkpoint (the matrix's own kind of run)
        first = trains[f"train:ft-base-to-harsh-lighting-n8-k4-s{s}"]
        assert first.params["init_ref"] == "ckpt:base" and first.params["seed"] == s
        # depth 2: from the checkpoint made along base -> harsh lighting, and after it
        deep = trains[f"train:ft-via-0-1-to-offset-gripper-n8-k4-s{s}"]
        assert deep.params["init_ref"] == f"ckpt:x3-ft-base-to-harsh-lighting-n8-k4-s{s}@latest"
        assert f"train:ft-base-to-harsh-lighting-n8-k4-s{s}" in deep.deps
        assert deep.params["checkpoint"] == f"x3-ft-via-0-1-to-offset-gripper-n8-k4-s{s}"
        assert deep.params["target"]["dataset"] == "d-offset" and deep.params["lr"] == 7.5e-5
        # its control: the same fine-tune from the catalogued checkpoint of harsh lighting
        assert trains[f"train:ft-harsh-lighting-to-offset-gripper-n8-k4-s{s}"].params["init_ref"] == "ckpt:harsh"
        for t in ("base", "harsh-lighting", "offset-gripper"):  # the denominators
            assert trains[f"train:scratch-{t}-n{6 if t == 'base' else 8}-k4-s{s}"].params["method"] == "scratch"
    # a task learned from scratch is taken as learned: no run of its own; the all-scratch tree adds nothing
    assert len(trains) == 2 * (3 + 3)
    assert not any(n.endswith(("-s0", "-s1")) for n in trains)


def test_measured_costs_and_the_independence_check_on_known_curves():
    plan, cplan, _ = _units({"optimal": CHAIN, "pessimal": {t: SCRATCH for t in CHAIN}})
    matrix = matrix_from_dict(
        {
            "tasks": ["base", "harsh_lighting", "offset_gripper"],
            "base": "base",
            "advantage": {
                "base": {"harsh_lighting": 3.0, "offset_gripper": 2.0},
                "harsh_lighting": {"base": 0.5, "offset_gripper": 4.0},
                "offset_gripper": {"base": 0.5, "harsh_lighting": 1.5},
            },
        }
    )
    auc = {
        "scratch-harsh-lighting-n8-k4-s2": 0.1,
        "scratch-harsh-lighting-n8-k4-s3": 0.2,
        "scratch-offset-gripper-n8-k4-s2": 0.1,
        "scratch-offset-gripper-n8-k4-s3": 0.01,  # floored at 1/10
        "ft-base-to-harsh-lighting-n8-k4-s2": 0.3,
        "ft-base-to-harsh-lighting-n8-k4-s3": 0.4,
        "ft-via-0-1-to-offset-gripper-n8-k4-s2": 0.2,
        "ft-via-0-1-to-offset-gripper-n8-k4-s3": 0.2,
        "ft-harsh-lighting-to-offset-gripper-n8-k4-s2": 0.4,
        "ft-harsh-lighting-to-offset-gripper-n8-k4-s3": 0.5,
    }
    out = measure(plan, cplan, matrix, auc.get, lambda tag: 0.5 if tag in auc else None)
    opt = out["trees"]["optimal"]
    assert [(e["from"], e["to"]) for e in opt["edges"]] == [
        (SCRATCH, "base"),
        ("base", "harsh_lighting"),
        ("harsh_lighting", "offset_gripper"),
    ]
    assert opt["predicted"] == pytest.approx(-(1 + 3 + 4))
    a_harsh = {2: 0.3 / 0.1, 3: 0.4 / 0.2}
    a_offset = {2: 0.2 / 0.1, 3: 0.2 / 0.1}
    assert opt["edges"][1]["measured"] == pytest.approx(2.5) and opt["edges"][2]["measured"] == pytest.approx(2.0)
    assert opt["per_seed"] == pytest.approx({str(s): -(1 + a_harsh[s] + a_offset[s]) for s in (2, 3)})
    assert opt["measured"] == pytest.approx(-5.5) and opt["complete"]
    assert opt["edges"][0]["final"] is None and opt["mean_final"] is None  # no scratch run of base recorded
    pes = out["trees"]["pessimal"]
    assert pes["predicted"] == pes["measured"] == -3.0
    (row,) = out["independence"]
    assert row["path"] == ["base", "harsh_lighting", "offset_gripper"] and row["matrix"] == 4.0
    assert row["per_seed"] == pytest.approx({"2": 2.0 - 0.4 / 0.1, "3": 2.0 - 0.5 / 0.1})
    assert row["difference"] == pytest.approx(-2.5) and row["interval"][0] < -2.5 < row["interval"][1]
    assert row["auc_difference"] == pytest.approx(((0.2 - 0.4) + (0.2 - 0.5)) / 2)
    # an unfinished run leaves the tree incomplete rather than guessing
    del auc["ft-via-0-1-to-offset-gripper-n8-k4-s3"]
    out = measure(plan, cplan, matrix, auc.get, lambda tag: None)
    assert not out["trees"]["optimal"]["complete"] and out["trees"]["optimal"]["measured"] is None


def test_curricula_of_the_mini_transfer_through_the_cli(mini_run, tmp_path, capsys):
    path = tmp_path / "xmini.toml"
    path.write_text(MINI_TRANSFER)
    assert run_cli("transfer", "curricula", "nope") == 2
    assert "no transfer named 'nope'" in capsys.readouterr().err
    assert run_cli("transfer", "run", str(path), "--quiet") == 0
    capsys.readouterr()
    assert run_cli("transfer", "curricula", "xmini", "--seed", "0") == 2
    assert "repeats the matrix's own seeds [0]" in capsys.readouterr().err
    assert run_cli("transfer", "curricula", "xmini", "--quiet", "--json") == 0
    out = json.loads(capsys.readouterr().out)
    folder = mini_run / "transfers" / "xmini" / "curricula"
    assert (folder / "curricula.md").is_file() and out["seeds"] == [1]
    matrix = json.loads((mini_run / "transfers" / "xmini" / "matrix.json").read_text())
    for name in ("optimal", "pessimal"):
        tree = out["trees"][name]
        assert tree["complete"]
        for e in tree["edges"]:
            if e["from"] != SCRATCH:  # measured from new runs (seed 1), predicted from the matrix (seed 0)
                assert e["predicted"] == pytest.approx(matrix["advantage"][e["from"]][e["to"]])
                run = mini_run / "runs" / f"xmini-ft-{e['from'].replace('_', '-')}-to-{e['to'].replace('_', '-')}"
                assert list(run.parent.glob(run.name + "-n*-k4-s1"))
    # running again trains nothing; other seeds after a start are refused
    assert run_cli("transfer", "curricula", "xmini", "--quiet") == 0
    assert "0 left" in capsys.readouterr().out
    assert run_cli("transfer", "curricula", "xmini", "--seed", "5") == 2
    assert "use the same --seed to resume" in capsys.readouterr().err
