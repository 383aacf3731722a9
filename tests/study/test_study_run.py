"""The study end to end through the real CLI, and a kill -9 in the middle that resumes to the same numbers."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from nsl.catalog import Catalog
from nsl.datasets import api
from nsl.study.report import findings
from tests.conftest import run_cli
from tests.study.conftest import STUDY_THREADS

ROOT = Path(__file__).resolve().parents[2]


def _table(text: str, heading: str) -> list[list[str]]:
    """The rows (cells) of the first Markdown table after a heading."""
    lines = text.split(heading, 1)[1].splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("|"))
    block = []
    for ln in lines[start:]:
        if not ln.startswith("|"):
            break
        block.append([c.strip() for c in ln.strip("|").split("|")])
    return [r for r in block[2:]]  # without the header and the separator


def test_mini_study_writes_every_table_from_catalogued_outputs(mini_run, capsys):
    folder = mini_run / "studies" / "mini"
    text = (folder / "report.md").read_text()
    records = json.loads((folder / "records.json").read_text())
    for png in ("tiers.png", "curves.png", "early_stop.png", "weight_change.png"):
        assert (folder / png).stat().st_size > 1000
    # Table 5.1: base task + 2 shifts; the drop equals base minus shift success, from the catalog's evaluations.
    challenge = _table(text, "## Challenge table")
    assert [r[0] for r in challenge] == ["base task", "harsh lighting", "offset gripper"]
    with Catalog() as cat:
        base_id = cat.resolve_checkpoint("ckpt:base").id
        ev = {e.shift: e for e in cat.evaluations(base_id) if e.seed == 2000 and e.episodes == 4}
    assert set(ev) >= {"base", "harsh_lighting", "offset_gripper"}
    for row, shift in zip(challenge[1:], ("harsh_lighting", "offset_gripper")):
        assert row[1].startswith(f"{round(100 * ev[shift].successes / 4)}%")
        change = round(100 * (ev[shift].successes - ev["base"].successes) / 4)
        assert row[2].startswith(f"{change:+d} ")
        assert row[3].endswith("%")  # the study's real-robot figure beside ours
    # Table 5.2: an 'ours' and a 'study' row per shift; columns base policy, tiers 4 and 8, scratch
    tiers = _table(text, "## Fine-tuning by data size")
    assert [(r[0], r[1]) for r in tiers] == [
        ("harsh lighting", "ours"),
        ("", "study"),
        ("offset gripper", "ours"),
        ("", "study"),
    ]
    assert all(len(r) == 9 for r in tiers)  # + scratch_target, no_target and supervised
    # the tier cells are the fine-tuned checkpoints' catalogued evaluations
    with Catalog() as cat:
        ft = cat.resolve_checkpoint("ckpt:mini-ft-harsh-lighting-n8-k10-s0@latest")
        e = next(x for x in cat.evaluations(ft.id, "harsh_lighting") if x.episodes == 4)
        assert ft.step == 10 and ft.parent == base_id
        assert [(d.dataset, d.tier) for d in ft.data] == [("mini-base-oracle", 12), ("mini-harsh-lighting-by-base", 8)]
    assert tiers[0][4].startswith(f"{round(100 * e.successes / 4)}%")
    # the fine-tunes ran the product's recipe, and the report says so from what the checkpoint recorded
    from nsl.learners import FINE_TUNE_CONSERVATIVE, load_checkpoint

    training = load_checkpoint(ft.path).config["training"]
    assert training["conservative"] == FINE_TUNE_CONSERVATIVE == records["recipe"]["conservative"]
    assert f"conservative term {FINE_TUNE_CONSERVATIVE:g})" in text
    # tiers are nested views of one 8-episode collection by the base policy, with the plan's epsilon
    v = api.open_version("mini-harsh-lighting-by-base")
    spec = v.provenance["collections"][-1]["spec"]
    assert v.num_episodes == 8 and spec["policy_ref"] == "ckpt:base" and spec["policy"]["epsilon"] == 0.1
    # Table 5.2's base-task row: the base fine-tuned on 8 base-task episodes it collected, evaluated on the base task
    assert set(records["base_task"]) == {"4", "8"} and records["base_task"]["8"][0]["episodes"] == 4
    assert api.open_version("mini-base-by-base").num_episodes == 8
    # Fig. 5.8: each shift's 8-episode fine-tune against the base, layer by layer, over the base-task fine-tune's
    from nsl.learners import layer_distances

    with Catalog() as cat:
        base_dir, bt = (cat.resolve_checkpoint(r).path for r in ("ckpt:base", "ckpt:mini-ft-base-n8-k10-s0@latest"))
    norm = layer_distances(base_dir, bt)
    wc = records["weight_change"]
    assert set(wc) == {"harsh_lighting", "offset_gripper"} and list(wc["harsh_lighting"]) == list(norm)
    assert all(v > 0 for v in norm.values())  # ten steps changed every layer
    raw = layer_distances(base_dir, ft.path)
    assert wc["harsh_lighting"] == pytest.approx({k: raw[k] / norm[k] for k in norm})
    assert "## Where the weights change (Fig. 5.8)" in text and "![where the weights change](weight_change.png)" in text
    # Table 5.3: one row per stage plus the base task; the matrix has base policy + 2 stages
    assert [r[0] for r in _table(text, "## The continual sequence")] == [
        "harsh lighting",
        "offset gripper",
        "base task",
    ]
    assert len(records["continual"]["cells"]) == 3
    assert all(c is not None for row in records["continual"]["cells"] for c in row)
    # stage 2 collected with stage 1's policy and fine-tuned from it
    with Catalog() as cat:
        s1 = cat.resolve_checkpoint("ckpt:mini-ft-harsh-lighting-n8-k10-s0@latest")
        s2 = cat.resolve_checkpoint("ckpt:mini-c2-offset-gripper-n8-k10-s0@latest")
    assert s2.parent == s1.id
    assert (
        api.open_version("mini-offset-gripper-by-ft-harsh-lighting-n8-k10-s0").provenance["collections"][-1]["spec"][
            "policy_ref"
        ]
        == "ckpt:mini-ft-harsh-lighting-n8-k10-s0@latest"
    )
    # curves: steps 0, 5, 10 for target and base; early stopping: every planned criterion has a row
    assert [r["step"] for r in records["curves"]["ft"]["0"]] == [0, 5, 10]
    es = _table(text, "## Overfitting and early stopping")
    assert [r[0] for r in es] == ["best point (oracle)", "last step (no stopping)", "eval", "softopc", "auc", "td"]
    # the study's curves run `nsl train`'s own scorer, so the TD criterion chooses a step like the others
    assert es[-1][1] != "no choice" and any(ch.isdigit() for ch in es[-1][1]), es
    # findings (a)-(e), each with a verdict, in the report and recomputed from the records
    verdicts = {f.key: f.verdict for f in findings(records)}
    assert set(verdicts) == set("abcdefghij")
    # online rounds: round 1 of ft at half target data is Table 5.2's tier-4 fine-tune; round 2 collects with it
    online = records["online"]
    assert set(online) == {"ft@0.5", "new_head@0.5", "ft@0.24", "ft@0.99"}
    assert all(x is not None for run in online.values() for x in run["success"]) and online["ft@0.5"]["grasps"] == [
        0,
        4,
        8,
    ]
    with Catalog() as cat:
        r2 = cat.resolve_checkpoint("ckpt:mini-online-ft-p50-harsh-lighting-r2-k10-s0@latest")
        r1 = cat.resolve_checkpoint("ckpt:mini-ft-harsh-lighting-n4-k10-s0@latest")
    assert r2.parent == r1.id
    assert sorted(d.dataset for d in r2.data) == [
        "mini-base-oracle",
        "mini-harsh-lighting-by-base",
        "mini-harsh-lighting-by-ft-harsh-lighting-n4-k10-s0",
    ]
    assert (folder / "online.png").is_file() and "## Online fine-tuning (Figs. 5.10, 5.11)" in text
    # the baselines that separate the causes ran as the plan defines them
    with Catalog() as cat:
        alone = cat.resolve_checkpoint("ckpt:mini-scratch_target-harsh-lighting-n8-k10-s0@latest")
        none = cat.resolve_checkpoint("ckpt:mini-no_target-k10-s0@latest")
    assert [d.dataset for d in alone.data] == ["mini-harsh-lighting-by-base"]
    assert load_checkpoint(alone.path).config["method"] == "scratch"  # the base gives only its architecture
    assert [d.dataset for d in none.data] == ["mini-base-oracle"] and none.parent == base_id
    assert tiers[0][7] != "-" and tiers[2][7] != "-"  # no_target on each shift
    # the supervised features: a classifier's trunk in the base's architecture, fine-tuned with a fresh head
    with Catalog() as cat:
        features = cat.resolve_checkpoint("ckpt:mini-features@latest")
        supervised = cat.resolve_checkpoint("ckpt:mini-supervised-harsh-lighting-n8-k10-s0@latest")
    assert load_checkpoint(features.path).config["data"]["features"]["classes"] == 3
    assert supervised.parent == features.id and load_checkpoint(supervised.path).config["method"] == "new_head"
    assert tiers[0][8] != "-" and tiers[1][8] == "2%"  # ours, and the study's ImageNet column (harsh lighting)
    # how well the features learned their classification, from the features checkpoint, in the table's text
    got = records["features"]
    assert got["classes"] == 3 and got["chance"] == pytest.approx(1 / 3) and 0 <= got["heldout_accuracy"] <= 1
    assert f"{100 * got['heldout_accuracy']:.1f}% of held-out frames of the 3 train objects (chance 33.33%" in text
    # every top-tier fine-tune on every shift, against the base policy there
    cross = _table(text, "The top tier's fine-tunes on every shift")
    assert [r[0] for r in cross] == ["base policy", "harsh lighting", "offset gripper"]
    assert all("[" in cell for r in cross for cell in r[1:])
    for f in _table(text, "## Findings"):
        assert f[1].strip("*") in ("holds", "fails", "not resolvable", "not measured")
    # status lists every unit as done, with time spent
    capsys.readouterr()
    assert run_cli("study", "status", "mini") == 0
    out = capsys.readouterr().out
    units = json.loads((folder / "units.json").read_text())["units"]
    assert f"{len(units)} done" in out and "0 left" in out and "minutes spent" in out


def test_rerun_of_a_finished_study_does_no_work(mini_run, mini_plan, capsys):
    folder = mini_run / "studies" / "mini"
    before = {p: p.stat().st_mtime_ns for p in (mini_run / "runs").rglob("model.safetensors")}
    assert run_cli("study", "run", str(mini_plan), "--quiet") == 0
    status = json.loads((folder / "status.json").read_text())
    assert status["state"] == "finished"
    assert all(u["state"] == "done" for u in status["units"].values())
    assert {p: p.stat().st_mtime_ns for p in (mini_run / "runs").rglob("model.safetensors")} == before


def _numbers(home: Path, study: str = "mini") -> dict:
    """The measured records of a finished study (a plan without an experiment has no record of it)."""
    records = json.loads((home / "studies" / study / "records.json").read_text())
    assert "base_policy" in records and "finetune" in records
    return {k: records.get(k) for k in ("base_policy", "finetune", "continual", "curves", "early_stop")}


def _kill_9_then_rerun(plan: Path, study: str, local: Path, home: Path) -> None:
    """Run ``plan`` in a process killed with SIGKILL after a random number of finished units, run the same command
    again, and check the numbers against the uninterrupted run in ``local``."""
    env = {
        **os.environ,
        "NSL_HOME": str(home),
        "PYTHONPATH": str(ROOT),
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
        "OMP_NUM_THREADS": str(STUDY_THREADS),  # the uninterrupted run's thread count
    }
    cmd = [sys.executable, "-m", "nsl", "study", "run", str(plan), "--quiet"]
    n_units = len(json.loads((local / "studies" / study / "units.json").read_text())["units"])
    seed = int(os.environ.get("NSL_KILL_SEED", "0"))  # NSL_KILL_SEED=k tries another point, reproducibly
    kill_after = random.Random(seed).randint(2, n_units - 2)  # this many units done before the kill
    print(f"killing after {kill_after} units (NSL_KILL_SEED={seed})")
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=env, process_group=0, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    status_file = home / "studies" / study / "status.json"
    killed = False
    for _ in range(6000):  # bounded: at most about 10 minutes on a busy machine
        if proc.poll() is not None:
            break
        try:
            status = json.loads(status_file.read_text())
        except (OSError, ValueError):
            status = {}
        done = sum(u["state"] == "done" for u in status.get("units", {}).values())
        if done >= kill_after:
            os.killpg(proc.pid, signal.SIGKILL)  # the study and the simulator workers it started
            proc.wait()
            killed = True
            break
        time.sleep(0.1)
    assert killed, "the study finished or stalled before the kill point"
    assert not (home / "studies" / study / "report.md").exists()
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    killed_numbers, whole = _numbers(home, study), _numbers(local, study)
    assert _differences(killed_numbers, whole) == [], f"killed after {kill_after} units"
    assert killed_numbers == whole


def test_kill_9_then_rerun_gives_the_uninterrupted_numbers(micro_run, micro_plan, tmp_path):
    """The micro plan: base data, a checkpoint policy's collection, a fine-tune and evaluations."""
    _kill_9_then_rerun(micro_plan, "micro", micro_run, tmp_path / "killed")


@pytest.mark.slow  # every experiment of the study (about 4 minutes); the micro plan's test is the default
def test_kill_9_of_the_mini_study_then_rerun_gives_the_uninterrupted_numbers(mini_run, mini_plan, tmp_path):
    _kill_9_then_rerun(mini_plan, "mini", mini_run, tmp_path / "killed")


def _differences(a, b, path: str = "") -> list[str]:
    """Where two records differ, as 'path: a != b' lines (so a failure says which number moved)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b), key=str) for d in _differences(a.get(k), b.get(k), f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]
