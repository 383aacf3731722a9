"""scripts/experiments/plasticity_diagnose.py, the measurements behind docs/experiments/plasticity.md's diagnosis of
fine-tuning: run on a tiny pre-trained checkpoint and a short fine-tune of it, on small real datasets."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cli

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "experiments" / "plasticity_diagnose.py"


def _script():
    spec = importlib.util.spec_from_file_location("plasticity_diagnose", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def home(tmp_path_factory):
    home = tmp_path_factory.mktemp("diagnose_home")
    mp = pytest.MonkeyPatch()
    mp.setenv("NSL_HOME", str(home))
    assert (
        run_cli(
            *[
                "collect",
                "--shift",
                "base",
                "--episodes",
                "16",
                "--policy",
                "oracle:0.5",
                "--data",
                "d-base",
                "--num-envs",
                "4",
            ]
        )
        == 0
    )
    assert (
        run_cli(
            *[
                "collect",
                "--shift",
                "harsh_lighting",
                "--episodes",
                "12",
                "--policy",
                "oracle:0.5",
                "--data",
                "d-harsh",
                "--num-envs",
                "4",
            ]
        )
        == 0
    )
    assert (
        run_cli(
            *[
                "train",
                "--data",
                "d-base",
                "--steps",
                "6",
                "--name",
                "tiny",
                "--net",
                "hidden=16",
                "--net",
                "conv_channels=4,4,8,8",
                "--batch-size",
                "8",
            ]
        )
        == 0
    )
    assert (
        run_cli(
            *[
                "train",
                "--init",
                "ckpt:tiny",
                "--data",
                "d-base=0.5",
                "--data",
                "d-harsh=0.5",
                "--steps",
                "4",
                "--name",
                "tiny-ft",
                "--batch-size",
                "8",
                "--lr",
                "0.01",
            ]
        )
        == 0
    )
    yield home
    mp.undo()


def test_measurements_have_every_key_in_range(home, monkeypatch, tmp_path):
    monkeypatch.setenv("NSL_HOME", str(home))
    out = tmp_path / "diag.json"
    assert (
        _script().main(
            [
                "--checkpoint",
                "ckpt:tiny",
                "--checkpoint",
                "ckpt:tiny-ft",
                "--data",
                "d-base",
                "--data",
                "d-harsh:8",
                "--transitions",
                "40",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    result = json.loads(out.read_text())
    assert set(result["measurements"]) == {"ckpt:tiny", "ckpt:tiny-ft"}
    assert result["data"]["d-harsh:8"]["episodes"] == 8
    for per in result["measurements"].values():
        assert set(per) == {"d-base", "d-harsh:8"}
        for m in per.values():
            assert m["transitions"] == 40
            lg = m["logits"]
            assert lg["p1"] <= lg["median"] <= lg["p99"] and 0 <= lg["saturated"] <= 1
            assert 0 < lg["sigmoid_slope"] <= 0.25
            v = m["values"]
            for k in ("q_mean", "target_mean", "return_mean", "v0_mean", "success_rate"):
                assert 0.0 <= v[k] <= 1.0, k
            assert v["optimism"] == pytest.approx(v["target_mean"] - v["return_mean"])
            assert m["action_spread"]["logit_std_over_actions"] > 0
            assert m["auc"] is None or 0.0 <= m["auc"] <= 1.0
            assert set(m["dormant"]) == {"conv0", "conv1", "conv2", "conv3", "head0", "head1"}
            for layer in m["dormant"].values():
                assert 0 <= layer["tau=0"] <= layer["tau=0.025"] <= layer["tau=0.1"] <= 1
            assert m["dormant"]["conv3"]["units"] == 8 and m["dormant"]["head1"]["units"] == 16
            trunk = m["rank"]["trunk"]
            assert 1 <= trunk["srank"] <= min(40, trunk["dims"]) and 1.0 <= trunk["effective_rank"] <= trunk["dims"]
            assert m["gradient"]["total"] > 0
    change = result["weight_change"]["ckpt:tiny-ft"]
    assert change["reference"] == "ckpt:tiny" and change["total"] > 0  # a fine-tune at lr 0.01 moves the weights
    assert set(change["layers"]) >= {"columns.0.convs.0", "columns.0.out"}
    assert "ckpt:tiny" not in result["weight_change"]


def test_ranks_of_known_matrices():
    mod = _script()
    eye = mod.ranks(np.eye(5))
    assert eye["srank"] == 5 and eye["effective_rank"] == pytest.approx(5.0)
    one = mod.ranks(np.outer([1.0, 2.0, 3.0], [1.0, -1.0]))
    assert one["srank"] == 1 and one["effective_rank"] == pytest.approx(1.0)


def test_unknown_checkpoint_is_a_clear_error(home, monkeypatch, capsys):
    monkeypatch.setenv("NSL_HOME", str(home))
    assert _script().main(["--checkpoint", "nothing-here", "--data", "d-base"]) == 2
    assert "ckpt:NAME" in capsys.readouterr().err


def test_shrink_perturb_option_is_recorded_and_checked(home, monkeypatch, capsys):
    from nsl import workspace

    monkeypatch.setenv("NSL_HOME", str(home))
    assert (
        run_cli(
            "train",
            "--init",
            "ckpt:tiny",
            "--data",
            "d-harsh",
            "--steps",
            "1",
            "--name",
            "tiny-sp",
            "--batch-size",
            "8",
            "--shrink-perturb",
            "0.5,0.02",
        )
        == 0
    )
    run = json.loads((workspace.runs_dir() / "tiny-sp" / "run.json").read_text())
    assert run["training"]["shrink_perturb"] == [0.5, 0.02]
    command = json.loads((workspace.runs_dir() / "tiny-sp" / "command.json").read_text())
    assert command["options"]["shrink_perturb"] == "0.5,0.02"
    capsys.readouterr()
    assert (
        run_cli(
            "train",
            "--init",
            "ckpt:tiny",
            "--data",
            "d-harsh",
            "--steps",
            "1",
            "--name",
            "tiny-sp2",
            "--shrink-perturb",
            "0.5",
        )
        != 0
    )
    assert "write ALPHA,SIGMA" in capsys.readouterr().err
    assert (
        run_cli("train", "--data", "d-harsh", "--steps", "1", "--name", "tiny-sp3", "--shrink-perturb", "0.5,0.1") != 0
    )
    assert "give --init" in capsys.readouterr().err
    assert not (workspace.runs_dir() / "tiny-sp3").exists()
