"""``nsl study run|status|report``: plan -> checks -> unit graph -> scheduler -> report.

A study lives in ``$NSL_HOME/studies/NAME/``::

    plan.json      the validated plan (a study's name is bound to one plan)
    units.json     every unit: kind, dependencies, settings
    status.json    the scheduler's journal: each unit's state and seconds
    records.json   the raw numbers the report is computed from
    report.md      tables, findings (a)-(e), and the PNG plots beside it

Beside it, ``studies/.NAME.lock`` is the writer lock of the process running it (:mod:`nsl.locks`;
``.NAME.lock.json`` names that process).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from nsl import code_version, workspace
from nsl.errors import ConfigError, UnknownReferenceError
from nsl.locks import writer_lock

from . import actions
from .plan import Plan, load_plan, parse_plan
from .report import (
    RECORDS_FILE,
    REPORT_FILE,
    count,
    gather,
    plot_curves,
    plot_early_stop,
    plot_online,
    plot_tiers,
    plot_weight_change,
    render,
)
from .scheduler import STATUS_FILE, live_status, read_status, run_graph
from .units import build_units, order, unit_graph

PLAN_FILE = "plan.json"
UNITS_FILE = "units.json"


def study_dir(name: str) -> Path:
    return workspace.home() / "studies" / name


def _same_plan(saved: dict, plan) -> bool:
    """True when a study's saved plan is ``plan``; settings added since it was saved count at their defaults."""
    try:
        again = parse_plan(saved, default_name=plan.name).to_dict()
    except (ConfigError, UnknownReferenceError):
        return False
    return json.loads(json.dumps(again)) == json.loads(json.dumps(plan.to_dict()))


def prepare(plan_ref: str, name: str | None = None):
    """Load and check everything (plan, workspace, base data) and build the graph; writes nothing."""
    plan = load_plan(plan_ref)
    name = name or plan.name
    if not name.replace("-", "").replace("_", "").isalnum():
        raise ConfigError(f"--name {name!r} must use letters, digits, '-' and '_'")
    _check_saved_plan(name, plan)
    base = actions.base_sources(plan)
    units = build_units(plan, name, base)
    return plan, name, units, unit_graph(units)


def _check_saved_plan(name: str, plan) -> None:
    saved = study_dir(name) / PLAN_FILE
    if saved.is_file() and not _same_plan(json.loads(saved.read_text()), plan):
        raise ConfigError(
            f"study {name!r} exists with a different plan ({saved}); run it with the same plan to "
            "resume, or choose another --name"
        )


def estimate_study(plan_ref: str, name: str | None = None, slots: int | None = None):
    """The estimated cost of the units not done yet (nothing runs, nothing is written); with ``slots``, also
    the wall time of running that many units at once (:func:`nsl.study.estimate.schedule`): (cost, schedule)."""
    _, _, units, graph = prepare(plan_ref, name)
    return estimate_units(units, graph, slots)


def estimate_units(units: dict, graph, slots: int | None = None):
    """:func:`estimate_study` of a built unit graph (a study's or a transfer's)."""
    from .estimate import estimate, schedule

    done = [n for n in order(graph) if actions.is_done(units[n])]
    cost = estimate([units[n] for n in order(graph)], done)
    if slots is None:
        return cost
    return cost, schedule(graph, slots, done)


def cluster_slots(cluster: str | None, workers: int, unit_cpus: float = 1.0) -> int:
    """Units at once: ``workers`` locally, else the cluster's CPUs over the CPUs a unit holds (connects)."""
    from nsl.cluster import open_executor, parse_cluster

    spec = parse_cluster(cluster)
    if spec == "local":
        return workers
    with open_executor(spec) as ex:
        return max(1, int(ex.cpus() // unit_cpus))


def run_study(
    plan_ref: str,
    name: str | None = None,
    workers: int = 1,
    progress: bool = True,
    cluster: str | None = None,
    unit_cpus: float = 1.0,
    store: str | None = None,
    wait: bool = False,
    unit_gpus: float = 0.0,
) -> dict[str, Any]:
    """Run (or resume) a study; writes its report at the end.  Returns the final status record.

    ``cluster`` (``--cluster``; None: ``$NSL_CLUSTER``, else local) runs every unit as a Ray task holding
    ``unit_cpus`` CPUs (training units also ``unit_gpus`` GPUs) instead of ``workers`` local processes; the numbers
    are the same on the CPU.  ``store`` (``--store``,
    an fsspec URL; None: ``$NSL_STORE``, else a shared ``NSL_HOME``) moves the units' folders through it.
    One process runs a study at a time (its folder's writer lock, from the plan check to the report): while
    another holds it this raises LockedError naming it, or with ``wait`` waits for it, then resumes.
    """
    if workers < 1:
        raise ConfigError(f"--workers {workers} must be at least 1")
    plan, name, units, graph = prepare(plan_ref, name)  # checks everything, writes nothing
    with writer_lock(study_dir(name), f"study {name!r}", wait=wait):
        _check_saved_plan(name, plan)  # again: a run that held the lock may have saved another plan
        status = run_planned(
            study_dir(name),
            "study",
            name,
            plan,
            units,
            graph,
            workers=workers,
            progress=progress,
            cluster=cluster,
            unit_cpus=unit_cpus,
            unit_gpus=unit_gpus,
            store=store,
            bases=(plan.base,),
        )
        write_study_report(name)
    return status


def run_planned(
    folder: Path,
    key: str,
    name: str,
    plan,
    units: dict,
    graph,
    *,
    workers: int,
    progress: bool,
    cluster: str | None = None,
    unit_cpus: float = 1.0,
    store: str | None = None,
    bases: tuple[str, ...] = (),
    wait: bool = False,
    unit_gpus: float = 0.0,
) -> dict[str, Any]:
    """Run a planned unit graph in ``folder`` (a study's or a transfer's, ``key`` says which): take the folder's
    writer lock (refuse while another process holds it, or ``wait`` for it), save the plan and the unit list,
    then run (or resume) the graph.

    Units never open the catalog: this process resolves the checkpoints each reads and registers what each made,
    on a cluster as on this machine.  ``bases`` are resolved here first (the shipped base registers itself).
    """
    from nsl.cluster import open_executor, parse_cluster
    from nsl.share.store import parse_store

    if unit_cpus <= 0 or unit_gpus < 0:
        raise ConfigError(f"--unit-cpus {unit_cpus} must be positive and --unit-gpus {unit_gpus} not negative")
    spec, store = parse_cluster(cluster), parse_store(store)
    executor = open_executor(spec, store=store)  # without Ray, --cluster ray stops here, before anything is written
    with writer_lock(folder, f"{key} {name!r}", wait=wait):  # reentrant: run_study holds it already
        return _run_locked(
            folder, key, name, plan, units, graph, executor, spec, store, workers, progress, unit_cpus, bases, unit_gpus
        )


def _run_locked(
    folder, key, name, plan, units, graph, executor, spec, store, workers, progress, unit_cpus, bases, unit_gpus=0.0
):
    """:func:`run_planned` under the folder's writer lock (the status file's pid is for information only)."""
    from functools import partial

    from .estimate import unit_seconds

    folder.mkdir(parents=True, exist_ok=True)
    workspace.atomic_write_json(folder / PLAN_FILE, plan.to_dict())
    workspace.atomic_write_json(
        folder / UNITS_FILE,
        {
            "units": [
                {"name": n, "kind": units[n].kind, "deps": list(units[n].deps), "params": dict(units[n].params)}
                for n in order(graph)
            ],
            "code_version": code_version(),
        },
    )
    for ref in bases:
        actions.resolve_checkpoint(ref)
    with executor as ex:
        where = {"workers": workers} if spec == "local" else {**ex.describe(), "unit_cpus": unit_cpus}
        if unit_gpus:
            where["unit_gpus"] = unit_gpus
        if store:  # no shared NSL_HOME: units pull what they read from the store and push what they make
            where["store"] = store
            execute, prepare = actions.run_staged_unit, partial(actions.stage_unit, store=store)
            register = partial(actions.register_staged_unit, store=store)
        else:
            execute, prepare = partial(actions.run_unit, register=False), actions.prepare_unit
            register = actions.register_unit
        return run_graph(
            graph,
            folder / STATUS_FILE,
            execute=execute,
            is_done=actions.is_done,
            register=register,
            prepare=prepare,
            cost=unit_seconds,
            workers=workers,
            progress=progress,
            executor=None if spec == "local" else ex,
            unit_cpus=unit_cpus,
            unit_gpus=unit_gpus,
            meta={key: name, "plan": plan.source, **where, "code_version": code_version()},
        )


def _load(name: str) -> Plan:
    path = study_dir(name) / PLAN_FILE
    if not path.is_file():
        known = sorted(p.name for p in (workspace.home() / "studies").glob("*") if (p / PLAN_FILE).is_file())
        raise UnknownReferenceError(
            f"no study named {name!r} in {workspace.home()}; "
            + (f"known: {', '.join(known)}" if known else "start one with `nsl study run small`")
        )
    return parse_plan(json.loads(path.read_text()), source=str(path), default_name=name)


def study_status(name: str) -> dict[str, Any]:
    """The status record, with 'running' units of a dead scheduler shown as 'interrupted'."""
    _load(name)
    return live_status(study_dir(name) / STATUS_FILE, "study", name)


def status_lines(status: dict[str, Any], kind: str = "study") -> list[str]:
    """The status record for a terminal (``kind``: study or transfer, the record's name key)."""
    units = status.get("units", {})
    by: dict[str, list[str]] = {}
    for n, u in units.items():
        by.setdefault(u["state"], []).append(n)
    spent = sum(u.get("seconds") or 0 for u in units.values())
    lines = [
        f"{kind} {status.get(kind)}: {status.get('state')}; "
        + ", ".join(
            f"{len(by.get(s, []))} {s}"
            for s in ("done", "running", "interrupted", "failed", "left")
            if by.get(s) or s in ("done", "left")
        )
        + f"; {spent / 60:.1f} minutes spent in units"
    ]
    for state in ("running", "interrupted", "failed", "left", "done"):
        for n in by.get(state, []):
            u = units[n]
            secs = "" if u.get("seconds") is None else f"{u['seconds']:.1f}s"
            err = f"  {u['error']}" if u.get("error") else ""
            node = f"  on {u['node']}" if u.get("node") else ""
            lines.append(f"  {state:<11} {secs:>8}  {n}{node}{err}")
    return lines


def _read_curve(checkpoint: str):
    from nsl.eval import CURVE_FILE, read_curve

    path = workspace.runs_dir() / checkpoint / CURVE_FILE
    return read_curve(path) if path.is_file() else None


def _fine_tune_recipe(plan: Plan, name: str) -> dict[str, Any] | None:
    """The settings the first shift's top-tier fine-tune trained with (from its checkpoint), or None before it."""
    from nsl.learners import read_config

    from .units import train_tag

    f = plan.finetune
    entry = actions._checkpoint_at(
        f"{name}-{train_tag('ft', plan.shifts[0], f.tiers[-1], f.steps, f.seeds[0])}", f.steps
    )
    if entry is None:
        return None
    training = read_config(Path(entry.path))["training"]
    return {k: training.get(k) for k in ("steps", "lr", "n_step", "augment_crop", "conservative")}


def _checkpoint_folder(ref: str) -> Path | None:
    try:
        return Path(actions.resolve_checkpoint(ref).path)
    except UnknownReferenceError:
        return None


def write_study_report(name: str) -> Path:
    """Write records.json, the plots and report.md under the study's folder; returns report.md's path."""
    plan = _load(name)
    folder = study_dir(name)
    records = gather(plan, name, actions.evaluation, _read_curve, _checkpoint_folder)
    records["recipe"] = _fine_tune_recipe(plan, name)
    workspace.atomic_write_json(folder / RECORDS_FILE, records)
    figures = {}
    if any(any(c is not None for v in row["tiers"].values() for c in v) for row in records["finetune"].values()):
        figures["tiers"] = plot_tiers(records, folder / "tiers.png").name
    if records.get("curves") and any(r for by in records["curves"].values() for r in by.values()):
        figures["curves"] = plot_curves(records, folder / "curves.png").name
    if records.get("early_stop"):
        figures["early_stop"] = plot_early_stop(records, folder / "early_stop.png").name
    if records.get("weight_change"):
        figures["weight_change"] = plot_weight_change(records, folder / "weight_change.png").name
    if records.get("online") and any(count(x) for r in records["online"].values() for x in r["success"][1:]):
        figures["online"] = plot_online(records, folder / "online.png").name
    text = render(records, read_status(folder / STATUS_FILE), figures)
    workspace.atomic_write_bytes(folder / REPORT_FILE, (text + "\n").encode())
    return folder / REPORT_FILE
