"""The scheduler on its own: dependencies first, finished units skipped, failures stop the study, W processes."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from nsl.study.scheduler import UnitFailed, run_graph
from nsl.study.units import Unit, unit_graph


def touch_unit(unit: Unit, inner_workers: int, progress: bool) -> dict:
    """A picklable unit action: record the start, wait a little, write the output file."""
    out = Path(unit.params["dir"])
    if unit.params.get("fail"):
        raise RuntimeError(f"{unit.name} was told to fail")
    for d in unit.deps:  # its dependencies' outputs exist before it starts
        assert (out / d.replace(":", "_")).is_file(), d
    (out / f"{unit.name.replace(':', '_')}.start").write_text(f"{time.time()} {os.getpid()}")
    met = True
    if unit.kind == "collect" and unit.params.get("meet"):  # wait (bounded) until the other collection has started
        deadline = time.monotonic() + 60.0
        others = [out / f"{n}.start" for n in ("collect_a", "collect_b") if n != unit.name.replace(":", "_")]
        while not all(o.exists() for o in others) and time.monotonic() < deadline:
            time.sleep(0.05)
        met = all(o.exists() for o in others)  # run one after the other, the first would wait in vain
    (out / f"{unit.name.replace(':', '_')}.met").write_text(str(met))
    (out / unit.name.replace(":", "_")).write_text(str(inner_workers))
    return {}


def done(unit: Unit) -> bool:
    return (Path(unit.params["dir"]) / unit.name.replace(":", "_")).is_file()


def _graph(tmp_path, fail: str | None = None, meet: bool = False):
    p = {"dir": str(tmp_path), "meet": meet}
    units = [
        Unit("collect:a", "collect", p),
        Unit("collect:b", "collect", p),
        Unit("train:x", "train", {**p, "fail": fail == "train:x"}, ("collect:a", "collect:b")),
        Unit("eval:x", "eval", p, ("train:x",)),
        Unit("eval:b", "eval", p, ("collect:b",)),
    ]
    return unit_graph(units)


def test_runs_in_dependency_order_and_skips_finished_units(tmp_path):
    status_path = tmp_path / "status.json"
    (tmp_path / "collect_a").write_text("made earlier")  # already done: must not run again
    status = run_graph(_graph(tmp_path), status_path, execute=touch_unit, is_done=done, workers=1, progress=False)
    assert status["state"] == "finished"
    assert {n: u["state"] for n, u in status["units"].items()} == dict.fromkeys(
        ["collect:a", "collect:b", "train:x", "eval:x", "eval:b"], "done"
    )
    assert (tmp_path / "collect_a").read_text() == "made earlier"
    assert not (tmp_path / "collect_a.start").exists()
    assert json.loads(status_path.read_text())["units"]["train:x"]["seconds"] is not None


def test_a_failing_unit_stops_the_study_and_is_reported(tmp_path):
    with pytest.raises(UnitFailed, match="train:x was told to fail"):
        run_graph(
            _graph(tmp_path, fail="train:x"),
            tmp_path / "status.json",
            execute=touch_unit,
            is_done=done,
            workers=1,
            progress=False,
        )
    units = json.loads((tmp_path / "status.json").read_text())["units"]
    assert units["train:x"]["state"] == "failed" and "told to fail" in units["train:x"]["error"]
    assert units["eval:x"]["state"] == "left"


def test_two_workers_run_independent_units_at_once_in_their_own_processes(tmp_path):
    status = run_graph(
        _graph(tmp_path, meet=True),
        tmp_path / "status.json",
        execute=touch_unit,
        is_done=done,
        workers=2,
        progress=False,
    )
    assert all(u["state"] == "done" for u in status["units"].values())
    starts = {n: (tmp_path / f"{n}.start").read_text().split() for n in ("collect_a", "collect_b")}
    pids = {p for _, p in starts.values()}
    assert len(pids) == 2 and str(os.getpid()) not in pids
    # the two collections overlapped: each saw the other start before it finished (no clock involved)
    assert all((tmp_path / f"{n}.met").read_text() == "True" for n in ("collect_a", "collect_b"))
    a, b = (float(starts[n][0]) for n in ("collect_a", "collect_b"))
    ta = float((tmp_path / "train_x.start").read_text().split()[0])
    assert ta > max(a, b)  # and the training waited for both


def _cost(unit: Unit) -> float:
    return float(unit.params["cost"])


def _chain_graph(tmp_path):
    """A long chain (train a -> train b -> eval b) beside two short independent evaluations."""
    p = {"dir": str(tmp_path)}
    return unit_graph(
        [
            Unit("eval:short1", "eval", {**p, "cost": 1}),
            Unit("eval:short2", "eval", {**p, "cost": 1}),
            Unit("train:a", "train", {**p, "cost": 10}),
            Unit("train:b", "train", {**p, "cost": 10}, ("train:a",)),
            Unit("eval:b", "eval", {**p, "cost": 1}, ("train:b",)),
        ]
    )


def test_ready_units_start_by_critical_path_and_the_schedule_model_agrees(tmp_path):
    from nsl.study.estimate import schedule
    from nsl.study.scheduler import critical_path

    g = _chain_graph(tmp_path)
    rank = critical_path(g, _cost)
    assert rank == {"train:a": 21.0, "train:b": 11.0, "eval:b": 1.0, "eval:short1": 1.0, "eval:short2": 1.0}
    started = []

    def record(unit: Unit, inner_workers: int, progress: bool) -> dict:
        started.append(unit.name)
        return touch_unit(unit, inner_workers, progress)

    run_graph(g, tmp_path / "status.json", execute=record, is_done=done, cost=_cost, progress=False)
    assert started[0] == "train:a"  # the head of the longest chain first, although listed after the evaluations
    one, two = schedule(g, 1, cost=_cost), schedule(g, 2, cost=_cost)
    assert one.seconds == 23.0 and two.seconds == 21.0  # two slots: the short units fit beside the chain
    assert two.critical == 21.0 and two.path == ("train:a", "train:b", "eval:b")
    assert schedule(g, 2, done=["train:a"], cost=_cost).seconds == 11.0  # finished units cost nothing


def test_with_a_registrar_units_run_without_the_catalog_and_the_scheduler_registers(tmp_path):
    """Worker processes get NSL_NO_CATALOG=1; register() runs in the scheduler's process after each unit."""
    from nsl.catalog import NO_CATALOG_ENV

    registered = []

    def register(unit: Unit, summary: dict) -> None:
        assert os.environ.get(NO_CATALOG_ENV) != "1"
        registered.append((unit.name, summary["no_catalog"]))

    def prepare(unit: Unit) -> Unit:
        return Unit(unit.name, unit.kind, {**unit.params, "prepared": True}, unit.deps)

    run_graph(
        _graph(tmp_path),
        tmp_path / "status.json",
        execute=catalog_free_unit,
        is_done=done,
        register=register,
        prepare=prepare,
        workers=2,
        progress=False,
    )
    assert sorted(registered) == sorted((n, "1") for n in ("collect:a", "collect:b", "train:x", "eval:x", "eval:b"))


def catalog_free_unit(unit: Unit, inner_workers: int, progress: bool) -> dict:
    from nsl.catalog import NO_CATALOG_ENV, Catalog
    from nsl.errors import ConfigError

    assert unit.params["prepared"]
    with pytest.raises(ConfigError, match=r"this process may not open the catalog .*open it on the driver"):
        Catalog()
    touch_unit(unit, inner_workers, progress)
    return {"no_catalog": os.environ.get(NO_CATALOG_ENV)}


def test_on_a_cluster_training_units_hold_the_unit_gpus_and_the_others_none():
    from nsl.study.scheduler import _Cluster

    class Recorder:
        def __init__(self):
            self.tasks = []

        def cpus(self) -> int:
            return 4

        def submit(self, task) -> None:
            self.tasks.append(task)

    ex = Recorder()
    pool = _Cluster(ex, execute=lambda *a: {}, unit_cpus=2.0, where=None, unit_gpus=1.0)
    assert pool.capacity == 2
    for kind in ("train", "eval", "collect"):
        pool.start(f"{kind}:x", Unit(f"{kind}:x", kind, {}))
    assert [(t.key, t.num_cpus, t.num_gpus) for t in ex.tasks] == [
        ("train:x", 2.0, 1.0),
        ("eval:x", 2.0, 0.0),
        ("collect:x", 2.0, 0.0),
    ]
