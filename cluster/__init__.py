"""Scale-out: where collection, evaluation and independent units run (local processes or Ray).

Public surface (the CLI wires it in; the five folders never import it, they
take a ``runner`` instead)::

    open_executor, parse_cluster, add_option   # --cluster local|ray|auto|ray://HOST:PORT
    Executor, RayExecutor, Unit, UnitFailed    # executor.runner; submit/wait/run_units
    RayChunkRunner                             # collect_episodes(..., runner=...) on Ray
    node_home                                  # --store: a node's own NSL_HOME (the folders move via nsl.share.store)

Ray is an optional extra (``pip install 'nsl[ray]'``); it is imported only when
a Ray executor is made.  See docs/scale.md.
"""

from .collect import RayChunkRunner
from .executor import (
    CLUSTER_ENV,
    Executor,
    RayExecutor,
    Unit,
    UnitFailed,
    add_option,
    node_home,
    open_executor,
    parse_cluster,
)

__all__ = [
    "CLUSTER_ENV",
    "Executor",
    "RayExecutor",
    "RayChunkRunner",
    "Unit",
    "UnitFailed",
    "add_option",
    "node_home",
    "open_executor",
    "parse_cluster",
]
