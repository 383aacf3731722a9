"""The whole chain through the real CLI: collect, pre-train, fine-tune, evaluate, continual, report."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from nsl import workspace
from nsl.catalog import Catalog
from nsl.errors import ConfigError, UnknownReferenceError
from nsl.learners import read_config
from tests.conftest import run_cli


@pytest.fixture(scope="module")
def home(tmp_path_factory):
    return tmp_path_factory.mktemp("pipeline_home")


@pytest.fixture
def pipeline(home, monkeypatch):
    """Small base and shifted datasets and a tiny pre-trained checkpoint, built once per module."""
    monkeypatch.setenv("NSL_HOME", str(home))
    if not (home / "runs" / "base-tiny").exists():
        assert (
            run_cli(
                "collect",
                "--shift",
                "base",
                "--episodes",
                "24",
                "--policy",
                "oracle:0.5",
                "--data",
                "grasp-base",
                "--num-envs",
                "4",
            )
            == 0
        )
        assert (
            run_cli(
                "collect",
                "--shift",
                "harsh_lighting",
                "--episodes",
                "12",
                "--policy",
                "oracle:0.5",
                "--data",
                "grasp-harsh",
                "--num-envs",
                "4",
            )
            == 0
        )
        assert (
            run_cli("train", "--data", "grasp-base", "--steps", "8", "--name", "base-tiny", "--checkpoint-every", "4")
            == 0
        )
    return home


def test_fine_tuning_chain_is_catalogued_with_lineage(pipeline, capsys):
    assert (
        run_cli(
            "train",
            "--data",
            "grasp-base=0.5",
            "--data",
            "grasp-harsh=0.5",
            "--init",
            "ckpt:base-tiny",
            "--steps",
            "6",
            "--name",
            "harsh-tiny",
        )
        == 0
    )
    with Catalog() as cat:
        child = cat.resolve_checkpoint("ckpt:harsh-tiny@latest")
        parent = cat.resolve_checkpoint("ckpt:base-tiny@latest")
        assert child.parent == parent.id
        assert [(d.dataset, d.weight) for d in child.data] == [("grasp-base", 0.5), ("grasp-harsh", 0.5)]
        assert child.shift == "harsh_lighting"
        assert {d.name for d in cat.datasets()} >= {"grasp-base", "grasp-harsh"}
    capsys.readouterr()
    assert run_cli("catalog", "lineage", "ckpt:harsh-tiny@latest") == 0
    out = capsys.readouterr().out
    assert "base-tiny" in out and "grasp-harsh@v1" in out
    # the fine-tuning run recorded what produced it
    command = json.loads((workspace.runs_dir() / "harsh-tiny" / "command.json").read_text())
    assert command["init"] == parent.id and command["target_shift"] == "harsh_lighting"


def test_checkpoint_policy_collects_and_evaluations_are_stored(pipeline, capsys):
    assert (
        run_cli(
            "collect",
            "--shift",
            "harsh_lighting",
            "--episodes",
            "4",
            "--policy",
            "ckpt:base-tiny",
            "--data",
            "grasp-harsh-explore",
            "--num-envs",
            "4",
            "--epsilon",
            "0.2",
        )
        == 0
    )
    capsys.readouterr()
    assert (
        run_cli(
            "eval",
            "--checkpoint",
            "ckpt:base-tiny",
            "--shift",
            "base,harsh_lighting",
            "--episodes",
            "4",
            "--num-envs",
            "4",
            "--json",
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert set(out["results"]) == {"base", "harsh_lighting"}
    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:base-tiny@latest")
        evals = {e.shift: e for e in cat.evaluations(entry.id) if e.episodes == 4}
    assert {"base", "harsh_lighting"} <= set(evals)
    # each episode's outcome on its scene is kept, so that evaluations on the same scenes can be paired
    for e in evals.values():
        assert len(e.extra["outcomes"]) == 4 and e.extra["outcomes"].count("1") == e.successes


def test_action_noise_is_recorded_with_the_data_and_refused_for_scripted_policies(pipeline):
    from nsl.datasets import api

    assert (
        run_cli(
            "collect",
            "--shift",
            "offset_gripper@0.25",
            "--episodes",
            "2",
            "--policy",
            "ckpt:base-tiny",
            "--data",
            "offset-noisy",
            "--num-envs",
            "2",
            "--action-noise",
            "0.3",
        )
        == 0
    )
    v = api.open_version("offset-noisy")
    spec = v.provenance["collections"][-1]["spec"]
    assert spec["policy"]["action_noise"] == 0.3 and spec["policy"]["epsilon"] == 0.0
    assert "--action-noise 0.3" in v.manifest["created"]["command"]
    with pytest.raises(ConfigError, match="--action-noise applies to checkpoint policies"):
        run_cli(
            "--debug",
            "collect",
            "--shift",
            "base",
            "--episodes",
            "2",
            "--policy",
            "oracle:0.5",
            "--data",
            "oracle-noisy",
            "--action-noise",
            "0.3",
        )


def test_continual_rejects_bad_sequences_before_any_work(pipeline):
    before = sorted(p.name for p in (pipeline / "datasets").iterdir())
    with pytest.raises(UnknownReferenceError, match="unknown shift 'harsh'"):
        run_cli(
            "--debug",
            "continual",
            "--sequence",
            "harsh_lighting,harsh",
            "--init",
            "ckpt:base-tiny",
            "--base-data",
            "grasp-base",
            "--name",
            "bad1",
        )
    with pytest.raises(UnknownReferenceError, match="nope"):
        run_cli(
            "--debug",
            "continual",
            "--sequence",
            "harsh_lighting",
            "--init",
            "ckpt:nope",
            "--base-data",
            "grasp-base",
            "--name",
            "bad2",
        )
    with pytest.raises(ConfigError, match="repeats a task"):
        run_cli(
            "--debug",
            "continual",
            "--sequence",
            "harsh_lighting,harsh_lighting",
            "--init",
            "ckpt:base-tiny",
            "--base-data",
            "grasp-base",
            "--name",
            "bad3",
        )
    assert sorted(p.name for p in (pipeline / "datasets").iterdir()) == before
    assert not (pipeline / "runs" / "bad1").exists()


def test_continual_resumes_at_the_interrupted_stage(pipeline, monkeypatch, capsys):
    import nsl.services.continual as continual

    args = [
        "continual",
        "--sequence",
        "checkerboard_backing,extend_gripper,offset_gripper",
        "--init",
        "ckpt:base-tiny",
        "--base-data",
        "grasp-base",
        "--episodes",
        "4",
        "--steps",
        "4",
        "--eval-episodes",
        "2",
        "--name",
        "cont",
    ]
    real_stage = continual._stage
    calls: list[int] = []

    def stage_then_interrupt(run, i, shift, policy, cfg, progress):
        if i == 3:
            raise KeyboardInterrupt  # the user presses Ctrl-C during stage 3
        calls.append(i)
        return real_stage(run, i, shift, policy, cfg, progress)

    monkeypatch.setattr(continual, "_stage", stage_then_interrupt)
    assert run_cli(*args) == 130
    matrix = json.loads((workspace.runs_dir() / "cont" / "matrix.json").read_text())
    assert matrix["stages"] == ["init", "checkerboard_backing", "extend_gripper"]
    s2 = workspace.runs_dir() / "cont-s2-extend-gripper" / "final" / "model.safetensors"
    mtime = s2.stat().st_mtime_ns

    monkeypatch.setattr(continual, "_stage", real_stage)
    capsys.readouterr()
    assert run_cli(*args) == 0
    out = capsys.readouterr().out
    assert "stage 1 (checkerboard_backing) done earlier" in out and "stage 2 (extend_gripper) done earlier" in out
    assert s2.stat().st_mtime_ns == mtime  # stage 2 was not trained again
    matrix = json.loads((workspace.runs_dir() / "cont" / "matrix.json").read_text())
    assert matrix["stages"] == ["init", "checkerboard_backing", "extend_gripper", "offset_gripper"]
    assert run_cli("report", "cont") == 0
    assert (workspace.runs_dir() / "cont" / "report" / "report.md").exists()


@pytest.mark.precision  # with bfloat16 the bench also times bf16 acting
def test_bench_eval_reports_both_worker_counts(capsys):
    assert run_cli("bench", "eval", "--json", "--episodes", "16") == 0
    out = json.loads(capsys.readouterr().out)
    assert out["episodes"] == 16
    assert out["eval_episodes_per_s_1_worker"] > 0 and out["eval_episodes_per_s_2_workers"] > 0


def test_pre_training_takes_an_architecture_and_refuses_bad_ones(pipeline, capsys):
    assert (
        run_cli(
            "train",
            "--data",
            "grasp-base",
            "--steps",
            "2",
            "--name",
            "spatial-tiny",
            "--net",
            "pool=spatial",
            "--net",
            "hidden=16",
            "--net",
            "action_dims=0,1,3",
        )
        == 0
    )
    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:spatial-tiny@latest")
    arch = json.loads((Path(entry.path) / "config.json").read_text())["architecture"]
    assert (arch["pool"], arch["hidden"], arch["action_dims"]) == ("spatial", 16, [0, 1, 3])
    for extra, message in (
        (["--net", "poool=max"], "FIELD=VALUE"),
        (["--net", "hidden=wide"], "not a valid hidden"),
        (["--init", "ckpt:base-tiny", "--net", "hidden=16"], "parent's is kept"),
    ):
        capsys.readouterr()
        assert run_cli("train", "--data", "grasp-base", "--steps", "2", "--name", "x", *extra) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1, err


def test_training_records_crop_and_n_step_and_refuses_data_from_an_older_environment(pipeline, capsys):
    assert (
        run_cli(
            "train",
            "--data",
            "grasp-base",
            "--steps",
            "2",
            "--name",
            "crop-tiny",
            "--crop",
            "2",
            "--n-step",
            "3",
            "--weight-decay",
            "1e-4",
        )
        == 0
    )
    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:crop-tiny@latest")
    config = json.loads((Path(entry.path) / "config.json").read_text())
    training = config["training"]
    assert (training["augment_crop"], training["augment_colour"], training["n_step"]) == (2, 0.1, 3)
    assert training["weight_decay"] == 1e-4
    assert (config["data"]["n_step"], config["data"]["gamma"]) == (3, training["gamma"])
    # A fine-tune keeps how its parent read the data (n-step returns, crop) unless told otherwise.
    assert (
        run_cli(
            "train",
            "--data",
            "grasp-base=0.5",
            "--data",
            "grasp-harsh=0.5",
            "--init",
            "ckpt:crop-tiny",
            "--steps",
            "2",
            "--name",
            "crop-tiny-ft",
        )
        == 0
    )
    assert (
        run_cli(
            "train",
            "--data",
            "grasp-base=0.5",
            "--data",
            "grasp-harsh=0.5",
            "--init",
            "ckpt:crop-tiny",
            "--steps",
            "2",
            "--name",
            "crop-tiny-ft1",
            "--n-step",
            "1",
            "--crop",
            "4",
        )
        == 0
    )
    with Catalog() as cat:
        kept, told = (
            json.loads((Path(cat.resolve_checkpoint(f"ckpt:{n}@latest").path) / "config.json").read_text())
            for n in ("crop-tiny-ft", "crop-tiny-ft1")
        )
    assert (kept["training"]["n_step"], kept["training"]["augment_crop"], kept["data"]["n_step"]) == (3, 2, 3)
    assert (told["training"]["n_step"], told["training"]["augment_crop"], told["data"].get("n_step", 1)) == (1, 4, 1)
    capsys.readouterr()
    assert run_cli("train", "--data", "grasp-base", "--steps", "2", "--name", "x", "--n-step", "0") == 2
    err = capsys.readouterr().err.strip()
    assert "n_step 0" in err and len(err.splitlines()) == 1, err
    assert run_cli("train", "--data", "grasp-base", "--steps", "2", "--name", "x", "--weight-decay", "-1") == 2
    err = capsys.readouterr().err.strip()
    assert "weight_decay" in err and len(err.splitlines()) == 1, err
    # A copy of the base data whose provenance says it came from environment v2 (shoulder camera, 10 cm jaw).
    src = workspace.datasets_dir() / "grasp-base"
    old = workspace.datasets_dir() / "grasp-old"
    import shutil

    shutil.copytree(src, old)
    for prov in old.glob("v*/meta/*.json"):
        text = prov.read_text()
        if "nsl-grasp-v3" in text:
            prov.write_text(text.replace("nsl-grasp-v3", "nsl-grasp-v2"))
    capsys.readouterr()
    assert run_cli("train", "--data", "grasp-old", "--steps", "2", "--name", "old-tiny") == 2
    err = capsys.readouterr().err.strip()
    assert "nsl-grasp-v2" in err and "collect it again" in err and len(err.splitlines()) == 1, err


def test_a_fine_tune_without_steps_or_conservative_takes_the_recipes_and_pre_training_must_give_steps(
    pipeline, monkeypatch, capsys
):
    from nsl.commands import continual, efficiency
    from nsl.learners import FINE_TUNE_CONSERVATIVE
    from nsl.learners import config as learner_config

    recipe_steps = learner_config.FINE_TUNE_STEPS
    monkeypatch.setattr(learner_config, "FINE_TUNE_STEPS", 3)  # the recipe's 2,000, shortened for the test
    assert (
        run_cli(
            "train",
            "--data",
            "grasp-base=0.5",
            "--data",
            "grasp-harsh=0.5",
            "--init",
            "ckpt:base-tiny",
            "--name",
            "recipe-tiny",
        )
        == 0
    )
    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:recipe-tiny@latest")
    training = json.loads((Path(entry.path) / "config.json").read_text())["training"]
    assert (entry.step, training["steps"], training["conservative"]) == (3, 3, FINE_TUNE_CONSERVATIVE)
    capsys.readouterr()
    assert run_cli("train", "--data", "grasp-base", "--name", "no-steps") == 2
    err = capsys.readouterr().err.strip()
    assert "--steps is required for pre-training" in err and len(err.splitlines()) == 1, err
    # The commands that fine-tune in loops default to the recipe's steps too.
    import argparse

    from nsl.commands import train as train_command

    def subparser(command):
        parser = argparse.ArgumentParser()
        command.register(parser.add_subparsers())
        return next(iter(parser._subparsers._group_actions[0].choices.values()))

    for command in (continual, efficiency):
        assert subparser(command).get_default("steps") == recipe_steps
    helps = {a.dest: a.help for a in subparser(train_command)._actions}  # what `nsl train --help` says
    assert (
        f"fine-tuning: {recipe_steps}" in helps["steps"]
        and f"{FINE_TUNE_CONSERVATIVE} for fine-tuning" in helps["conservative"]
    )


def test_td_criterion_chooses_a_step_by_held_out_td_error(pipeline, capsys):
    from nsl.eval import read_curve

    assert (
        run_cli(
            "train",
            "--data",
            "grasp-base=0.5",
            "--data",
            "grasp-harsh=0.5",
            "--init",
            "ckpt:base-tiny",
            "--steps",
            "4",
            "--name",
            "td-tiny",
            "--eval-every",
            "2",
            "--eval-episodes",
            "0",
            "--criterion",
            "td",
            "--holdout",
            "0.25",
            "--patience",
            "3",
        )
        == 0
    )
    run_dir = workspace.runs_dir() / "td-tiny"
    rows = read_curve(run_dir / "curve.csv")
    assert [r.step for r in rows] == [0, 2, 4]
    td = [r.td_error for r in rows]
    assert all(t is not None and 0.0 <= t <= 1.0 for t in td)  # Q and its targets are probabilities
    assert len(set(td)) > 1  # the network changes between evaluations, and so does its TD error
    summary = json.loads((run_dir / "early_stop.json").read_text())
    assert summary["criterion"] == "td" and summary["mode"] == "min"
    assert summary["best_step"] == [r.step for r in rows][td.index(min(td))]
    assert summary["best_value"] == pytest.approx(min(td))
    out = capsys.readouterr().out
    if summary["best_step"] == 0:  # the parent itself had the lowest TD error
        assert "best by td: step 0, the starting point (base-tiny@" in out
    else:  # the chosen step is catalogued, so it can be evaluated or fine-tuned further
        assert f"best by td: ckpt:td-tiny@{summary['best_step']}" in out
        with Catalog() as cat:
            assert cat.resolve_checkpoint(f"ckpt:td-tiny@{summary['best_step']}").step == summary["best_step"]


@pytest.mark.parametrize("criterion, column", [("qmean", "q_mean"), ("fqe", "fqe")])
def test_average_q_and_fqe_criteria_choose_a_step_without_a_simulator(pipeline, capsys, criterion, column):
    from nsl.eval import read_curve

    name = f"{criterion}-tiny"
    train = ["train", "--data", "grasp-base=0.5", "--data", "grasp-harsh=0.5", "--init", "ckpt:base-tiny"]
    offline = ["--eval-every", "2", "--eval-episodes", "0", "--holdout", "0.25", "--patience", "3"]
    assert run_cli(*train, "--steps", "4", "--name", name, *offline, "--criterion", criterion) == 0
    run_dir = workspace.runs_dir() / name
    rows = read_curve(run_dir / "curve.csv")
    values = [getattr(r, column) for r in rows]
    assert [r.step for r in rows] == [0, 2, 4] and all(v is not None and 0.0 <= v <= 1.0 for v in values)
    assert all(r.q_mean is not None for r in rows)  # the average Q comes with every offline evaluation
    summary = json.loads((run_dir / "early_stop.json").read_text())
    assert summary["criterion"] == criterion and summary["mode"] == "max"
    assert summary["best_step"] == [r.step for r in rows][values.index(max(values))]


def test_efficiency_writes_tiers_json_that_the_report_reads(pipeline, capsys):
    from nsl.eval import TierResults

    args = [
        "efficiency",
        "--data",
        "grasp-harsh",
        "--sizes",
        "4,8,100",
        "--init",
        "ckpt:base-tiny",
        "--base-data",
        "grasp-base",
        "--steps",
        "2",
        "--eval-episodes",
        "3",
        "--name",
        "eff",
    ]
    assert run_cli(*args) == 0
    run_dir = workspace.runs_dir() / "eff"
    tiers = TierResults.load(run_dir / "tiers.json")
    assert list(tiers.rows) == ["harsh_lighting"] and tiers.tiers == [4, 8]  # 100 > the dataset's 12 episodes
    row = tiers.rows["harsh_lighting"]
    assert row.base.episodes == 3 and {k: r.episodes for k, r in row.tiers.items()} == {4: 3, 8: 3}
    with Catalog() as cat:  # each cell is a catalogued fine-tune of the starting checkpoint on its tier
        ckpt = cat.resolve_checkpoint("ckpt:eff-harsh-lighting-4@latest")
        assert ckpt.parent == cat.resolve_checkpoint("ckpt:base-tiny@latest").id
        assert [(d.dataset, d.tier) for d in ckpt.data] == [("grasp-base", None), ("grasp-harsh", 4)]
        assert {e.shift for e in cat.evaluations(ckpt.id)} == {"harsh_lighting"}
    capsys.readouterr()
    assert run_cli(*args) == 0  # everything measured: nothing is trained or evaluated again
    out = capsys.readouterr().out
    assert "tier 4 done earlier" in out and "tier 8 done earlier" in out
    assert TierResults.load(run_dir / "tiers.json") == tiers
    assert run_cli("report", "eff") == 0
    report = (run_dir / "report" / "report.md").read_text()
    assert "| challenge | base | 4 | 8 | best (change) |" in report
    with pytest.raises(ConfigError, match="different configuration"):
        run_cli("--debug", *args[:-2], "--name", "eff", "--steps", "3")


def test_continual_reports_a_stage_error_once_and_debug_shows_it(pipeline, monkeypatch, capsys):
    import nsl.services.collect as collect_command

    def failing_collect(config, **kwargs):
        raise ConfigError(f"collection of {config.data} refused")

    monkeypatch.setattr(collect_command, "collect", failing_collect)
    args = [
        "continual",
        "--sequence",
        "harsh_lighting",
        "--init",
        "ckpt:base-tiny",
        "--base-data",
        "grasp-base",
        "--episodes",
        "4",
        "--steps",
        "2",
        "--eval-episodes",
        "2",
        "--name",
        "cont-error",
    ]
    assert run_cli(*args) == 2
    err = capsys.readouterr().err
    assert [line for line in err.splitlines() if line.startswith("nsl: error:")] == [
        "nsl: error: collection of cont-error-harsh-lighting refused"
    ]
    with pytest.raises(ConfigError, match="collection of cont-error-harsh-lighting refused"):
        run_cli("--debug", *args)  # the stage's own exception, with its traceback


def test_simulator_early_stopping_evaluates_on_its_own_scenes_and_catalogues_them(pipeline, capsys):
    from nsl.eval import read_curve

    assert (
        run_cli(
            "train",
            "--data",
            "grasp-base=0.5",
            "--data",
            "grasp-harsh=0.5",
            "--init",
            "ckpt:base-tiny",
            "--steps",
            "4",
            "--name",
            "es-tiny",
            "--eval-every",
            "2",
            "--eval-episodes",
            "3",
            "--base-episodes",
            "2",
            "--eval-scenes",
            "3000",
            "--patience",
            "3",
        )
        == 0
    )
    run_dir = workspace.runs_dir() / "es-tiny"
    rows = read_curve(run_dir / "curve.csv")
    assert [r.step for r in rows] == [0, 2, 4]
    assert all(r.target.episodes == 3 and r.base.episodes == 2 for r in rows)
    summary = json.loads((run_dir / "early_stop.json").read_text())
    assert summary["config"]["seed"] == 3000
    assert json.loads((run_dir / "command.json").read_text())["options"]["eval_scenes"] == 3000
    with Catalog() as cat:
        for step in (2, 4):  # every evaluated step is catalogued with its evaluations, on the scenes of --eval-scenes
            entry = cat.resolve_checkpoint(f"ckpt:es-tiny@{step}")
            evals = {(e.shift, e.seed, e.episodes) for e in cat.evaluations(entry.id)}
            assert evals == {("harsh_lighting", 3000, 3), ("base", 3000, 2)}
    assert "best by eval:" in capsys.readouterr().out


def test_iql_pre_trains_and_fine_tunes_from_the_command_line_and_its_checkpoint_collects(pipeline, capsys):
    """`nsl train --learner iql` from scratch and from a QT-Opt parent (new head); the checkpoints record the learner,
    are catalogued with their lineage, and act through CEM like any other."""
    base = ["--data", "grasp-base", "--steps", "4", "--checkpoint-every", "2"]
    assert run_cli("train", "--learner", "iql:v_warmup=1", *base, "--name", "iql-tiny") == 0
    ft = ["--data", "grasp-base=0.5", "--data", "grasp-harsh=0.5", "--steps", "3", "--learner", "iql:expectile=0.9"]
    assert run_cli("train", *ft, "--init", "ckpt:base-tiny", "--method", "new_head", "--name", "iql-harsh") == 0
    with Catalog() as cat:
        child = cat.resolve_checkpoint("ckpt:iql-harsh@latest")
        assert child.parent == cat.resolve_checkpoint("ckpt:base-tiny@latest").id
        training = read_config(Path(child.path))["training"]
    assert training["learner"] == "iql" and training["learner_options"] == {"expectile": 0.9, "v_warmup": 200}
    assert training["conservative"] == 0.0  # IQL has no conservative term, also when fine-tuning
    assert run_cli("eval", "--checkpoint", "ckpt:iql-tiny", "--episodes", "2", "--num-envs", "2") == 0
    capsys.readouterr()
    assert run_cli("train", *base, "--learner", "iql:tau=0.9", "--name", "iql-bad") == 2
    assert "learner 'iql' has no option(s) ['tau']" in capsys.readouterr().err
    assert run_cli("train", *base, "--learner", "sac", "--name", "sac") == 2
    assert "unknown learner 'sac'" in capsys.readouterr().err


def test_the_gpu_fine_tune_script_exports_trains_and_catalogues_with_torch_alone(pipeline, tmp_path, monkeypatch):
    """scripts/gpu/finetune.py: the data mix and the parent as arrays; the recipe's steps from them (here on the
    CPU, on the GPU machine with --device cuda); the result catalogued under its parent with its data."""
    import runpy
    import sys

    script = str(Path(__file__).resolve().parents[2] / "scripts" / "gpu" / "finetune.py")
    folder, weights = tmp_path / "gpu", tmp_path / "ft.pt"

    def call(*argv: str) -> None:
        monkeypatch.setattr(sys, "argv", [script, *argv])
        runpy.run_path(script, run_name="__main__")

    call("export", str(folder), "--base", "ckpt:base-tiny", "--data", "grasp-base=0.5", "--data", "grasp-harsh=0.5")
    call("train", str(folder), "--seed", "1", "--steps", "3", "--device", "cpu", "--out", str(weights))
    call("import", str(weights), "--data", str(folder), "--name", "gpu-ft")
    with Catalog() as cat:
        child = cat.resolve_checkpoint("ckpt:gpu-ft")
        assert child.parent == cat.resolve_checkpoint("ckpt:base-tiny@latest").id
        assert [(d.dataset, d.weight) for d in child.data] == [("grasp-base", 0.5), ("grasp-harsh", 0.5)]
    config = json.loads((Path(child.path) / "config.json").read_text())
    assert config["step"] == 3 and config["training"]["seed"] == 1 and config["training"]["conservative"] == 0.1
