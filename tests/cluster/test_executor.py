"""The executor: choosing a cluster, the one-line error without Ray, and units as Ray tasks with num_cpus."""

from __future__ import annotations

import functools
import re
import sys

import pytest

from nsl import workspace
from nsl.cluster import Executor, Unit, UnitFailed, open_executor, parse_cluster
from nsl.errors import ConfigError, EnvironmentSetupError
from tests.conftest import run_cli

COLLECT = ["collect", "--shift", "base", "--episodes", "2", "--policy", "random", "--data", "d"]


def setup_module(module) -> None:
    from ray import cloudpickle

    cloudpickle.register_pickle_by_value(module)  # Ray workers cannot import this test module; ship its functions


def test_cluster_spec_comes_from_the_option_then_the_environment(monkeypatch):
    monkeypatch.delenv("NSL_CLUSTER", raising=False)
    assert parse_cluster(None) == "local"
    assert [parse_cluster(s) for s in ("ray", "auto", "ray://10.0.0.1:10001")] == [
        "ray",
        "auto",
        "ray://10.0.0.1:10001",
    ]
    monkeypatch.setenv("NSL_CLUSTER", "ray")
    assert parse_cluster(None) == "ray" and parse_cluster("local") == "local"
    monkeypatch.setenv("NSL_CLUSTER", "slurm")
    with pytest.raises(ConfigError, match=r"\$NSL_CLUSTER 'slurm' is not a cluster; use local, ray"):
        parse_cluster(None)
    with pytest.raises(ConfigError, match="--cluster 'ray://' is not a cluster"):
        parse_cluster("ray://")


def test_without_ray_cluster_commands_fail_in_one_line_saying_how_to_install(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now fails as if Ray were not installed
    with pytest.raises(
        EnvironmentSetupError,
        match=r"needs Ray, which is not installed; install it with "
        r"`pip install 'nsl\[ray\]'`",
    ):
        open_executor("ray")
    assert run_cli(*COLLECT, "--cluster", "ray") == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "nsl: error: --cluster ray needs Ray, which is not installed; install it with "
        "`pip install 'nsl[ray]'` (in a checkout: `pip install -e '.[ray]'`)"
    )
    monkeypatch.setenv("NSL_CLUSTER", "auto")
    assert run_cli("eval", "--policy", "random", "--episodes", "2") == 2
    assert capsys.readouterr().err.strip().startswith("nsl: error: --cluster auto needs Ray")
    assert run_cli("study", "run", "tiny", "--quiet") == 2  # the study's units too, before any of them runs
    err = capsys.readouterr().err.strip()
    assert err.startswith("nsl: error: --cluster auto needs Ray") and len(err.splitlines()) == 1
    assert not (workspace.home() / "studies" / "tiny" / "status.json").exists()
    # local stays the default and needs no Ray
    monkeypatch.delenv("NSL_CLUSTER")
    assert run_cli(*COLLECT) == 0


def _square(x: int) -> int:
    return x * x


def _node_and_home(tag: str) -> tuple[str, str]:
    """Which node ran this, and a file written under NSL_HOME (which the driver must then see).

    The first two units wait for each other (bounded): with one CPU per node, two units running at once are on
    the two nodes, however slowly a loaded machine starts a node's worker.
    """
    import time

    import ray

    started = workspace.home() / "units" / "started"
    started.mkdir(parents=True, exist_ok=True)
    (started / tag).touch()
    deadline = time.monotonic() + 60
    while len(list(started.iterdir())) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    path = workspace.home() / "units" / f"{tag}.txt"
    workspace.atomic_write_bytes(path, tag.encode())
    return ray.get_runtime_context().get_node_id(), str(path)


def _visible_gpus() -> tuple[str, str | None]:
    """Which node ran this, and the GPUs Ray let it see."""
    import os

    import ray

    return ray.get_runtime_context().get_node_id(), os.environ.get("CUDA_VISIBLE_DEVICES")


def _fail() -> None:
    raise ConfigError("--steps 0 must be at least 1")


def test_units_run_locally_in_submission_order():
    with open_executor("local") as ex:
        assert type(ex) is Executor and ex.runner is None
        out = list(ex.run_units(Unit(f"sq{i}", _square, (i,)) for i in range(4)))
        assert out == [("sq0", 0), ("sq1", 1), ("sq2", 4), ("sq3", 9)]
        ex.submit(Unit("bad", _fail))
        with pytest.raises(UnitFailed, match=r"^unit bad failed: --steps 0 must be at least 1$") as e:
            ex.wait()
        assert e.value.key == "bad" and isinstance(e.value.__cause__, ConfigError)


def test_units_run_as_ray_tasks_on_both_nodes_and_need_the_shared_workspace(ray_cluster):
    import ray

    cluster, worker = ray_cluster
    with open_executor("ray") as ex:
        assert ex.describe()["nodes"] == 2 and ex.cpus() == 2
        assert dict(ex.run_units(Unit(f"sq{i}", _square, (i,), num_cpus=1) for i in range(6))) == {
            f"sq{i}": i * i for i in range(6)
        }
        out = dict(ex.run_units(Unit(f"u{i}", functools.partial(_node_and_home, f"u{i}")) for i in range(4)))
        nodes = {node for node, _ in out.values()}
        assert nodes == {cluster.head_node.node_id, worker.node_id}
        for key, (_, path) in out.items():
            assert path == str(workspace.home().resolve() / "units" / f"{key}.txt")
            assert open(path).read() == key

        ex.submit(Unit("needs-2-cpus", _square, (3,), num_cpus=2))  # no node has 2 CPUs: the unit waits
        ex.submit(Unit("bad", _fail))
        with pytest.raises(UnitFailed, match=r"^unit bad failed: --steps 0 must be at least 1$"):
            ex.wait()
        assert ex.outstanding == 1
        marker = ex._shared_marker()
    assert not marker.exists() and ray.is_initialized()  # closing cancelled the waiting unit; the cluster stays

    with open_executor("ray") as ex:  # a node with its own (unshared) NSL_HOME does not see the driver's marker
        ex._shared_marker().unlink()
        ex.submit(Unit("train", _square, (2,)))
        with pytest.raises(
            UnitFailed,
            match=r"unit train failed: NSL_HOME .* of the driver is not visible on node "
            r".*; mount the same shared folder",
        ):
            ex.wait()

    with open_executor("ray") as ex:  # a node that runs another nsl than the driver refuses
        ex.code_version = "0.0.1+gdeadbeefcafe"
        ex.submit(Unit("train", _square, (2,)))
        with pytest.raises(
            UnitFailed,
            match=r"unit train failed: node .* runs nsl .*, but the driver runs 0.0.1\+gdeadbeefcafe; install the "
            r"same nsl on every node",
        ):
            ex.wait()


def test_a_unit_that_holds_a_gpu_runs_on_the_node_that_has_one_and_is_refused_where_none_is(ray_cluster):
    """``--unit-gpus``: Ray counts GPUs as it counts CPUs (a node declares them; none is needed to test the
    scheduling), and sets CUDA_VISIBLE_DEVICES for the unit that holds one."""
    from tests.cluster.conftest import NODE_MEMORY

    cluster, _ = ray_cluster
    with open_executor("ray") as ex:
        with pytest.raises(ConfigError, match=r"^unit gpu asks for 1 GPU\(s\) but the cluster has 0; add a node"):
            ex.submit(Unit("gpu", _visible_gpus, num_gpus=1))
        assert ex.outstanding == 0
    gpu_node = cluster.add_node(num_cpus=1, num_gpus=1, object_store_memory=NODE_MEMORY)
    cluster.wait_for_nodes()
    with open_executor("ray") as ex:
        assert ex.gpus() == 1
        out = dict(ex.run_units([Unit("gpu", _visible_gpus, num_gpus=1)]))
    assert out["gpu"] == (gpu_node.node_id, "0")


def test_the_five_folders_take_a_runner_and_never_import_the_cluster_package():
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    imports = re.compile(r"^\s*(from\s+nsl\.cluster|import\s+nsl\.cluster|from\s+nsl\s+import\s+.*\bcluster\b)", re.M)
    offenders = [
        str(f.relative_to(root))
        for folder in ("collectors", "datasets", "learners", "eval", "catalog")
        for f in (root / folder).rglob("*.py")
        if imports.search(f.read_text())
    ]
    assert offenders == []
    import inspect

    from nsl.collectors import collect_episodes
    from nsl.eval import evaluate

    assert "runner" in inspect.signature(collect_episodes).parameters
    assert "runner" in inspect.signature(evaluate).parameters


@pytest.mark.slow  # starts a Ray instance of its own and a local pool (~25 s on a busy 2-core machine)
def test_bench_cluster_starts_its_own_ray_and_stops_it(capsys):
    import json

    import ray

    assert not ray.is_initialized()
    assert run_cli("bench", "cluster", "--json", "--episodes", "16", "--batch-size", "2") == 0
    out = json.loads(capsys.readouterr().out)
    assert out["same_episodes"] is True and out["episodes"] == 16 and out["cpus"] == 2
    assert out["local_episodes_per_s"] > 0 and out["ray_episodes_per_s"] > 0
    assert out["ray_vs_local"] == pytest.approx(out["ray_episodes_per_s"] / out["local_episodes_per_s"], rel=0.02)
    assert 50_000 < out["bytes_per_episode"] < 1_000_000  # 8 frames of 64x64x3 images and the rest
    assert not ray.is_initialized()  # the instance it started is shut down
