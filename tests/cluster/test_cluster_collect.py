"""Collection and evaluation on a two-node Ray cluster give what one machine gives, even when a node is lost."""

from __future__ import annotations

import functools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from nsl.datasets import api
from tests.conftest import run_cli

ROOT = Path(__file__).resolve().parents[2]

# 16 episodes in chunks of 2: eight one-chunk Ray tasks over the two nodes
COLLECT = [
    "collect",
    "--shift",
    "harsh_lighting",
    "--episodes",
    "16",
    "--policy",
    "oracle:0.5",
    "--num-envs",
    "2",
    "--episodes-per-file",
    "5",
    "--seed",
    "3",
]
EVAL = [
    "eval",
    "--policy",
    "oracle:0.5",
    "--shift",
    "base,checkerboard_backing",
    "--episodes",
    "16",
    "--num-envs",
    "2",
    "--json",
]


def test_collect_and_eval_on_two_nodes_match_local(ray_cluster, capsys):
    import ray

    assert run_cli(*COLLECT, "--data", "local") == 0
    assert run_cli(*COLLECT, "--data", "on-ray", "--cluster", "ray", "--stop-after-files", "1") == 130  # Ctrl-C
    assert api.list_versions("on-ray") == []
    assert run_cli(*COLLECT, "--data", "on-ray", "--cluster", "ray") == 0  # resumes after the staged file
    assert "5 of 16 episodes already staged" in capsys.readouterr().err
    local, remote = api.open_version("local"), api.open_version("on-ray")
    assert remote.hash == local.hash
    assert remote.manifest["created"]["cluster"] == "ray" and local.manifest["created"]["cluster"] == "local"
    assert ray.is_initialized()  # the command used the cluster this process was connected to and left it up

    capsys.readouterr()
    assert run_cli(*EVAL) == 0
    local_eval = json.loads(capsys.readouterr().out)["results"]
    assert run_cli(*EVAL, "--cluster", "ray") == 0
    ray_eval = json.loads(capsys.readouterr().out)["results"]
    assert {s: r["successes"] for s, r in ray_eval.items()} == {s: r["successes"] for s, r in local_eval.items()}
    assert ray_eval == local_eval and set(ray_eval) == {"base", "checkerboard_backing"}

    cluster, worker = ray_cluster  # every listener of the cluster is on loopback
    processes = [
        info.process for node in (cluster.head_node, worker) for infos in node.all_processes.values() for info in infos
    ]
    listening = {
        c.laddr.ip
        for p in processes
        for c in psutil.Process(p.pid).net_connections("inet")
        if c.status == psutil.CONN_LISTEN
    }
    assert listening and listening <= {"127.0.0.1", "::ffff:127.0.0.1"}


class _SlowOnNode:
    """A policy factory: the oracle, slowed down on one node, where it touches ``flag`` at every step.

    The flag shows that the node is in the middle of a chunk; the pause keeps it there.  Elsewhere the
    policy waits for the flag before its first action, so the other node cannot finish every chunk first.
    The actions are the oracle's, so the episodes are too.
    """

    def __init__(self, node_id: str, flag: str):
        self.node_id, self.flag = node_id, flag

    def __call__(self):
        import ray

        from nsl.collectors import scripted_policy

        policy = scripted_policy("oracle:0.5")
        return _Paced(policy, self.flag, ray.get_runtime_context().get_node_id() == self.node_id)


class _Paced:
    def __init__(self, policy, flag: str, slow: bool):
        self.policy, self.flag, self.slow = policy, Path(flag), slow

    def __getattr__(self, name):
        return getattr(self.policy, name)

    def __call__(self, *args, **kwargs):
        if self.slow:
            self.flag.touch()
            time.sleep(0.1)
        else:
            deadline = time.time() + 60
            while not self.flag.exists() and time.time() < deadline:
                time.sleep(0.01)
        return self.policy(*args, **kwargs)


def test_a_node_lost_mid_chunk_changes_nothing(ray_cluster, tmp_path):
    import threading

    from ray import cloudpickle

    from nsl.cluster import RayExecutor
    from nsl.collectors import EnvConfig, collect_episodes, scripted_policy

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # Ray workers cannot import this test module
    cluster, worker = ray_cluster
    config = EnvConfig(shift="base")
    make_policy = functools.partial(scripted_policy, "oracle:0.5")
    spec = {"env": config.to_dict(), "policy": make_policy().describe(), "policy_ref": "oracle:0.5", "seed": 5}
    n = 24
    local = list(collect_episodes(config, make_policy, range(n), seed=5, batch=2))

    flag = tmp_path / "worker-node-busy"
    removed = threading.Event()

    def kill_the_worker_node_mid_chunk():
        deadline = time.time() + 120
        while not flag.exists() and time.time() < deadline:
            time.sleep(0.01)
        cluster.remove_node(worker, allow_graceful=False)  # its raylet, object store and workers die
        removed.set()

    killer = threading.Thread(target=kill_the_worker_node_mid_chunk, daemon=True)
    killer.start()
    executor = RayExecutor("ray")
    runner = executor.runner
    runner.chunks_per_task = 1  # 12 tasks of 2 episodes
    episodes = list(
        collect_episodes(config, _SlowOnNode(worker.node_id, str(flag)), range(n), seed=5, batch=2, runner=runner)
    )
    killer.join()
    executor.close()

    assert flag.exists() and removed.is_set()
    # the worker node was mid-chunk when it died and returned nothing: the head ran its chunk again
    assert dict(runner.chunks_per_node) == {cluster.head_node.node_id: n // 2}
    assert [e.index for e in episodes] == list(range(n))
    a = api.write_dataset("local", local, spec, 64, n, episodes_per_file=5)
    b = api.write_dataset("lost-node", episodes, spec, 64, n, episodes_per_file=5)
    assert b.hash == a.hash


@pytest.mark.slow  # torch and a checkpoint load in the Ray workers of both nodes
def test_checkpoint_policy_evaluates_the_same_on_two_nodes(ray_cluster, capsys):
    argv = [
        "eval",
        "--checkpoint",
        "base",
        "--shift",
        "base,harsh_lighting",
        "--episodes",
        "16",
        "--num-envs",
        "4",
        "--json",
    ]
    assert run_cli(*argv) == 0
    local = json.loads(capsys.readouterr().out)["results"]
    assert run_cli(*argv, "--cluster", "ray") == 0
    assert json.loads(capsys.readouterr().out)["results"] == local


@pytest.mark.slow  # a second driver process connects to the cluster
def test_a_killed_driver_resumes_to_the_same_hash(ray_cluster):
    cluster, _ = ray_cluster
    argv = [
        "collect",
        "--shift",
        "base",
        "--episodes",
        "48",
        "--policy",
        "oracle:0.5",
        "--episodes-per-file",
        "4",
        "--cluster",
        "ray",
    ]
    proc = subprocess.Popen(
        [sys.executable, "-m", "nsl", *argv, "--data", "killed"],
        cwd=ROOT,
        env={**os.environ, "RAY_ADDRESS": cluster.address},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    staged = api.dataset_root("killed") / ".staging/data/chunk-000/file-000.parquet"
    try:
        deadline = time.time() + 180
        while not staged.exists() and proc.poll() is None and time.time() < deadline:
            time.sleep(0.05)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert staged.exists() and api.list_versions("killed") == []
    assert run_cli(*argv, "--data", "killed") == 0  # resumes, on the cluster this process is connected to
    assert run_cli(*argv[:-2], "--data", "fresh") == 0  # locally, from scratch
    assert api.open_version("killed").hash == api.open_version("fresh").hash
