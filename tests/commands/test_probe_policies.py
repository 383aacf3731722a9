"""scripts/experiments/probe_policies.py, the research probes behind numbers in docs/experiments/: an ensemble
of one network repeated acts exactly like that network's own CEM policy, and the Polyak probe names what it needs."""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import pytest

import nsl
from nsl.collectors import parse_shift
from nsl.eval import EvalConfig, evaluate_outcomes
from nsl.learners import load_policy

ASSET = str(Path(nsl.__file__).parent / "assets" / "base")
SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "experiments" / "probe_policies.py"


def _probe():
    spec = importlib.util.spec_from_file_location("probe_policies", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_mean_q_of_one_network_twice_acts_like_that_network():
    probe = _probe()
    cfg = EvalConfig(episodes=8, seed=5, workers=1, batch=4)
    single = evaluate_outcomes(functools.partial(load_policy, ASSET), [parse_shift("base")], cfg, progress=False)
    twice = evaluate_outcomes(
        functools.partial(probe.mean_q_policy, [ASSET, ASSET]), [parse_shift("base")], cfg, progress=False
    )
    assert twice == single
    assert 0 < sum(single["base"]) < 8  # not a degenerate scene set: some succeed, some fail


def test_polyak_probe_needs_a_trainer_state(tmp_path):
    with pytest.raises(SystemExit, match="trainer_state.pt"):
        _probe().polyak_folder(Path(ASSET), tmp_path / "out")
