"""Run a unit graph on local processes or a Ray cluster, skipping finished units, and keep a status file.

The scheduler knows nothing about what a unit does.  It is given the graph
(:func:`nsl.study.units.unit_graph`), ``is_done(unit)``,
``execute(unit, inner_workers, progress)`` and optionally ``prepare(unit)``
and ``register(unit, summary)``, which run in this process before and after
each unit.  It:

* marks every unit whose output already exists as done (so a killed study resumes where it stopped);
* runs ready units (all dependencies done), the longest critical path first (``cost``), up to ``workers`` at a
  time: in this process when ``workers == 1``, else each in a fresh spawned process with ``cpu_count // workers``
  threads; or, given a Ray executor, each as a Ray task holding ``unit_cpus`` CPUs, as many as the cluster holds;
* with ``register``, runs units in processes that may not open the catalog (``NSL_NO_CATALOG=1``), so this
  process is the catalog's only user;
* writes ``status.json`` (through a temporary file and a rename) after every change: each unit's state
  (``done``, ``running``, ``left``, ``failed``), the seconds it took and, on a cluster, its node.
"""

from __future__ import annotations

import datetime as dt
import json
import multiprocessing as mp
import os
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import networkx as nx

from nsl.errors import NslError
from nsl.workspace import atomic_write_json

from .units import Unit, order

STATUS_FILE = "status.json"
STATES = ("done", "running", "left", "failed")


class UnitFailed(NslError):
    """A unit raised; the study stops after the units already running finish."""


def _now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")


def read_status(path: Path) -> dict[str, Any]:
    path = Path(path)
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError:
        return {}  # a status file is a journal; the outputs are the truth


def live_status(path: Path, key: str, name: str) -> dict[str, Any]:
    """The status record at ``path`` (``{key: name, ...}``), with the 'running' units of a dead scheduler shown
    as 'interrupted'; ``{key: name, "state": "not started"}`` before the first run.

    The scheduler is alive while a process holds the folder's writer lock (:mod:`nsl.locks`), which dies with it
    even by kill -9; a pid in the record could have been reused."""
    from nsl.locks import holder

    status = read_status(path)
    if not status:
        return {key: name, "state": "not started", "units": {}}
    alive = holder(Path(path).parent) is not None
    if status.get("state") == "running" and not alive:
        status["state"] = "interrupted"
    for name, u in status.get("units", {}).items():
        if u["state"] == "running" and not alive:
            u["state"] = "interrupted"
        if u["state"] == "running" and "node" not in u:  # on a cluster: the node its task started on
            where = read_status(Path(path).parent / WHERE_DIR / _file_name(name))
            if where.get("node"):
                u["node"] = where["node"]
    return status


class _Status:
    def __init__(self, path: Path, graph: nx.DiGraph, meta: dict[str, Any]):
        self.path = Path(path)
        old = read_status(self.path).get("units", {})
        self.data = {**meta, "pid": os.getpid(), "state": "running", "started": _now(), "updated": _now(), "units": {}}
        for name in order(graph):
            u: Unit = graph.nodes[name]["unit"]
            prev = old.get(name, {})
            self.data["units"][name] = {"kind": u.kind, "state": "left", "seconds": prev.get("seconds"), "error": None}

    def set(
        self, name: str, state: str, seconds: float | None = None, error: str | None = None, node: str | None = None
    ) -> None:
        rec = self.data["units"][name]
        rec["state"] = state
        if seconds is not None:
            rec["seconds"] = round(seconds, 2)
        rec["error"] = error
        if node is not None:
            rec["node"] = node
        self.save()

    def save(self, state: str | None = None) -> None:
        if state:
            self.data["state"] = state
        self.data["updated"] = _now()
        atomic_write_json(self.path, self.data)


def critical_path(graph: nx.DiGraph, cost: Callable[[Unit], float]) -> dict[str, float]:
    """Each unit's cost plus the costliest chain of units that wait for it: the time it keeps the study going.

    Ready units start in decreasing order of it, so the long trainings at the head of a chain start first and
    short evaluations fill the gaps.
    """
    rank: dict[str, float] = {}
    for name in reversed(list(nx.topological_sort(graph))):
        after = max((rank[s] for s in graph.successors(name)), default=0.0)
        rank[name] = float(cost(graph.nodes[name]["unit"])) + after
    return rank


def _error_text(e: BaseException) -> str:
    return str(e) if isinstance(e, NslError) else f"{type(e).__name__}: {e}"


def _child(execute: Callable, unit: Unit, inner_workers: int, threads: int, queue, no_catalog: bool) -> None:
    """A spawned worker: one unit with a fixed thread count; reports (name, error or None, summary)."""
    import torch

    torch.set_num_threads(threads)
    if no_catalog:  # the scheduler resolved what it needs and registers what it makes
        from nsl.catalog import NO_CATALOG_ENV

        os.environ[NO_CATALOG_ENV] = "1"
    try:
        out = execute(unit, inner_workers, False)
        queue.put((unit.name, None, out))
    except BaseException as e:  # noqa: BLE001  # reported to the parent, which stops the study
        msg = _error_text(e) if isinstance(e, NslError) else f"{_error_text(e)}\n{traceback.format_exc()}"
        queue.put((unit.name, msg, None))


def cluster_task(execute: Callable, unit: Unit, where: str | None) -> dict:
    """A unit as a Ray task, which never opens the catalog (the driver resolves and registers), leaving a note of
    the node it runs on."""
    import socket

    from nsl.catalog import NO_CATALOG_ENV

    os.environ[NO_CATALOG_ENV] = "1"
    node = socket.gethostname()
    try:
        import ray

        node = f"{node}/{ray.get_runtime_context().get_node_id()[:8]}"
    except Exception:  # noqa: BLE001  # outside a Ray worker: the host name will do
        pass
    if where:  # every start of the unit, in order (a task run again after its node was lost starts again)
        starts = read_status(Path(where)).get("starts", [])
        starts.append({"node": node, "pid": os.getpid(), "started": _now()})
        atomic_write_json(Path(where), {"node": node, "starts": starts})
    out = execute(unit, 1, False)
    return {**out, "node": node}


class _InProcess:
    """Units one at a time in this process (``--workers 1``)."""

    def __init__(self, execute: Callable, inner: int, progress: bool):
        self.execute, self.inner, self.progress = execute, inner, progress
        self.capacity = 1
        self.todo: list[tuple[str, Unit]] = []

    def start(self, name: str, unit: Unit) -> None:
        self.todo.append((name, unit))

    def next(self) -> tuple[str, BaseException | None, dict | None]:
        name, unit = self.todo.pop(0)
        try:
            return name, None, self.execute(unit, self.inner, self.progress)
        except Exception as e:  # noqa: BLE001  # the scheduler reports it
            return name, e, None

    def stop(self) -> None:
        self.todo.clear()


class _Processes:
    """Each unit in a fresh spawned process with ``cpus // workers`` threads (``--workers W``)."""

    def __init__(self, execute: Callable, workers: int, no_catalog: bool):
        self.execute, self.no_catalog = execute, no_catalog
        self.capacity = workers
        self.threads = max(1, (os.cpu_count() or 1) // workers)
        self.ctx = mp.get_context("spawn")
        self.queue = self.ctx.Queue()
        self.running: dict[str, Any] = {}

    def start(self, name: str, unit: Unit) -> None:
        proc = self.ctx.Process(
            target=_child,
            args=(self.execute, unit, 1, self.threads, self.queue, self.no_catalog),
            name=f"nsl-study-{name}",
        )
        proc.start()
        self.running[name] = proc

    def next(self) -> tuple[str, BaseException | str | None, dict | None]:
        import queue as queue_mod

        while True:
            try:
                name, error, out = self.queue.get(timeout=1.0)
                break
            except queue_mod.Empty:  # a worker that died without a report (killed, crashed) counts as failed
                dead = [n for n, p in self.running.items() if not p.is_alive() and p.exitcode not in (0, None)]
                if dead:
                    code = self.running[dead[0]].exitcode
                    name, error, out = dead[0], f"worker process exited with code {code}", None
                    break
        self.running.pop(name).join()
        return name, error, out

    def stop(self) -> None:
        for proc in self.running.values():
            proc.terminate()
            proc.join()
        self.running.clear()


class _Cluster:
    """Each unit a Ray task holding ``unit_cpus`` CPUs (and a training unit ``unit_gpus`` GPUs), as many at once as
    the cluster has room for."""

    def __init__(self, executor, execute: Callable, unit_cpus: float, where: Path | None, unit_gpus: float = 0.0):
        from nsl.cluster import Unit as Task

        self.ex, self.execute, self.unit_cpus, self.where = executor, execute, unit_cpus, where
        self.unit_gpus = unit_gpus
        self.Task = Task
        self.capacity = max(1, int(executor.cpus() // unit_cpus))

    def start(self, name: str, unit: Unit) -> None:
        where = str(self.where / _file_name(name)) if self.where else None
        gpus = self.unit_gpus if unit.kind == "train" else 0.0  # collections and evaluations act on the CPU
        self.ex.submit(
            self.Task(name, cluster_task, (self.execute, unit, where), num_cpus=self.unit_cpus, num_gpus=gpus)
        )

    def next(self) -> tuple[str, BaseException | None, dict | None]:
        from nsl.cluster import UnitFailed as TaskFailed

        try:
            name, out = self.ex.wait()
            return name, None, out
        except TaskFailed as e:
            return e.key, e.error, None

    def stop(self) -> None:
        self.ex.close()


def _file_name(unit_name: str) -> str:
    return unit_name.replace(":", "_").replace("/", "_")


WHERE_DIR = "where"  # beside status.json: a file per unit started on a cluster, naming its node


def run_graph(
    graph: nx.DiGraph,
    status_path: Path,
    *,
    execute: Callable[[Unit, int, bool], dict],
    is_done: Callable[[Unit], bool],
    workers: int = 1,
    progress: bool = True,
    meta: dict[str, Any] | None = None,
    register: Callable[[Unit, dict], None] | None = None,
    prepare: Callable[[Unit], Unit] | None = None,
    cost: Callable[[Unit], float] | None = None,
    executor=None,
    unit_cpus: float = 1.0,
    unit_gpus: float = 0.0,
) -> dict[str, Any]:
    """Run every unit not yet done; returns the final status record.  Raises UnitFailed if a unit fails.

    ``register(unit, summary)``, when given, runs in this process after each unit, and ``prepare(unit)`` before
    it starts (e.g. to resolve the checkpoints it reads): worker processes and cluster tasks then never open the
    catalog, and this process is its only user.  ``cost(unit)`` (seconds, estimated) orders the ready
    units by their critical path.  ``executor`` (a Ray :class:`nsl.cluster.RayExecutor`) runs each unit as a Ray
    task holding ``unit_cpus`` CPUs, instead of ``workers`` local processes; training units also hold
    ``unit_gpus`` GPUs there (a plan's ``device = "auto"`` then trains on them).
    """
    from nsl.progress import progress_bar

    if workers < 1:
        raise NslError(f"--workers {workers} must be at least 1")
    names = order(graph)
    rank = critical_path(graph, cost) if cost is not None else {}
    position = {n: i for i, n in enumerate(names)}
    status = _Status(status_path, graph, meta or {})
    done = set()
    for name in names:
        if is_done(graph.nodes[name]["unit"]):
            done.add(name)
            status.data["units"][name]["state"] = "done"
    status.save()
    # a unit task notes where it runs beside status.json, which a node without the shared NSL_HOME (--store) cannot
    where = None if getattr(executor, "store", None) else Path(status_path).parent / WHERE_DIR
    if executor is not None:
        pool: Any = _Cluster(executor, execute, unit_cpus, where, unit_gpus)
    elif workers == 1:
        pool = _InProcess(execute, os.cpu_count() or 1, progress)
    else:
        pool = _Processes(execute, workers, no_catalog=register is not None)
    bar = progress_bar(
        total=len(names),
        initial=len(done),
        unit="unit",
        desc="study",
        disable=not progress,
        dynamic_ncols=True,
        position=0,
    )
    failed: list[str] = []
    first_error: BaseException | None = None
    running: dict[str, float] = {}

    def ready() -> list[str]:
        out = [n for n in names if n not in done and n not in running and all(d in done for d in graph.predecessors(n))]
        return sorted(out, key=lambda n: (-rank.get(n, 0.0), position[n]))

    try:
        while True:
            todo = [] if failed else ready()
            for name in todo[: pool.capacity - len(running)]:
                unit = graph.nodes[name]["unit"]
                pool.start(name, prepare(unit) if prepare is not None else unit)
                running[name] = time.perf_counter()
                status.set(name, "running")
            if not running:
                break
            bar.set_postfix_str(", ".join(running), refresh=True)
            name, error, out = pool.next()
            seconds = time.perf_counter() - running.pop(name)
            if error is None and register is not None:
                try:
                    register(graph.nodes[name]["unit"], out or {})
                except Exception as e:  # noqa: BLE001  # reported like the unit's own failure
                    error = e
            if error is None:
                status.set(name, "done", seconds, node=(out or {}).get("node"))
                done.add(name)
                bar.update(1)
                continue
            text = error if isinstance(error, str) else _error_text(error)
            status.set(name, "failed", seconds, text.splitlines()[0] if text else "failed")
            failed.append(f"{name}: {text}")
            if isinstance(error, BaseException) and first_error is None:
                first_error = error
    except BaseException:
        pool.stop()
        status.save("interrupted")
        raise
    finally:
        bar.close()
    pool.stop()
    if failed:
        status.save("failed")
        raise UnitFailed(
            "unit "
            + failed[0].splitlines()[0]
            + "; fix it and run the same command again to resume"
            + (" (--debug shows the traceback)" if executor is None and workers == 1 else "")
        ) from first_error
    left = [n for n in names if n not in done]
    status.save("finished" if not left else "stopped")
    return status.data
