"""A real two-node Ray cluster on this machine, one per test, on loopback and small.

``ray.cluster_utils.Cluster`` starts a head node and a worker node as separate
raylets (each with its own object store and worker processes), the closest a
single machine gets to two machines.  Never ``ray stop`` here: it kills Ray
processes by name machine-wide; the fixture shuts down only its own cluster.
"""

from __future__ import annotations

import os

# Read when Ray is imported: bind every listener to 127.0.0.1, and no token authentication (it would write
# ~/.ray/auth_token).  Nodes started below inherit these.
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
os.environ.setdefault("RAY_AUTH_MODE", "disabled")

import pytest

NODE_MEMORY = 100 * 1024 * 1024  # object store per node: 200 MB for the cluster
# A killed node is declared dead after ~1 s instead of the default ~15 s.
FAST_FAILURE_DETECTION = {
    "health_check_initial_delay_ms": 0,
    "health_check_period_ms": 500,
    "health_check_failure_threshold": 2,
}


@pytest.fixture
def ray_cluster():
    """``(cluster, worker_node)``: a head and a worker node of one CPU each, this process connected."""
    import ray
    from ray.cluster_utils import Cluster

    cluster = Cluster(
        initialize_head=True,
        head_node_args={
            "num_cpus": 1,
            "object_store_memory": NODE_MEMORY,
            "include_dashboard": False,
            "_system_config": FAST_FAILURE_DETECTION,
        },
    )
    try:
        worker = cluster.add_node(num_cpus=1, object_store_memory=NODE_MEMORY)
        ray.init(address=cluster.address, logging_level="WARNING")
        yield cluster, worker
    finally:
        ray.shutdown()
        cluster.shutdown()
