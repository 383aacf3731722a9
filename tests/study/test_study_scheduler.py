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
