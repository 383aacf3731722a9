"""Two OS processes registering at the same moment lose no entry and corrupt nothing."""

from __future__ import annotations

import multiprocessing as mp
from pathlib import Path

from catalog_factories import make_checkpoint, make_dataset

from nsl.catalog import SCHEMA_VERSION, Catalog

PER_PROCESS = 100


def _register_many(worker: int, tmp: str, barrier, errors) -> None:
    try:
        with Catalog() as cat:  # opened after the fork, as every process must
            barrier.wait(timeout=60)
            parent = None
            for i in range(PER_PROCESS):
                # the same 20 datasets from both processes: idempotent under the race
                data = make_dataset(cat, f"shared-{i % 20}", 1, "base", 10)
                ck = make_checkpoint(
                    cat,
                    Path(tmp),
                    f"w{worker}",
                    i,
                    worker * 1000 + i,
                    parent=parent,
                    data=[cat.resolve_data(f"data:{data.name}@v1").use()],
                )
                cat.add_evaluation(ck.id, "base", episodes=10, successes=i % 11, seed=worker)
                parent = ck.id
    except BaseException as e:  # reported to the parent, which fails the test
        errors.put(f"worker {worker}: {type(e).__name__}: {e}")
        raise


def test_two_processes_register_100_entries_each_without_loss(tmp_path):
    Catalog().close()  # both workers also race on opening; creating first keeps the test about writes
    ctx = mp.get_context("fork")
    barrier = ctx.Barrier(2)
    errors = ctx.Queue()
    procs = [ctx.Process(target=_register_many, args=(w, str(tmp_path), barrier, errors)) for w in (1, 2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=300)
    assert errors.empty(), errors.get()
    assert [p.exitcode for p in procs] == [0, 0]
    with Catalog() as cat:
        assert cat.conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        for w in (1, 2):
            chain = cat.checkpoints(f"w{w}")
            assert [c.step for c in chain] == list(range(PER_PROCESS))
            assert len(cat.lineage(f"ckpt:w{w}@latest")) == PER_PROCESS  # every parent link intact
        assert len(cat.evaluations()) == 2 * PER_PROCESS
        assert sorted(d.name for d in cat.datasets()) == sorted(f"shared-{i}" for i in range(20))
        assert cat.trained_on("shared-0", 1) and len(cat.trained_on("shared-0", 1)) == 2 * PER_PROCESS // 20


def test_two_processes_creating_the_catalog_at_once(tmp_path):
    ctx = mp.get_context("fork")
    barrier = ctx.Barrier(2)
    errors = ctx.Queue()
    procs = [ctx.Process(target=_open_and_register, args=(w, barrier, errors)) for w in (1, 2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=120)
    assert errors.empty(), errors.get()
    with Catalog() as cat:
        assert sorted(d.name for d in cat.datasets()) == ["first-1", "first-2"]
        # each migration ran once, although both processes found an empty file
        assert cat.conn.execute("SELECT COUNT(*) FROM schema_history").fetchone()[0] == SCHEMA_VERSION


def _open_and_register(worker: int, barrier, errors) -> None:
    try:
        barrier.wait(timeout=60)
        with Catalog() as cat:
            make_dataset(cat, f"first-{worker}")
    except BaseException as e:
        errors.put(f"worker {worker}: {type(e).__name__}: {e}")
        raise
