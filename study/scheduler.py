"""Run a unit graph with local processes, skipping finished units, and keep a status file.

The scheduler knows nothing about what a unit does.  It is given the graph
(:func:`nsl.study.units.unit_graph`), ``is_done(unit)`` and
``execute(unit, inner_workers, progress)``.  It:

* marks every unit whose output already exists as done (so a killed study resumes where it stopped);
* runs ready units (all dependencies done) in topological order, up to ``workers`` at a time: in this process
  when ``workers == 1``, else each in a fresh spawned process with ``cpu_count // workers`` threads;
* writes ``status.json`` (through a temporary file and a rename) after every change: each unit's state
  (``done``, ``running``, ``left``, ``failed``) and the seconds it took.

A cluster scheduler can replace this module: the graph, ``is_done`` and
``execute`` are all it needs.
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


def pid_alive(pid: int | None) -> bool:
    if not pid:
        return False
    try:
        os.kill(int(pid), 0)
    except (ProcessLookupError, PermissionError, ValueError):
        return False
    try:  # a zombie (killed, not yet reaped) is not running
        with open(f"/proc/{int(pid)}/stat") as f:
            return f.read().split(") ", 1)[1][0] != "Z"
    except (OSError, IndexError):
        return True


def live_status(path: Path, key: str, name: str) -> dict[str, Any]:
    """The status record at ``path`` (``{key: name, ...}``), with the 'running' units of a dead scheduler shown
    as 'interrupted'; ``{key: name, "state": "not started"}`` before the first run."""
    status = read_status(path)
    if not status:
        return {key: name, "state": "not started", "units": {}}
    alive = pid_alive(status.get("pid"))
    if status.get("state") == "running" and not alive:
        status["state"] = "interrupted"
    for u in status.get("units", {}).values():
        if u["state"] == "running" and not alive:
            u["state"] = "interrupted"
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

    def set(self, name: str, state: str, seconds: float | None = None, error: str | None = None) -> None:
        rec = self.data["units"][name]
        rec["state"] = state
        if seconds is not None:
            rec["seconds"] = round(seconds, 2)
        rec["error"] = error
        self.save()

    def save(self, state: str | None = None) -> None:
        if state:
            self.data["state"] = state
        self.data["updated"] = _now()
        atomic_write_json(self.path, self.data)


def _child(execute: Callable, unit: Unit, inner_workers: int, threads: int, queue) -> None:
    """A spawned worker: one unit with a fixed thread count; reports (name, error or None, summary)."""
    import torch

    torch.set_num_threads(threads)
    try:
        out = execute(unit, inner_workers, False)
        queue.put((unit.name, None, out))
    except BaseException as e:  # noqa: BLE001  # reported to the parent, which stops the study
        msg = str(e) if isinstance(e, NslError) else f"{type(e).__name__}: {e}\n{traceback.format_exc()}"
        queue.put((unit.name, msg, None))


def run_graph(
    graph: nx.DiGraph,
    status_path: Path,
    *,
    execute: Callable[[Unit, int, bool], dict],
    is_done: Callable[[Unit], bool],
    workers: int = 1,
    progress: bool = True,
    meta: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Run every unit not yet done; returns the final status record.  Raises UnitFailed if a unit fails."""
    from nsl.progress import progress_bar

    if workers < 1:
        raise NslError(f"--workers {workers} must be at least 1")
    names = order(graph)
    status = _Status(status_path, graph, meta or {})
    done = set()
    for name in names:
        if is_done(graph.nodes[name]["unit"]):
            done.add(name)
            status.data["units"][name]["state"] = "done"
    status.save()
    cpus = os.cpu_count() or 1
    inner = max(1, cpus // workers)
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
    running: dict[str, tuple[Any, float]] = {}
    ctx = mp.get_context("spawn")
    queue = ctx.Queue() if workers > 1 else None

    def ready() -> list[str]:
        return [
            n for n in names if n not in done and n not in running and all(d in done for d in graph.predecessors(n))
        ]

    try:
        while True:
            todo = [] if failed else ready()
            if workers == 1:
                if not todo:
                    break
                name = todo[0]
                unit = graph.nodes[name]["unit"]
                status.set(name, "running")
                bar.set_postfix_str(name, refresh=True)
                t0 = time.perf_counter()
                try:
                    execute(unit, inner, progress)
                except Exception as e:
                    msg = str(e) if isinstance(e, NslError) else f"{type(e).__name__}: {e}"
                    status.set(name, "failed", time.perf_counter() - t0, msg)
                    status.save("failed")
                    raise UnitFailed(
                        f"unit {name}: {msg}; fix it and run the same command again to resume "
                        "(--debug shows the traceback)"
                    ) from e
                status.set(name, "done", time.perf_counter() - t0)
                done.add(name)
                bar.update(1)
                continue
            for name in todo[: workers - len(running)]:
                unit = graph.nodes[name]["unit"]
                proc = ctx.Process(
                    target=_child, args=(execute, unit, 1, max(1, cpus // workers), queue), name=f"nsl-study-{name}"
                )
                proc.start()
                running[name] = (proc, time.perf_counter())
                status.set(name, "running")
            if not running:
                break
            bar.set_postfix_str(", ".join(running), refresh=True)
            name, error, _ = _next_result(queue, running)
            proc, t0 = running.pop(name)
            proc.join()
            if error is None:
                status.set(name, "done", time.perf_counter() - t0)
                done.add(name)
                bar.update(1)
            else:
                status.set(name, "failed", time.perf_counter() - t0, error.splitlines()[0] if error else "failed")
                failed.append(f"{name}: {error}")
    except UnitFailed:
        raise
    except BaseException:
        for proc, _ in running.values():
            proc.terminate()
            proc.join()
        status.save("interrupted")
        raise
    finally:
        bar.close()
    if failed:
        status.save("failed")
        raise UnitFailed("unit " + failed[0].splitlines()[0] + "; fix it and run the same command again to resume")
    left = [n for n in names if n not in done]
    status.save("finished" if not left else "stopped")
    return status.data


def _next_result(queue, running: dict[str, tuple[Any, float]]):
    """Wait for a worker's report; a worker that died without one (killed, crashed) counts as failed."""
    import queue as queue_mod

    while True:
        try:
            return queue.get(timeout=1.0)
        except queue_mod.Empty:
            for name, (proc, _) in running.items():
                if not proc.is_alive() and proc.exitcode not in (0, None):
                    return name, f"worker process exited with code {proc.exitcode}", None
