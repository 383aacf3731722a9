"""Versions are content-addressed, immutable and append-only; collection resumes to the same hash."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from nsl import keys
from nsl.datasets import api
from nsl.errors import ConfigError, UnknownReferenceError
from tests.conftest import run_cli

ROOT = Path(__file__).resolve().parents[2]
COLLECT = [
    "collect",
    "--shift",
    "checkerboard_backing",
    "--episodes",
    "10",
    "--policy",
    "oracle:0.5",
    "--episodes-per-file",
    "3",
]


def _collect(name: str, *extra: str) -> int:
    return run_cli(*COLLECT, "--data", name, *extra)


def test_resumed_and_parallel_collections_equal_an_uninterrupted_one(capsys):
    assert _collect("whole") == 0
    whole = api.open_version("whole")
    assert api.verify("whole")["hash"] == whole.hash

    assert _collect("resumed", "--stop-after-files", "2") == 130  # interrupted like Ctrl-C after 2 files
    assert api.list_versions("resumed") == []  # nothing published
    capsys.readouterr()
    assert run_cli("dataset", "ls") == 0
    listing = capsys.readouterr().out
    assert "resumed@" not in listing and "unfinished: resumed episodes 0..9" in listing and "6 of 10 staged" in listing
    assert _collect("resumed") == 0
    assert "6 of 10 episodes already staged" in capsys.readouterr().err
    assert api.open_version("resumed").hash == whole.hash

    assert _collect("parallel", "--workers", "2") == 0
    assert api.open_version("parallel").hash == whole.hash


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_killed_collection_leaves_no_version_and_resumes_to_the_same_hash(engine):
    collect = [*COLLECT, "--engine", engine]
    argv = [sys.executable, "-m", "nsl", *collect, "--episodes", "16", "--episodes-per-file", "2", "--data", "killed"]
    proc = subprocess.Popen(argv, cwd=ROOT, env={**os.environ}, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    staged = api.dataset_root("killed") / ".staging/data/chunk-000/file-000.parquet"
    try:
        deadline = time.time() + 120
        while not staged.exists() and proc.poll() is None and time.time() < deadline:
            time.sleep(0.01)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert staged.exists()
    assert api.list_versions("killed") == [] and api.dataset_names() == []

    assert run_cli(*collect, "--episodes", "16", "--episodes-per-file", "2", "--data", "killed") == 0
    assert run_cli(*collect, "--episodes", "16", "--episodes-per-file", "2", "--data", "fresh") == 0
    assert api.open_version("killed").hash == api.open_version("fresh").hash
    assert not (api.dataset_root("killed") / ".staging").exists()


def test_append_makes_a_new_version_that_shares_the_old_files(make_synth):
    v1 = make_synth("grow", [3, 4, 2, 5, 3])
    v1_files = dict(v1.manifest["files"])
    v2 = make_synth("grow", [2, 6, 3], start=5)
    assert (v1.version, v2.version) == (1, 2) and v2.num_episodes == 8
    assert api.open_version("grow@v1").manifest["files"] == v1_files  # the old version is untouched
    assert api.verify("grow@v1")["hash"] == v1.hash
    for rel in v1_files:
        if rel.startswith("data/"):
            assert os.path.samefile(v1.root / rel, v2.root / rel)  # hard links, not copies
    assert v2.view(0, 5).content_hash == v1.view().content_hash  # the tier is the old version, by content
    assert api.open_view("grow").ref == "grow@v2"
    assert api.open_view("data:grow@v1:4").ref == "grow@v1:4"
    a = v2.view(5, 8).read_columns()
    assert a[keys.EPISODE_INDEX][0] == 5 and a[keys.INDEX][0] == 17


def test_tiers_are_nested_views(make_synth):
    make_synth("tiered", [3, 4, 2, 5, 3, 4, 2], successes={1, 4})
    rows = api.tiers("tiered", sizes=(2, 5))
    assert [r["episodes"] for r in rows] == [2, 5, 7]
    small, mid, full = (api.open_view(f"tiered:{k}").episodes_arrays() for k in (2, 5, 7))
    for inner, outer in ((small, mid), (mid, full)):
        n = len(inner[keys.INDEX])
        for k in (keys.OBS_IMAGE, keys.ACTION, keys.REWARD, keys.INDEX):
            assert np.array_equal(inner[k], outer[k][:n])
    assert rows[1]["success_rate"] == pytest.approx(2 / 5)
    assert len({r["content_hash"] for r in rows}) == 3
    train, held = api.episode_split("tiered", 2)
    assert (train.ref, held.ref) == ("tiered@v1:5", "tiered@v1[5:7]")
    assert [e[keys.EPISODE_INDEX][0] for e in held.iter_episodes()] == [5, 6]


def test_refs_and_settings_errors(make_synth):
    make_synth("grasp-base", [2, 2])
    with pytest.raises(UnknownReferenceError, match="unknown dataset 'grasp-bse'; did you mean 'grasp-base'"):
        api.open_view("grasp-bse")
    with pytest.raises(UnknownReferenceError, match="grasp-base@v1"):
        api.open_view("grasp-base@v3")
    with pytest.raises(ConfigError, match="tier 5 of grasp-base@v1 is larger"):
        api.open_view("grasp-base:5")
    with pytest.raises(ConfigError, match="malformed"):
        api.parse_ref("grasp@2")
    assert api.parse_ref("data:grasp@v2:25") == api.Ref("grasp", 2, 25)

    assert _collect("mixed", "--stop-after-files", "1") == 130
    with pytest.raises(ConfigError, match="unfinished collection with other settings.*--restart"):
        run_cli(
            "--debug", "collect", "--shift", "base", "--episodes", "10", "--policy", "oracle:0.5", "--data", "mixed"
        )
    assert _collect("mixed", "--episodes", "3") == 0  # same settings, fewer episodes: resumes and publishes
    with pytest.raises(ConfigError, match="collected with other settings"):
        run_cli("--debug", "collect", "--shift", "base", "--episodes", "6", "--policy", "oracle:0.5", "--data", "mixed")
