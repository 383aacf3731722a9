"""Fixtures for the study tests: a small plan file (every experiment, toy sizes) and one finished run of it."""

from __future__ import annotations

import pytest


def plan_data(name: str) -> str:
    """A test plan's base data (12 scripted episodes named NAME-base-oracle), target collections of 8 episodes and
    evaluations on 4 scenes."""
    return f"""
[base_data]
source = "plan"

[[base_data.datasets]]
name = "{name}-base-oracle"
policy = "oracle:0.5"
seed = 1
episodes = 12

[collect]
episodes = 8
epsilon = 0.1
seed = 5

[eval]
episodes = 4
seed = 2000
"""


# Smaller than the shipped `tiny` plan so that the end-to-end and kill tests stay within a few minutes:
# two shifts, tiers 4/8, 10 training steps, 4 evaluation scenes, one seed, every experiment switched on.
MINI_PLAN = (
    """
name = "mini"
base = "ckpt:base"
shifts = ["harsh_lighting", "offset_gripper"]
checkpoint_every = 5
"""
    + plan_data("mini")
    + """
[finetune]
tiers = [4, 8]
steps = 10
seeds = [0]
baselines = ["scratch", "scratch_target", "no_target", "supervised"]
cross_shift = true
base_task = true

[supervised]
classes = 3
frames = 3
steps = 4

[online]
shift = "harsh_lighting"
rounds = 2
episodes = 4
steps = 10
methods = ["ft", "new_head"]
ratios = [0.24, 0.99]

[continual]
sequence = ["harsh_lighting", "offset_gripper"]
episodes = 8
steps = 10

[curves]
shift = "harsh_lighting"
episodes = 8
methods = ["ft"]
steps = 10
every = 5
eval_episodes = 4
seeds = [0]

[early_stop]
shift = "offset_gripper"
episodes = 8
steps = 10
every = 5
eval_episodes = 4
criteria = ["eval", "softopc", "auc", "td"]
patience = 2
holdout = 0.25
"""
)


# The fewest units that still move every kind of folder a study makes (base data, a checkpoint policy's
# collection, a fine-tune, evaluations: 7 units).  The cluster's fault tests (a lost node, a killed driver, the S3
# store) run it; the mini plan's every experiment runs on the cluster once, uninterrupted.
MICRO_PLAN = (
    """
name = "micro"
base = "ckpt:base"
shifts = ["harsh_lighting"]
checkpoint_every = 5
continual = false
curves = false
early_stop = false
"""
    + plan_data("micro")
    + """
[finetune]
tiers = [8]
steps = 10
seeds = [0]
baselines = []
"""
)


# Torch threads of every mini study run: Q-values (and so the held-out TD error the records keep) are float sums
# whose last bits depend on how many threads add them up, and earlier tests may have changed this process's count.
STUDY_THREADS = 2


def _plan_file(tmp_path_factory, name: str, text: str):
    path = tmp_path_factory.mktemp("plans") / f"{name}.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="session")
def mini_plan(tmp_path_factory):
    return _plan_file(tmp_path_factory, "mini", MINI_PLAN)


@pytest.fixture(scope="session")
def micro_plan(tmp_path_factory):
    return _plan_file(tmp_path_factory, "micro", MICRO_PLAN)


@pytest.fixture(scope="session")
def mini_home(tmp_path_factory):
    return tmp_path_factory.mktemp("mini_home")


@pytest.fixture(scope="session")
def micro_home(tmp_path_factory):
    return tmp_path_factory.mktemp("micro_home")


@pytest.fixture
def micro_run(micro_plan, micro_home, monkeypatch):
    """The micro plan run once, uninterrupted, in this process (the reference of the cluster's fault tests)."""
    from nsl.study import run_study

    monkeypatch.setenv("NSL_HOME", str(micro_home))
    if not (micro_home / "studies" / "micro" / "report.md").is_file():
        _with_study_threads(lambda: run_study(str(micro_plan), progress=False))
    return micro_home


def _with_study_threads(fn):
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(STUDY_THREADS)  # as the killed run's process (OMP_NUM_THREADS): the same float sums
    try:
        return fn()
    finally:
        torch.set_num_threads(threads)


@pytest.fixture
def mini_run(mini_plan, mini_home, monkeypatch):
    """The mini plan run once, uninterrupted, through the real CLI (shared by the tests of this folder)."""
    from tests.conftest import run_cli

    monkeypatch.setenv("NSL_HOME", str(mini_home))
    if not (mini_home / "studies" / "mini" / "report.md").is_file():
        assert _with_study_threads(lambda: run_cli("study", "run", str(mini_plan), "--quiet")) == 0
    return mini_home
