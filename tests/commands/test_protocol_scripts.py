"""The protocol scripts behind the fine-tuning tables of docs/experiments/ run the commands they say: three seeds of
one recipe on each of the five study shifts, each scored on the reporting scenes of its shift and of the base task,
and the base task after every fine-tune on 1,000 scenes in one paired evaluation with the base."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import recorded_calls

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "experiments" / "protocol_reporting.sh"
SHIFTS = [
    "harsh_lighting@2",
    "transparent_objects@0.8",
    "checkerboard_backing@0.4",
    "extend_gripper@2",
    "offset_gripper@0.25",
]


def _opt(call, flag):
    return [call[i + 1] for i, a in enumerate(call) if a == flag]


@pytest.mark.parametrize("recipe", [(), ("mcc01", "--n-step", "8", "--crop", "2", "--conservative", "0.1")])
def test_protocol_reporting_trains_and_scores_three_seeds_of_one_recipe(tmp_path, recipe):
    calls = recorded_calls(SCRIPT, tmp_path, *recipe, PY="true")  # the stand-in writes no records to summarise
    name = recipe[0] if recipe else None
    options = list(recipe[1:]) if recipe else ["--n-step", "8", "--crop", "2"]
    trains = {_opt(c, "--name")[0]: c for c in calls if c[0] == "train"}
    expected = {}
    for s in SHIFTS:
        slug = s.replace("_", "-").replace("@", "-")
        seeds = (
            [f"{name}-{slug}", f"{name}s1-{slug}", f"{name}s2-{slug}"]
            if name
            else [f"mcft-{slug}", f"mcs1-{slug}", f"mcs2-{slug}"]
        )
        expected.update({run: seed for seed, run in enumerate(seeds)})
        for run in seeds:  # each seed scored on 200 reporting scenes of its shift and of the base task
            assert any(
                _opt(c, "--checkpoint") == [f"ckpt:{run}@latest"]
                and _opt(c, "--shift") == [f"{s},base"]
                and _opt(c, "--seed") == ["2000"]
                and _opt(c, "--episodes") == ["200"]
                for c in calls
            ), run
    assert set(trains) == set(expected)
    for run, seed in expected.items():
        call = trains[run]
        assert _opt(call, "--init") == ["ckpt:rounds-r4@6000"] and _opt(call, "--steps") == ["1000"]
        assert call[call.index("--checkpoint-every") + 2 :][: len(options)] == options  # the recipe's options
        assert _opt(call, "--seed") == ([str(seed)] if seed else [])
        target = [d for d in _opt(call, "--data") if d.endswith("=0.5")]
        assert len(target) == 1 and target[0].startswith("protocol-rounds-")  # the study's 800 episodes by the base
    paired = [c for c in calls if c[0] == "eval" and _opt(c, "--episodes") == ["1000"]]
    assert len(paired) == 1 and _opt(paired[0], "--shift") == ["base"] and _opt(paired[0], "--seed") == ["2000"]
    refs = _opt(paired[0], "--checkpoint")[0].split(",")
    assert refs[0] == "ckpt:rounds-r4@6000" and sorted(refs[1:]) == sorted(f"ckpt:{r}@latest" for r in expected)
