"""``nsl transfer run|status|report``: transfer plan -> checks -> units -> the study's scheduler -> matrix.

A transfer lives in ``$NSL_HOME/transfers/NAME/``::

    plan.json        the validated transfer plan (a name is bound to one plan)
    units.json       every unit: kind, dependencies, settings
    status.json      the scheduler's journal
    proxy.json       offline proxy scores by (checkpoint id, data hash), a cache
    matrix.json      the transfer-advantage matrix (``nsl curriculum`` reads it) with AUCs and proxy scores
    matrix.md        the same as tables, the proxy's rank correlation, and the curricula when complete
    curriculum.png   the optimal and pessimal curricula (when every pair is measured)
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from nsl import code_version, workspace
from nsl.errors import ConfigError, UnknownReferenceError
from nsl.locks import writer_lock

from . import actions
from .driver import PLAN_FILE, run_planned
from .scheduler import STATUS_FILE, live_status, read_status
from .transfer import TransferPlan, build_transfer_units, ft_tag, load_transfer_plan, parse_transfer_plan, scratch_tag
from .units import unit_graph

MATRIX_JSON = "matrix.json"
MATRIX_MD = "matrix.md"
PROXY_FILE = "proxy.json"
PICTURE = "curriculum.png"


def transfer_dir(name: str) -> Path:
    return workspace.home() / "transfers" / name


def _study_plan(plan: TransferPlan):
    from .driver import _load

    try:
        return _load(plan.study)
    except UnknownReferenceError as e:
        raise UnknownReferenceError(
            f"transfer plan study = {plan.study!r}: {e} (the transfer uses its base data and checkpoints)"
        ) from None


def _check_workspace(plan: TransferPlan) -> None:
    """Every task's checkpoint is catalogued and its data present (or collectable): one line per problem."""
    from nsl.datasets import api

    for t in plan.tasks:
        try:
            actions.resolve_checkpoint(t.checkpoint)
        except UnknownReferenceError as e:
            raise UnknownReferenceError(
                f"transfer task {t.shift}: checkpoint {t.checkpoint} is not catalogued ({e}); "
                f"run `nsl study run {plan.study}` first, or fix the reference"
            ) from None
        if t.collect is not None:
            continue
        versions = api.list_versions(t.data)
        if not versions:
            raise UnknownReferenceError(
                f"transfer task {t.shift}: dataset {t.data!r} is not in {workspace.home()}; "
                f"run `nsl study run {plan.study}` first, or add a collect recipe to the task"
            )
        n = api.open_version(f"{t.data}@v{versions[-1]}").num_episodes
        if n < t.episodes:
            raise ConfigError(
                f"transfer task {t.shift}: dataset {t.data} has {n} episodes, fewer than episodes = "
                f"{t.episodes}; lower it or collect more"
            )


def _ft_lr(base_ref: str) -> float:
    """The study's fine-tuning learning rate: 25% of the base checkpoint's (``nsl.learners`` default)."""
    from nsl.learners.config import FINE_TUNE_LR_FACTOR

    entry = actions.resolve_checkpoint(base_ref)
    return FINE_TUNE_LR_FACTOR * float(json.loads((Path(entry.path) / "config.json").read_text())["training"]["lr"])


def _check_saved_plan(plan: TransferPlan) -> None:
    saved = transfer_dir(plan.name) / PLAN_FILE
    if saved.is_file() and json.loads(saved.read_text()) != json.loads(json.dumps(plan.to_dict())):
        raise ConfigError(
            f"transfer {plan.name!r} exists with a different plan ({saved}); run it with the same plan "
            "to resume, or choose another --name"
        )


def prepare_transfer(plan_ref: str, name: str | None = None):
    """Load and check everything and build the unit graph; writes nothing."""
    plan = load_transfer_plan(plan_ref)
    if name:
        plan = parse_transfer_plan({**plan.to_dict(), "name": name}, plan.source)
    _check_saved_plan(plan)
    study = _study_plan(plan)
    base = actions.base_sources(study)
    _check_workspace(plan)
    units = build_transfer_units(plan, study.base, base, _ft_lr(study.base))
    return plan, units, unit_graph(units)


def estimate_transfer(plan_ref: str, name: str | None = None, slots: int | None = None):
    """The estimated cost of the units not done yet (nothing runs, nothing is written); with ``slots``, also
    the wall time with that many units at once: (cost, schedule)."""
    from .driver import estimate_units

    _, units, graph = prepare_transfer(plan_ref, name)
    return estimate_units(units, graph, slots)


def run_transfer(
    plan_ref: str,
    name: str | None = None,
    workers: int = 1,
    progress: bool = True,
    cluster: str | None = None,
    unit_cpus: float = 1.0,
    store: str | None = None,
    wait: bool = False,
    unit_gpus: float = 0.0,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Run (or resume) a transfer, then write its matrix and report: (final status record, report summary).

    ``cluster``, ``unit_cpus``, ``unit_gpus``, ``store`` and ``wait`` as for :func:`nsl.study.driver.run_study`."""
    if workers < 1:
        raise ConfigError(f"--workers {workers} must be at least 1")
    plan, units, graph = prepare_transfer(plan_ref, name)  # checks everything, writes nothing
    with writer_lock(transfer_dir(plan.name), f"transfer {plan.name!r}", wait=wait):
        _check_saved_plan(plan)  # again: a run that held the lock may have saved another plan
        status = run_planned(
            transfer_dir(plan.name),
            "transfer",
            plan.name,
            plan,
            units,
            graph,
            workers=workers,
            progress=progress,
            cluster=cluster,
            unit_cpus=unit_cpus,
            unit_gpus=unit_gpus,
            store=store,
        )
        return status, write_transfer_report(plan.name)


def load_saved(name: str) -> TransferPlan:
    path = transfer_dir(name) / PLAN_FILE
    if not path.is_file():
        root = workspace.home() / "transfers"
        known = sorted(p.name for p in root.glob("*") if (p / PLAN_FILE).is_file())
        raise UnknownReferenceError(
            f"no transfer named {name!r} in {workspace.home()}; "
            + (f"known: {', '.join(known)}" if known else "start one with `nsl transfer run small`")
        )
    return parse_transfer_plan(json.loads(path.read_text()), source=str(path), default_name=name)


def transfer_status(name: str) -> dict[str, Any]:
    """The status record, with 'running' units of a dead scheduler shown as 'interrupted'."""
    load_saved(name)
    return live_status(transfer_dir(name) / STATUS_FILE, "transfer", name)


# --- the matrix -----------------------------------------------------------------------------------------------------


def _curve_auc(plan: TransferPlan, tag: str) -> float | None:
    """AUC of a finished run's success curve (step 0 to the last step), or None while it is not finished."""
    from nsl.eval import CURVE_FILE, curve_auc, read_curve

    path = workspace.runs_dir() / f"{plan.name}-{tag}" / CURVE_FILE
    if not path.is_file():
        return None
    points = [(r.step, r.target.success_rate) for r in read_curve(path) if r.target is not None]
    if len(points) < 2 or points[0][0] != 0 or points[-1][0] != plan.steps:
        return None
    return curve_auc([s for s, _ in points], [v for _, v in points])


def _proxies(plan: TransferPlan, checkpoints: dict[str, Any]) -> dict[tuple[str, str], dict[str, float]]:
    """Proxy scores of each source's checkpoint on each target's first ``proxy_episodes`` episodes."""
    from nsl.datasets import api

    from .proxy import ProxyCache, target_view

    cache = ProxyCache(transfer_dir(plan.name) / PROXY_FILE)
    out = {}
    for dst in plan.tasks:
        if not api.list_versions(dst.data):
            continue
        view = target_view(f"{dst.data}:{dst.episodes}", plan.proxy_episodes)
        for src in plan.tasks:
            if src.shift != dst.shift and checkpoints.get(src.shift):
                entry = checkpoints[src.shift]
                out[(src.shift, dst.shift)] = cache.scores(entry.id, entry.path, view)
    return out


def measure_matrix(plan: TransferPlan):
    """The :class:`~nsl.curriculum.TransferMatrix` of the runs finished so far, with AUCs and proxy scores."""
    from nsl.curriculum import TransferMatrix, advantage, rank_correlation

    from .proxy import PROXIES

    checkpoints = {}
    for t in plan.tasks:
        try:
            checkpoints[t.shift] = actions.resolve_checkpoint(t.checkpoint)
        except UnknownReferenceError:
            checkpoints[t.shift] = None
    names = plan.task_names
    scratch = {
        d: {s: a for s in plan.seeds if (a := _curve_auc(plan, scratch_tag(plan, d, s))) is not None} for d in names
    }
    ft: dict[tuple[str, str], dict[int, float]] = {}
    entries = {}
    for d in names:
        for s_ in names:
            if s_ != d:
                ft[(s_, d)] = {s: a for s in plan.seeds if (a := _curve_auc(plan, ft_tag(plan, s_, d, s))) is not None}
                entries[(s_, d)] = advantage(ft[(s_, d)], scratch[d], plan.floor)
    proxies = _proxies(plan, checkpoints)
    adv = {p: e.value for p, e in entries.items()}
    correlation = {k: rank_correlation({p: v.get(k) for p, v in proxies.items()}, adv).to_dict() for k in PROXIES}
    meta = {
        "transfer": plan.name,
        "study": plan.study,
        "plan": plan.to_dict(),
        "code_version": code_version(),
        "auc_floor": plan.floor,
        "definitions": {
            "auc": "trapezoid area under the success curve from step 0 to the last step, divided by "
            "the step range (nsl.eval.curve_auc)",
            "advantage": "mean over seeds of AUC(fine-tune, seed s) / max(AUC(scratch, seed s), "
            "auc_floor); interval: 95% Student-t over seeds",
            "proxy": "Q-ranking AUC and SoftOPC of the source checkpoint on the target's first proxy_episodes episodes",
        },
        "checkpoints": {
            t: None if e is None else {"ref": plan.task(t).checkpoint, "id": e.id, "resolved": e.ref}
            for t, e in checkpoints.items()
        },
        "scratch_auc": {d: {str(s): a for s, a in v.items()} for d, v in scratch.items()},
        "ft_auc": {s_: {d: {str(s): a for s, a in ft[(s_, d)].items()} for d in names if d != s_} for s_ in names},
        "entries": {s_: {d: entries[(s_, d)].to_dict() for d in names if d != s_} for s_ in names},
        "proxy": {s_: {d: proxies.get((s_, d)) for d in names if d != s_} for s_ in names},
        "rank_correlation": correlation,
    }
    interval = {p: e.interval for p, e in entries.items() if e.interval is not None}
    return TransferMatrix(names, adv, interval, "base" if "base" in names else None, meta)


def _render(matrix, status: dict[str, Any], figure: str | None, curriculum) -> str:
    from nsl.curriculum import Correlation

    meta = matrix.meta
    plan = meta["plan"]
    units = status.get("units", {})
    done = sum(u["state"] == "done" for u in units.values())
    lines = [
        f"# Transfer matrix: {meta['transfer']}",
        "",
        f"Study `{meta['study']}`; {len(matrix.tasks)} tasks; every run {plan['steps']} gradient steps, "
        f"success on the target every {plan['every']} steps on {plan['eval_episodes']} scenes (seed "
        f"{plan['eval_seed']}); training seeds {list(plan['seeds'])}; {done} of {len(units)} units done.",
        "Definitions: docs/transfer.md.  A > 1: fine-tuning from the row's checkpoint learns the column's task "
        "faster than from scratch.",
        "",
        "## Advantage A(row -> column), mean over seeds [95% interval over seeds]",
        "",
        matrix.markdown(),
        "",
        f"## AUC of training from scratch (floor {meta['auc_floor']:.3f})",
        "",
        "| task | " + " | ".join(f"seed {s}" for s in plan["seeds"]) + " |",
        "|---|" + "---|" * len(plan["seeds"]),
    ]
    for d in matrix.tasks:
        cells = [meta["scratch_auc"][d].get(str(s)) for s in plan["seeds"]]
        lines.append(f"| {d} | " + " | ".join("n/a" if c is None else f"{c:.3f}" for c in cells) + " |")
    lines += [
        "",
        "## Offline proxy: Q-ranking AUC of the row's checkpoint on the column's data",
        "",
        "| from \\ to | " + " | ".join(matrix.tasks) + " |",
        "|" + "---|" * (len(matrix.tasks) + 1),
    ]
    for s_ in matrix.tasks:
        cells = [
            "-"
            if s_ == d
            else "n/a"
            if not (meta["proxy"][s_].get(d) or {}).get("auc")
            else f"{meta['proxy'][s_][d]['auc']:.3f}"
            for d in matrix.tasks
        ]
        lines.append(f"| {s_} | " + " | ".join(cells) + " |")
    lines += ["", "Rank correlation of the proxy with the measured advantage, over (source, target) pairs:", ""]
    for k, c in meta["rank_correlation"].items():
        lines.append(f"- {k}: {Correlation(**c)}")
    lines.append("")
    if curriculum is None:
        lines += ["## Curriculum", "", "Not every pair is measured yet; run the same `nsl transfer run` to finish."]
    else:
        lines += ["## Curriculum (nsl curriculum)", "", "```", *curriculum.lines(), "```"]
        if figure:
            lines += ["", f"![curricula]({figure})"]
    return "\n".join(lines)


def write_transfer_report(name: str) -> dict[str, Any]:
    """Write matrix.json, matrix.md (and curriculum.png when complete); returns paths and the correlations."""
    from nsl.curriculum import build_curriculum, plot_curriculum, save_matrix

    plan = load_saved(name)
    folder = transfer_dir(name)
    matrix = measure_matrix(plan)
    save_matrix(matrix, folder / MATRIX_JSON)
    complete = all(v is not None for v in matrix.advantage.values())
    curriculum = build_curriculum(matrix) if complete else None
    figure = plot_curriculum(curriculum, folder / PICTURE).name if curriculum else None
    text = _render(matrix, read_status(folder / STATUS_FILE), figure, curriculum)
    workspace.atomic_write_bytes(folder / MATRIX_MD, (text + "\n").encode())
    measured = sum(v is not None for v in matrix.advantage.values())
    return {
        "matrix": folder / MATRIX_JSON,
        "report": folder / MATRIX_MD,
        "measured": measured,
        "pairs": len(matrix.advantage),
        "rank_correlation": matrix.meta["rank_correlation"],
    }


# --- following the curricula ----------------------------------------------------------------------------------------


def _final_success(plan: TransferPlan, tag: str) -> float | None:
    from nsl.eval import CURVE_FILE, read_curve

    path = workspace.runs_dir() / f"{plan.name}-{tag}" / CURVE_FILE
    if _curve_auc(plan, tag) is None:
        return None
    return [r.target.success_rate for r in read_curve(path) if r.target is not None][-1]


def prepare_curricula(name: str, seeds: tuple[int, ...] | None = None):
    """The curricula plan of a finished transfer (its optimal and pessimal trees) and the units that follow it."""
    from nsl.curriculum import build_curriculum

    from .curricula import TREES, CurriculaPlan, build_curricula_units, default_seeds, folder

    plan = load_saved(name)
    matrix = measure_matrix(plan)
    missing = sum(v is None for v in matrix.advantage.values())
    if missing:
        raise ConfigError(
            f"transfer {name!r} has {missing} unmeasured pairs; finish `nsl transfer run` first "
            "(the curricula come from the complete matrix)"
        )
    seeds = tuple(seeds) if seeds else default_seeds(plan)
    overlap = sorted(set(seeds) & set(plan.seeds))
    if overlap:
        raise ConfigError(
            f"--seed {','.join(map(str, seeds))} repeats the matrix's own seeds {overlap}; following a "
            "curriculum with them would rerun the matrix's runs, so choose others"
        )
    curriculum = build_curriculum(matrix)
    cplan = CurriculaPlan(name, seeds, {t: dict(getattr(curriculum, t).parent) for t in TREES})
    saved = folder(name) / PLAN_FILE
    if saved.is_file() and json.loads(saved.read_text()) != json.loads(json.dumps(cplan.to_dict())):
        raise ConfigError(
            f"the curricula of transfer {name!r} were started with other trees or seeds ({saved}); "
            "use the same --seed to resume"
        )
    study = _study_plan(plan)
    units = build_curricula_units(plan, cplan, study.base, actions.base_sources(study), _ft_lr(study.base))
    return plan, cplan, units, unit_graph(units)


def run_curricula(
    name: str, seeds: tuple[int, ...] | None = None, workers: int = 1, progress: bool = True
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Follow the optimal and pessimal curricula of transfer ``name`` for real (resumable), then report."""
    from .curricula import folder

    if workers < 1:
        raise ConfigError(f"--workers {workers} must be at least 1")
    _, cplan, units, graph = prepare_curricula(name, seeds)
    status = run_planned(folder(name), "curricula", name, cplan, units, graph, workers=workers, progress=progress)
    return status, write_curricula_report(name)


def write_curricula_report(name: str) -> dict[str, Any]:
    """curricula.json and curricula.md from the runs finished so far."""
    from .curricula import RESULT_JSON, RESULT_MD, CurriculaPlan, folder, measure, render

    plan = load_saved(name)
    path = folder(name) / PLAN_FILE
    if not path.is_file():
        raise UnknownReferenceError(f"transfer {name!r} has no curricula yet; run `nsl transfer curricula {name}`")
    saved = json.loads(path.read_text())
    cplan = CurriculaPlan(saved["transfer"], tuple(saved["seeds"]), saved["trees"], str(path))
    result = measure(
        plan, cplan, measure_matrix(plan), lambda tag: _curve_auc(plan, tag), lambda tag: _final_success(plan, tag)
    )
    workspace.atomic_write_json(folder(name) / RESULT_JSON, result)
    workspace.atomic_write_bytes(folder(name) / RESULT_MD, (render(result, name) + "\n").encode())
    return {"result": folder(name) / RESULT_JSON, "report": folder(name) / RESULT_MD, **result}
