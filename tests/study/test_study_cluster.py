"""The study on a real Ray cluster (``ray.cluster_utils.Cluster`` on 127.0.0.1): every unit a Ray task, the catalog
written by the driver alone, the same numbers as a local run, and faults (a lost node, a killed driver) and a store
instead of a shared NSL_HOME that change none of them.

The mini plan (every experiment) runs on the cluster once; the faults and the store run the micro plan (7 units:
base data, a checkpoint policy's collection, a fine-tune, evaluations).  One cluster serves every test of this module
but the lost node's, which removes a node and so starts its own."""

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

# its tests share the micro plan's run: one xdist worker takes them all (tests/conftest.py); the one mini-study test
# here is `slow`, and `make test-slow` runs in one process
pytestmark = pytest.mark.xdist_group("micro_run")

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


@pytest.fixture(scope="module")
def shared_cluster(s3_server, tmp_path_factory):
    """The cluster of :func:`_start_cluster` for the whole module.  Its nodes get the S3 store's endpoint and a
    folder for their own NSL_HOMEs in their environment (as a real cluster's nodes have them); a run without
    ``--store`` reads neither.  Yields ``(cluster, nodes folder)``."""
    import ray

    nodes_home = tmp_path_factory.mktemp("nodes")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("FSSPEC_S3", json.dumps({"client_kwargs": {"endpoint_url": s3_server.endpoint}}))
        mp.setenv("NSL_STORE_CACHE", str(nodes_home))
        for var in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY"):
            mp.setenv(var, "testing")  # the s3 fixture's dummy credentials, which the moto server accepts
        mp.delenv("AWS_PROFILE", raising=False)
        c, _ = _start_cluster()
    try:
        yield c, nodes_home
    finally:
        ray.shutdown()
        c.shutdown()


@pytest.fixture
def cluster(shared_cluster, monkeypatch):
    """The module's cluster, this process pointed at it (RAY_ADDRESS) and disconnected after the test."""
    import ray

    c, _ = shared_cluster
    monkeypatch.setenv("RAY_ADDRESS", c.address)
    try:
        yield c
    finally:
        ray.shutdown()


@pytest.fixture
def own_cluster(monkeypatch):
    """A cluster of this test's own (it removes a node): ``(cluster, worker nodes)``."""
    import ray

    c, nodes = _start_cluster()
    try:
        monkeypatch.setenv("RAY_ADDRESS", c.address)
        yield c, nodes
    finally:
        ray.shutdown()
        c.shutdown()


def _micro_numbers(home: Path) -> dict:
    return _numbers(home, "micro")


def _starts(home: Path, study: str = "micro") -> dict[str, list[dict]]:
    """Every unit's starts on the cluster, from the notes its tasks leave (``where/``)."""
    where = home / "studies" / study / "where"
    return {p.name: json.loads(p.read_text())["starts"] for p in where.iterdir()} if where.is_dir() else {}


def _on_the_cluster_gives_the_local_numbers(plan: Path, study: str, local: Path, home: Path) -> None:
    """Run ``plan`` on the cluster into ``home`` (NSL_HOME already points there) and check it against ``local``."""
    from nsl.catalog import Catalog
    from nsl.study import run_study, status_lines, study_status

    status = run_study(str(plan), workers=1, progress=False, cluster="ray", unit_cpus=STUDY_THREADS)
    assert status["state"] == "finished" and status["nodes"] == 3 and status["cpus"] == 2 * STUDY_THREADS
    assert _differences(_numbers(home, study), _numbers(local, study)) == []
    assert _numbers(home, study) == _numbers(local, study)
    units = status["units"]
    ran = _starts(home, study)
    assert len(ran) == len(units) and all(len(s) == 1 for s in ran.values())  # every unit one Ray task, once
    assert len({s[0]["node"] for s in ran.values()}) == 2  # on both worker nodes
    assert all(u["node"] for u in units.values())
    lines = status_lines(study_status(study))
    assert all(" on " in line for line in lines[1:])  # `nsl study status` says where each unit ran
    # the driver registered every checkpoint the units made, as a local run does
    with Catalog() as here, Catalog(local / "catalog.sqlite") as there:
        assert sorted(c.id for c in here.checkpoints()) == sorted(c.id for c in there.checkpoints())


def test_micro_study_on_a_cluster_gives_the_local_numbers_and_only_the_driver_writes_the_catalog(
    micro_run, micro_plan, tmp_path, monkeypatch, cluster
):
    home = tmp_path / "cluster"
    monkeypatch.setenv("NSL_HOME", str(home))
    _on_the_cluster_gives_the_local_numbers(micro_plan, "micro", micro_run, home)


@pytest.mark.slow  # every experiment on the cluster (about 2 minutes); the micro plan's test is the default
def test_mini_study_on_a_cluster_gives_the_local_numbers_and_only_the_driver_writes_the_catalog(
    mini_run, mini_plan, tmp_path, monkeypatch, cluster
):
    home = tmp_path / "cluster"
    monkeypatch.setenv("NSL_HOME", str(home))
    _on_the_cluster_gives_the_local_numbers(mini_plan, "mini", mini_run, home)


def test_a_node_lost_during_a_training_unit_changes_no_number(
    micro_run, micro_plan, tmp_path, monkeypatch, own_cluster
):
    """The unit runs again on the other node and resumes from the shared NSL_HOME; the report is the same."""
    import threading

    from nsl.study import run_study

    c, nodes = own_cluster
    home = tmp_path / "lost"
    monkeypatch.setenv("NSL_HOME", str(home))
    where = home / "studies" / "micro" / "where"
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
    status = run_study(str(micro_plan), workers=1, progress=False, cluster="ray", unit_cpus=STUDY_THREADS)
    killer.join(timeout=5)
    assert removed, "no training unit started"
    ((unit, node),) = removed.items()
    starts = _starts(home)[unit]
    assert len(starts) == 2 and starts[0]["node"].endswith(node) and not starts[1]["node"].endswith(node)
    assert status["state"] == "finished"
    assert _differences(_micro_numbers(home), _micro_numbers(micro_run)) == []


def test_a_killed_driver_resumes_and_runs_no_finished_unit_again(micro_run, micro_plan, tmp_path, cluster):
    c = cluster
    home = tmp_path / "driver"
    env = {
        **os.environ,
        "NSL_HOME": str(home),
        "RAY_ADDRESS": c.address,
        "PYTHONPATH": str(ROOT),
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    }
    cmd = [sys.executable, "-m", "nsl", "study", "run", str(micro_plan), "--quiet", "--cluster", "auto"]
    cmd += ["--unit-cpus", str(STUDY_THREADS)]
    n_units = len(json.loads((micro_run / "studies" / "micro" / "units.json").read_text())["units"])
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, process_group=0, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    status_file = home / "studies" / "micro" / "status.json"
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
    assert not (home / "studies" / "micro" / "report.md").exists()
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    starts = _starts(home)
    name = {n: n.replace(":", "_").replace("/", "_") for n in done_before}
    assert all(len(starts[name[n]]) == 1 for n in done_before)  # finished units were skipped
    assert len(starts) == n_units and max(len(s) for s in starts.values()) <= 2  # killed mid-way: started again once
    assert _differences(_micro_numbers(home), _micro_numbers(micro_run)) == []


def test_micro_study_through_an_s3_store_with_no_shared_nsl_home(
    micro_run, micro_plan, tmp_path, monkeypatch, s3, shared_cluster, cluster
):
    """Each node works in its own NSL_HOME: it pulls what a unit reads from S3 (checked by sha256) and pushes what
    the unit made, which the driver pulls and registers.  The numbers are the local run's."""
    from nsl.study import run_study

    home = tmp_path / "driver"
    monkeypatch.setenv("NSL_HOME", str(home))
    url = f"{s3}/micro"
    _, nodes_home = shared_cluster
    status = run_study(str(micro_plan), progress=False, cluster="ray", unit_cpus=STUDY_THREADS, store=url)
    assert status["state"] == "finished" and status["store"] == url
    assert _differences(_micro_numbers(home), _micro_numbers(micro_run)) == []
    nodes = [p for p in nodes_home.glob("*/*") if p.is_dir()]
    assert len(nodes) == 2  # both worker nodes ran units, each in its own NSL_HOME
    assert not (home / ".cluster").exists() and not (home / "studies" / "micro" / "where").exists()
    assert not any((n / "catalog.sqlite").exists() for n in nodes)  # the catalog is the driver's alone

    def runs(home: Path) -> set[str]:  # the run folders (not the writers' lock files beside them)
        return {p.name for p in (home / "runs").glob("[!.]*")} if (home / "runs").is_dir() else set()

    made = set().union(*(runs(n) for n in nodes))
    assert made and made == runs(home)  # every run was made on a node
    base = home / "datasets" / "micro-base-oracle" / "v1"  # collected on a node, pulled here, then by the others
    assert all(
        (n / base.relative_to(home) / "manifest.json").read_bytes() == (base / "manifest.json").read_bytes()
        for n in nodes
        if (n / "runs").is_dir() and any((n / "runs").iterdir())
    )
