"""The study on a real Ray cluster (``ray.cluster_utils.Cluster`` on 127.0.0.1): every unit a Ray task, the catalog
written by the driver alone, the same numbers as a local run, and faults (a lost node, a killed driver) that change
none of them."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.cluster.conftest import FAST_FAILURE_DETECTION, NODE_MEMORY
from tests.study.conftest import STUDY_THREADS
from tests.study.test_study_run import _differences, _numbers

ROOT = Path(__file__).resolve().parents[2]


def _start_cluster():
    """A head node without CPUs (it only schedules) and two worker nodes of STUDY_THREADS CPUs each, so that a
    unit holding STUDY_THREADS CPUs computes with the local run's thread count.  Nodes take this process's
    environment as it is now."""
    from ray.cluster_utils import Cluster

    c = Cluster(
        initialize_head=True,
        head_node_args={
            "num_cpus": 0,
            "object_store_memory": NODE_MEMORY,
            "include_dashboard": False,
            # Ray runs workers at niceness 15: on a machine busy with other work they would barely get the CPU
            "_system_config": {**FAST_FAILURE_DETECTION, "worker_niceness": 0},
        },
    )
    try:
        nodes = [c.add_node(num_cpus=STUDY_THREADS, object_store_memory=NODE_MEMORY) for _ in range(2)]
        c.wait_for_nodes()
    except BaseException:
        c.shutdown()
        raise
    return c, nodes


@pytest.fixture
def cluster(monkeypatch):
    """The cluster of :func:`_start_cluster`, this process connected."""
    import ray

    c, nodes = _start_cluster()
    try:
        monkeypatch.setenv("RAY_ADDRESS", c.address)
        yield c, nodes
    finally:
        ray.shutdown()
        c.shutdown()


@pytest.fixture
def store_cluster(s3, s3_server, monkeypatch, tmp_path):
    """The cluster, with the S3 store's endpoint and credentials in its nodes' environment (as a real cluster's
    nodes have them) and each node's own NSL_HOME under ``tmp_path/nodes``; yields the bucket's URL."""
    import ray

    monkeypatch.setenv("FSSPEC_S3", json.dumps({"client_kwargs": {"endpoint_url": s3_server.endpoint}}))
    monkeypatch.setenv("NSL_STORE_CACHE", str(tmp_path / "nodes"))
    c, _ = _start_cluster()
    try:
        monkeypatch.setenv("RAY_ADDRESS", c.address)
        yield s3
    finally:
        ray.shutdown()
        c.shutdown()


def _starts(home: Path) -> dict[str, list[dict]]:
    """Every unit's starts on the cluster, from the notes its tasks leave (``where/``)."""
    where = home / "studies" / "mini" / "where"
    return {p.name: json.loads(p.read_text())["starts"] for p in where.iterdir()} if where.is_dir() else {}


def test_mini_study_on_a_cluster_gives_the_local_numbers_and_only_the_driver_writes_the_catalog(
    mini_run, mini_plan, tmp_path, monkeypatch, cluster
):
    from nsl.study import run_study, status_lines, study_status

    home = tmp_path / "cluster"
    monkeypatch.setenv("NSL_HOME", str(home))
    status = run_study(str(mini_plan), workers=1, progress=False, cluster="ray", unit_cpus=STUDY_THREADS)
    assert status["state"] == "finished" and status["nodes"] == 3 and status["cpus"] == 2 * STUDY_THREADS
    assert _differences(_numbers(home), _numbers(mini_run)) == []
    assert _numbers(home) == _numbers(mini_run)
    units = status["units"]
    ran = _starts(home)
    assert len(ran) == len(units) and all(len(s) == 1 for s in ran.values())  # every unit one Ray task, once
    assert len({s[0]["node"] for s in ran.values()}) == 2  # on both worker nodes
    assert all(u["node"] for u in units.values())
    lines = status_lines(study_status("mini"))
    assert all(" on " in line for line in lines[1:])  # `nsl study status` says where each unit ran


def test_a_node_lost_during_a_training_unit_changes_no_number(mini_run, mini_plan, tmp_path, monkeypatch, cluster):
    """The unit runs again on the other node and resumes from the shared NSL_HOME; the report is the same."""
    import threading

    from nsl.study import run_study

    c, nodes = cluster
    home = tmp_path / "lost"
    monkeypatch.setenv("NSL_HOME", str(home))
    where = home / "studies" / "mini" / "where"
    removed: dict[str, str] = {}

    def remove_a_training_node() -> None:
        deadline = time.monotonic() + 600  # bounded
        while time.monotonic() < deadline and not removed:
            for f in where.glob("train_*") if where.is_dir() else ():
                try:
                    node = json.loads(f.read_text())["node"].split("/")[1]
                except (OSError, ValueError, KeyError, IndexError):
                    continue
                for n in nodes:
                    if n.node_id.startswith(node):
                        c.remove_node(n)  # the node dies with the training task on it
                        removed[f.name] = node
                        return
            time.sleep(0.05)

    killer = threading.Thread(target=remove_a_training_node, daemon=True)
    killer.start()
    status = run_study(str(mini_plan), workers=1, progress=False, cluster="ray", unit_cpus=STUDY_THREADS)
    killer.join(timeout=5)
    assert removed, "no training unit started"
    ((unit, node),) = removed.items()
    starts = _starts(home)[unit]
    assert len(starts) == 2 and starts[0]["node"].endswith(node) and not starts[1]["node"].endswith(node)
    assert status["state"] == "finished"
    assert _differences(_numbers(home), _numbers(mini_run)) == []


def test_a_killed_driver_resumes_and_runs_no_finished_unit_again(mini_run, mini_plan, tmp_path, cluster):
    c, _ = cluster
    home = tmp_path / "driver"
    env = {
        **os.environ,
        "NSL_HOME": str(home),
        "RAY_ADDRESS": c.address,
        "PYTHONPATH": str(ROOT),
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    }
    cmd = [sys.executable, "-m", "nsl", "study", "run", str(mini_plan), "--quiet", "--cluster", "auto"]
    cmd += ["--unit-cpus", str(STUDY_THREADS)]
    n_units = len(json.loads((mini_run / "studies" / "mini" / "units.json").read_text())["units"])
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, process_group=0, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    status_file = home / "studies" / "mini" / "status.json"
    done_before: set[str] = set()
    for _ in range(6000):  # bounded: at most about 10 minutes on a busy machine
        if proc.poll() is not None:
            break
        try:
            units = json.loads(status_file.read_text())["units"]
        except (OSError, ValueError, KeyError):
            units = {}
        done_before = {n for n, u in units.items() if u["state"] == "done"}
        if len(done_before) >= n_units // 2:
            os.killpg(proc.pid, signal.SIGKILL)  # the driver only: its Ray tasks die with it
            proc.wait()
            break
        time.sleep(0.1)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()[-2000:] if proc.stderr else ""
    assert not (home / "studies" / "mini" / "report.md").exists()
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    starts = _starts(home)
    name = {n: n.replace(":", "_").replace("/", "_") for n in done_before}
    assert all(len(starts[name[n]]) == 1 for n in done_before)  # finished units were skipped
    assert len(starts) == n_units and max(len(s) for s in starts.values()) <= 2  # killed mid-way: started again once
    assert _differences(_numbers(home), _numbers(mini_run)) == []


def test_mini_study_through_an_s3_store_with_no_shared_nsl_home(
    mini_run, mini_plan, tmp_path, monkeypatch, store_cluster
):
    """Each node works in its own NSL_HOME: it pulls what a unit reads from S3 (checked by sha256) and pushes what
    the unit made, which the driver pulls and registers.  The numbers are the local run's."""
    from nsl.study import run_study

    home = tmp_path / "driver"
    monkeypatch.setenv("NSL_HOME", str(home))
    url = f"{store_cluster}/mini"
    status = run_study(str(mini_plan), progress=False, cluster="ray", unit_cpus=STUDY_THREADS, store=url)
    assert status["state"] == "finished" and status["store"] == url
    assert _differences(_numbers(home), _numbers(mini_run)) == []
    nodes = [p for p in (tmp_path / "nodes").glob("*/*") if p.is_dir()]
    assert len(nodes) == 2  # both worker nodes ran units, each in its own NSL_HOME
    assert not (home / ".cluster").exists() and not (home / "studies" / "mini" / "where").exists()
    assert not any((n / "catalog.sqlite").exists() for n in nodes)  # the catalog is the driver's alone
    made = {p.name for n in nodes for p in (n / "runs").iterdir()}
    assert made and made == {p.name for p in (home / "runs").iterdir()}  # every run was made on a node
    base = home / "datasets" / "mini-base-oracle" / "v1"  # collected on a node, pulled here, then by the others
    assert all(
        (n / base.relative_to(home) / "manifest.json").read_bytes() == (base / "manifest.json").read_bytes()
        for n in nodes
        if (n / "runs").is_dir() and any((n / "runs").iterdir())
    )
