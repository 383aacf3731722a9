"""The study's adapter to the library: run one unit, tell whether its output exists, find the base data.

Collection and evaluation units call the commands' own functions (``nsl.commands.collect.collect``,
``nsl.commands.eval.evaluate``), so a unit's dataset or evaluation is exactly what ``nsl collect`` or
``nsl eval`` would make.  Training units repeat the call sequence of ``nsl/commands/train.py`` (data mix,
catalogued parent, a monitor whose patience outlasts the run, catalogued evaluated steps), because the
study records every evaluated step and replays each stopping criterion afterwards.

``nsl.commands._refs`` (policy factories, dataset registration, the shipped base) is
imported here only.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, CorruptDataError, UnknownReferenceError

from .plan import Plan
from .units import BaseSource, Unit

IMAGE_SIZE = 64
EPISODES_PER_FILE = 100  # nsl collect's default: part of a dataset's content, so of its hash


def _resolve():
    import nsl.commands._refs as resolve  # the one import of the reference glue

    return resolve


# --- references ----------------------------------------------------------------------------------------------------

def resolve_checkpoint(ref: str):
    """A catalogued checkpoint (the shipped base registers itself on first use)."""
    from nsl.catalog import Catalog

    with Catalog() as cat:
        return _resolve().resolve_init(cat, ref)


def _versions_with_hash(name: str, want: str | None) -> list[str]:
    from nsl.datasets import api

    try:
        vs = api.list_versions(name)
    except (UnknownReferenceError, ConfigError):
        return []
    refs = []
    for v in vs:
        ver = api.open_version(f"{name}@v{v}")
        if want is None or ver.hash == want:
            refs.append(ver.ref)
    return refs


def base_sources(plan: Plan) -> list[BaseSource]:
    """The base-task data of the study, checked against the workspace before any work starts.

    Source ``checkpoint``: the datasets and weights the base checkpoint's config records; a dataset missing
    from the workspace is collected again by its plan recipe and must reproduce the recorded hash.  Source
    ``plan``: the plan's datasets, collected when missing.  Raises a one-line error when base data is missing
    and cannot be collected, or when the workspace holds other data under a recorded name.
    """
    from nsl.datasets import api

    recipes = {d.name: d for d in plan.base_data.datasets}
    out = []
    if plan.base_data.source == "checkpoint":
        entry = resolve_checkpoint(plan.base)
        config = json.loads((Path(entry.path) / "config.json").read_text())
        sources = (config.get("data") or {}).get("sources") or []
        if not sources:
            raise ConfigError(f"base checkpoint {plan.base} records no training data; set base_data.source = 'plan' "
                              "and list the base datasets in the plan")
        total = sum(float(s["weight"]) for s in sources)
        for s in sources:
            name = api.parse_ref(s["ref"]).name
            want = s["version_hash"] if plan.base_data.verify else None  # verify = false: any version will do
            present = [r for r in _versions_with_hash(name, want)
                       if api.open_version(r).num_episodes >= int(s["episodes"])]
            recipe = _recipe(recipes[name]) if name in recipes else None  # a unit, done when the data is there
            if not present:
                if name not in recipes:
                    raise UnknownReferenceError(
                        f"base data {s['ref']} ({s['version_hash'][:19]}...) of {plan.base} is not in $NSL_HOME and the "
                        "plan has no "
                        f"recipe to collect it; add a [[base_data.datasets]] entry named {name!r} "
                        "(scripts/collect_base_data.sh has the commands) or copy the dataset into the workspace")
                if want is not None and _versions_with_hash(name, None):
                    raise CorruptDataError(
                        f"the workspace holds dataset {name!r} but no version with the hash {plan.base} was trained "
                        f"on ({want[:19]}...); remove it, use another NSL_HOME, or set base_data.verify = false")
                r = recipes[name]
                if r.episodes != int(s["episodes"]):
                    raise ConfigError(f"plan base_data.datasets {name!r} has episodes = {r.episodes}, but {plan.base} "
                                      f"was trained on {s['episodes']}; the recipe must match the recorded data")
                recipe = _recipe(r)
            out.append(BaseSource(name, float(s["weight"]) / total, want, int(s["episodes"]), recipe))
        return out
    total = sum(d.weight for d in plan.base_data.datasets)
    for d in plan.base_data.datasets:
        present = [r for r in _versions_with_hash(d.name, None) if api.open_version(r).num_episodes >= d.episodes]
        if present:
            _check_provenance(present[-1], _recipe(d))
        out.append(BaseSource(d.name, d.weight / total, None, d.episodes, _recipe(d)))
    return out


def _recipe(d) -> dict[str, Any]:
    return {"shift": d.shift, "policy": d.policy, "policy_ref": d.policy, "episodes": d.episodes, "seed": d.seed,
            "epsilon": 0.0, "batch": 8}


def _check_provenance(ref: str, recipe: Mapping[str, Any]) -> None:
    from nsl.datasets import api

    spec = api.open_version(ref).provenance["collections"][-1]["spec"]
    got = (spec.get("env", {}).get("shift"), spec.get("policy_ref"), spec.get("seed"))
    want = (recipe["shift"], recipe["policy_ref"], recipe["seed"])
    if got != want:
        raise ConfigError(f"dataset {ref} was collected as (shift, policy, seed) = {got}, but the plan's recipe says "
                          f"{want}; rename one of them")


# --- done? ----------------------------------------------------------------------------------------------------------

def is_done(unit: Unit) -> bool:
    """True when the unit's output (dataset version, checkpoint, evaluation) exists and is complete."""
    p = unit.params
    if unit.kind == "collect":
        from nsl.datasets import api

        refs = _versions_with_hash(p["dataset"], p.get("expect_hash"))  # tiers are views: a larger one will do
        return any(api.open_version(r).num_episodes >= p["episodes"] for r in refs)
    if unit.kind == "train":
        return _checkpoint_at(p["checkpoint"], p["steps"]) is not None
    if unit.kind == "eval":
        return evaluation(p["checkpoint_ref"], p["shift"], p["episodes"], p["seed"]) is not None
    raise ConfigError(f"unit {unit.name} has unknown kind {unit.kind!r}")


def _checkpoint_at(name: str, step: int):
    from nsl.catalog import Catalog

    with Catalog() as cat:
        try:
            return cat.resolve_checkpoint(f"ckpt:{name}@{step}")
        except UnknownReferenceError:
            return None


def evaluation(ref: str, shift: str, episodes: int, seed: int):
    """The catalogued evaluation of a checkpoint on a shift (test objects, that seed and size), or None."""
    from nsl.catalog import Catalog

    with Catalog() as cat:
        try:
            entry = _resolve().resolve_init(cat, ref)
        except UnknownReferenceError:
            return None
        for e in cat.evaluations(entry.id, shift):
            if e.split == "test" and e.seed == seed and e.episodes == episodes:
                return e
    return None


# --- run ------------------------------------------------------------------------------------------------------------

def run_unit(unit: Unit, workers: int = 1, progress: bool = True) -> dict[str, Any]:
    """Do the unit's job; ``workers`` simulator processes inside it.  Returns a small summary."""
    started = time.perf_counter()
    if unit.kind == "collect":
        out = _collect(unit, workers, progress)
    elif unit.kind == "train":
        out = _train(unit, workers, progress)
    elif unit.kind == "eval":
        out = _evaluate(unit, workers, progress)
    else:
        raise ConfigError(f"unit {unit.name} has unknown kind {unit.kind!r}")
    return {**out, "seconds": round(time.perf_counter() - started, 2)}


def _collect(unit: Unit, workers: int, progress: bool) -> dict[str, Any]:
    """``nsl collect`` (begin or resume, fill the missing episodes, publish, catalogue), then check the hash."""
    from nsl.commands.collect import collect

    p = unit.params
    version = collect(shift=p["shift"], episodes=p["episodes"], policy=p["policy_ref"], data=p["dataset"],
                      workers=workers, seed=p["seed"], batch_size=p["batch"], image_size=IMAGE_SIZE,
                      episodes_per_file=EPISODES_PER_FILE, epsilon=p["epsilon"], progress=progress)
    if p.get("expect_hash") and version.hash != p["expect_hash"]:
        raise CorruptDataError(
            f"dataset {version.ref} collected again has hash {version.hash[:19]}..., but the base checkpoint records "
            f"{p['expect_hash'][:19]}...; the simulator or recipe changed since the base was trained")
    return {"dataset": version.ref, "hash": version.hash, "episodes": version.num_episodes,
            "success_rate": float(version.episodes.success.mean())}


def _data_mix(p: Mapping[str, Any]) -> list[tuple[str, float]]:
    mix = []
    for b in p["base"]:
        refs = _versions_with_hash(b["dataset"], b["hash"])
        if not refs:
            raise UnknownReferenceError(f"base dataset {b['dataset']} ({b['hash'] or 'any version'}) is missing; "
                                        "run the study again to collect it")
        mix.append((refs[-1] if b["hash"] else f"{refs[-1]}:{b['episodes']}", float(b["weight"])))
    t = p["target"]
    mix.append((f"{t['dataset']}:{t['tier']}", float(t["weight"])))
    return mix


def _train(unit: Unit, workers: int, progress: bool) -> dict[str, Any]:
    """As in nsl/commands/train.py: resolve data and parent, train (resumable), catalogue the checkpoint(s)."""
    from nsl import code_version, workspace
    from nsl.catalog import Catalog
    from nsl.datasets import api
    from nsl.learners import TrainConfig, inherited_settings, train

    p = unit.params
    mix = _data_mix(p)
    resolve = _resolve()
    with Catalog() as cat:
        uses = resolve.dataset_uses(cat, mix)
        parent = resolve.resolve_init(cat, p["init_ref"]) if p["init_ref"] else None
    monitor_cfg = p.get("monitor")
    sources: list[tuple[Any, float]] = list(mix)
    held_out = None
    if monitor_cfg and monitor_cfg.get("holdout"):
        train_view, held_out = api.episode_split(api.open_view(mix[-1][0]), monitor_cfg["holdout"])
        sources[-1] = (train_view, mix[-1][1])
    config = TrainConfig(steps=p["steps"], seed=p["seed"], checkpoint_every=min(p["checkpoint_every"], p["steps"]),
                         eval_every=monitor_cfg["every"] if monitor_cfg else 0, lr=p.get("lr"),  # lr: None = default
                         **(inherited_settings(parent.path) if parent else {}))  # the parent's n-step and crop
    sampler = api.make_sampler(sources, n_step=config.n_step, gamma=config.gamma)
    run_dir = workspace.runs_dir() / p["checkpoint"]
    run_dir.mkdir(parents=True, exist_ok=True)
    workspace.atomic_write_json(run_dir / "command.json", {
        "argv": ["nsl", "study", "unit", unit.name], "data": [u.__dict__ for u in uses],
        "init": parent.id if parent else None, "target_shift": p["shift"], "code_version": code_version(),
        "unit": dict(p)})
    monitor = _monitor(p["shift"], monitor_cfg, run_dir, held_out, p["steps"], workers) if monitor_cfg else None
    result = train(config, sampler, run_dir, init_checkpoint=parent.path if parent else None, method=p["method"],
                   eval_fn=monitor, progress=progress)
    with Catalog() as cat:
        if monitor is not None:
            _register_evaluated(cat, p["checkpoint"], run_dir, parent, uses, p["shift"], monitor_cfg["seed"])
        entry = _register(cat, p["checkpoint"], result.checkpoint, parent, uses, p["shift"])
    return {"checkpoint": f"ckpt:{p['checkpoint']}@{result.step}", "id": entry.id}


def _monitor(shift: str, m: Mapping[str, Any], run_dir: Path, held_out, steps: int, workers: int):
    """As in nsl/commands/train.py: simulator success on target and base, offline scores on held-out episodes.

    The patience is larger than the run, so the run always trains to its last step (the study replays each
    criterion's patience on the recorded curve afterwards).  ``base_episodes`` 0 skips the base task.
    """
    from nsl.collectors import parse_shift
    from nsl.eval import EarlyStopConfig, EarlyStopMonitor, simulator_scorer

    cfg = EarlyStopConfig(every=m["every"], episodes=m["episodes"], base_episodes=m["base_episodes"],
                          patience=steps // m["every"] + 2, criterion="eval", seed=m["seed"],
                          held_out=m.get("holdout") or 0.1)
    score_base = (simulator_scorer(parse_shift("base"), cfg.eval_config(base=True, workers=workers))
                  if m["base_episodes"] else None)
    return EarlyStopMonitor(cfg, run_dir, score_target=simulator_scorer(parse_shift(shift),
                                                                        cfg.eval_config(workers=workers)),
                            score_base=score_base, offline=_offline_scorer(held_out) if held_out is not None else None)


def _offline_scorer(view):
    """As in nsl/commands/train.py: Q-values on held-out target transitions -> SoftOPC and AUC."""
    import numpy as np

    from nsl import keys
    from nsl.eval import offline_scores

    arrays = view.episodes_arrays()
    episode = arrays[keys.EPISODE_INDEX]
    success_by_episode = {e: bool(arrays[keys.SUCCESS][episode == e].any()) for e in np.unique(episode)}
    labels = np.array([success_by_episode[e] for e in episode])
    obs = {"image": arrays[keys.OBS_IMAGE], "state": arrays[keys.OBS_STATE]}

    def score(policy) -> dict:
        q = np.concatenate([policy.q_values({k: v[i:i + 512] for k, v in obs.items()},
                                            arrays[keys.ACTION][i:i + 512])
                            for i in range(0, len(labels), 512)])
        if labels.all() or not labels.any():
            return {}  # no criterion is defined without both successes and failures
        return {k: v for k, v in offline_scores(q, labels).items() if k in ("softopc", "auc")}

    return score


def _register(cat, name: str, folder: Path, parent, uses, shift: str):
    config = json.loads((Path(folder) / "config.json").read_text())
    return cat.save_checkpoint(name, int(config.get("step", 0)), Path(folder) / "model.safetensors", config,
                               parent=parent.id if parent else None, data=uses, shift=shift)


def _register_evaluated(cat, name: str, run_dir: Path, parent, uses, shift: str, seed: int) -> None:
    """As in nsl/commands/train.py: catalogue every evaluated step with its evaluations."""
    from nsl.eval import read_curve

    for row in read_curve(run_dir / "curve.csv"):
        folder = run_dir / "checkpoints" / f"step-{row.step:09d}"
        if row.target is None or not folder.is_dir():
            continue
        entry = _register(cat, name, folder, parent, uses, shift)
        for task, r in ((shift, row.target), ("base", row.base)):
            if r is not None and r.episodes:
                cat.add_evaluation(entry.id, task, episodes=r.episodes, successes=round(r.success_rate * r.episodes),
                                   seed=seed, extra={"source": "study curve", "step": row.step})


def _evaluate(unit: Unit, workers: int, progress: bool) -> dict[str, Any]:
    """``nsl eval``: success with a Wilson interval on test objects, stored in the catalog."""
    from nsl.commands.eval import evaluate

    p = unit.params
    result = evaluate([p["checkpoint_ref"]], shift=p["shift"], episodes=p["episodes"], seed=p["seed"],
                      workers=workers, batch_size=8, progress=progress, source="study")
    (r,) = result["table"][p["checkpoint_ref"]].values()
    return {"successes": r.successes, "episodes": r.episodes}
