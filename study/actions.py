"""The study's adapter to the services: run one unit, tell whether its output exists, find the base data.

Every unit calls the service behind the matching command (``nsl.services``: collect, train,
evaluate), so a unit's dataset, checkpoint or evaluation is exactly what ``nsl collect``,
``nsl train`` or ``nsl eval`` would make.  Training units with a curve record every criterion
(simulator, SoftOPC, AUC, TD error) and never stop early: the study replays each criterion's
patience on the recorded curve afterwards.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, CorruptDataError, UnknownReferenceError
from nsl.services.refs import resolve_init

from .plan import Plan
from .units import BaseSource, Unit

IMAGE_SIZE = 64
EPISODES_PER_FILE = 100  # nsl collect's default: part of a dataset's content, so of its hash


# --- references ----------------------------------------------------------------------------------------------------


def resolve_checkpoint(ref: str):
    """A catalogued checkpoint (the shipped base registers itself on first use)."""
    from nsl.catalog import Catalog

    with Catalog() as cat:
        return resolve_init(cat, ref)


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
            raise ConfigError(
                f"base checkpoint {plan.base} records no training data; set base_data.source = 'plan' "
                "and list the base datasets in the plan"
            )
        total = sum(float(s["weight"]) for s in sources)
        for s in sources:
            name = api.parse_ref(s["ref"]).name
            want = s["version_hash"] if plan.base_data.verify else None  # verify = false: any version will do
            present = [
                r for r in _versions_with_hash(name, want) if api.open_version(r).num_episodes >= int(s["episodes"])
            ]
            recipe = _recipe(recipes[name]) if name in recipes else None  # a unit, done when the data is there
            if not present:
                if name not in recipes:
                    raise UnknownReferenceError(
                        f"base data {s['ref']} ({s['version_hash'][:19]}...) of {plan.base} is not in $NSL_HOME "
                        "and the plan has no "
                        f"recipe to collect it; add a [[base_data.datasets]] entry named {name!r} "
                        "(scripts/collect_base_data.sh has the commands) or copy the dataset into the workspace"
                    )
                if want is not None and _versions_with_hash(name, None):
                    raise CorruptDataError(
                        f"the workspace holds dataset {name!r} but no version with the hash {plan.base} was trained "
                        f"on ({want[:19]}...); remove it, use another NSL_HOME, or set base_data.verify = false"
                    )
                r = recipes[name]
                if r.episodes != int(s["episodes"]):
                    raise ConfigError(
                        f"plan base_data.datasets {name!r} has episodes = {r.episodes}, but {plan.base} "
                        f"was trained on {s['episodes']}; the recipe must match the recorded data"
                    )
                recipe = _recipe(r)
            out.append(BaseSource(name, float(s["weight"]) / total, want, int(s["episodes"]), recipe))
        return out
    recorded = _recorded_data(plan.base) if plan.base_data.verify else {}
    total = sum(d.weight for d in plan.base_data.datasets)
    for d in plan.base_data.datasets:
        want = recorded.get((d.name, d.episodes))  # the hash the base checkpoint records for this recipe's data
        present = [r for r in _versions_with_hash(d.name, want) if api.open_version(r).num_episodes >= d.episodes]
        if present:
            _check_provenance(present[-1], _recipe(d))
        elif want is not None and _versions_with_hash(d.name, None):
            raise CorruptDataError(
                f"the workspace holds dataset {d.name!r} but no version with the hash {plan.base} records for it "
                f"({want[:19]}...); remove it, use another NSL_HOME, or set base_data.verify = false"
            )
        out.append(BaseSource(d.name, d.weight / total, want, d.episodes, _recipe(d)))
    return out


def _recorded_data(ref: str) -> dict[tuple[str, int], str]:
    """``{(dataset name, episodes): content hash}`` of the training data a checkpoint's config records."""
    from nsl.datasets import api

    config = json.loads((Path(resolve_checkpoint(ref).path) / "config.json").read_text())
    sources = (config.get("data") or {}).get("sources") or []
    return {
        (api.parse_ref(s["ref"]).name, int(s["episodes"])): s["version_hash"] for s in sources if s.get("version_hash")
    }


def _recipe(d) -> dict[str, Any]:
    return {
        "shift": d.shift,
        "policy": d.policy,
        "policy_ref": d.policy,
        "episodes": d.episodes,
        "seed": d.seed,
        "epsilon": 0.0,
        "batch": 8,
    }


def _check_provenance(ref: str, recipe: Mapping[str, Any]) -> None:
    from nsl.datasets import api

    spec = api.open_version(ref).provenance["collections"][-1]["spec"]
    got = (spec.get("env", {}).get("shift"), spec.get("policy_ref"), spec.get("seed"))
    want = (recipe["shift"], recipe["policy_ref"], recipe["seed"])
    if got != want:
        raise ConfigError(
            f"dataset {ref} was collected as (shift, policy, seed) = {got}, but the plan's recipe says "
            f"{want}; rename one of them"
        )


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
    if unit.kind == "features":
        return _checkpoint_at(p["checkpoint"], 0) is not None
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
            entry = resolve_init(cat, ref)
        except UnknownReferenceError:
            return None
        for e in cat.evaluations(entry.id, shift):
            if e.split == "test" and e.seed == seed and e.episodes == episodes and e.precision == "fp32":
                return e
    return None


# --- run ------------------------------------------------------------------------------------------------------------


def run_unit(unit: Unit, workers: int = 1, progress: bool = True, register: bool = True) -> dict[str, Any]:
    """Do the unit's job; ``workers`` simulator processes inside it.  Returns a small summary.

    ``register=False`` writes its dataset, checkpoint or evaluation to ``NSL_HOME`` but not to the catalog:
    the summary's ``made`` goes to :func:`register_unit` in the process that writes the catalog (the scheduler).
    """
    from nsl.services.refs import pin

    started = time.perf_counter()
    pin(unit.params.get("pinned") or {})  # checkpoints resolved by the scheduler (prepare_unit)
    try:
        if unit.kind == "collect":
            out = _collect(unit, workers, progress, register)
        elif unit.kind == "train":
            out = _train(unit, workers, progress, register)
        elif unit.kind == "eval":
            out = _evaluate(unit, workers, progress, register)
        elif unit.kind == "features":
            out = _features(unit, progress, register)
        else:
            raise ConfigError(f"unit {unit.name} has unknown kind {unit.kind!r}")
    finally:
        pin({})
    return {**out, "seconds": round(time.perf_counter() - started, 2)}


def prepare_unit(unit: Unit) -> Unit:
    """The unit with the checkpoints it reads resolved in the catalog (``params["pinned"]``), so that it runs
    where the catalog is not (a worker process, a cluster node).  Called when its dependencies are done."""
    from dataclasses import replace

    p = unit.params
    refs = [p.get("policy_ref"), p.get("init_ref"), p.get("checkpoint_ref"), p.get("like_ref")]
    refs = [r for r in refs if isinstance(r, str) and (r.startswith("ckpt:") or r == "base")]
    if not refs:
        return unit
    from nsl.catalog import Catalog

    with Catalog() as cat:
        pinned = {r: resolve_init(cat, r) for r in refs}
    return replace(unit, params={**p, "pinned": pinned})


def register_unit(unit: Unit, summary: Mapping[str, Any]) -> None:
    """Record in the catalog what a unit run with ``register=False`` made (idempotent)."""
    made = summary.get("made")
    if made is None:
        return
    if unit.kind == "collect":
        from nsl.datasets import api
        from nsl.services.collect import on_version_created

        on_version_created(api.open_version(made))
    elif unit.kind == "train":
        from nsl.services.train import register_training

        register_training(made)
    elif unit.kind == "eval":
        from nsl.services.evaluate import store_evaluation

        store_evaluation(made)
    elif unit.kind == "features":
        from nsl.services.features import register_features

        register_features(unit.params["checkpoint"], Path(made))


def _collect(unit: Unit, workers: int, progress: bool, register: bool = True) -> dict[str, Any]:
    """``nsl collect`` (begin or resume, fill the missing episodes, publish, catalogue), then check the hash."""
    from nsl.services.collect import CollectConfig, collect

    p = unit.params
    version = collect(
        CollectConfig(
            shift=p["shift"],
            episodes=p["episodes"],
            policy=p["policy_ref"],
            data=p["dataset"],
            workers=workers,
            seed=p["seed"],
            num_envs=p["batch"],
            image_size=IMAGE_SIZE,
            episodes_per_file=EPISODES_PER_FILE,
            epsilon=p["epsilon"],
        ),
        progress=progress,
        cluster="local",  # the unit's own simulators (on a cluster, the unit is the task)
        register=register,
    )
    if p.get("expect_hash") and version.hash != p["expect_hash"]:
        raise CorruptDataError(
            f"dataset {version.ref} collected again has hash {version.hash[:19]}..., but the base checkpoint records "
            f"{p['expect_hash'][:19]}...; the simulator or recipe changed since the base was trained"
        )
    return {
        "dataset": version.ref,
        "hash": version.hash,
        "episodes": version.num_episodes,
        "success_rate": float(version.episodes.success.mean()),
        **({} if register else {"made": version.ref}),
    }


def _data_mix(p: Mapping[str, Any]) -> list[tuple[str, float]]:
    mix = []
    for b in p["base"]:
        refs = _versions_with_hash(b["dataset"], b["hash"])
        if not refs:
            raise UnknownReferenceError(
                f"base dataset {b['dataset']} ({b['hash'] or 'any version'}) is missing; "
                "run the study again to collect it"
            )
        mix.append((refs[-1] if b["hash"] else f"{refs[-1]}:{b['episodes']}", float(b["weight"])))
    for t in [p["target"], *p.get("more_targets", ())]:
        if t is not None:  # None: a run on base data alone (the no_target baseline)
            mix.append((f"{t['dataset']}:{t['tier']}", float(t["weight"])))
    return mix


def _train(unit: Unit, workers: int, progress: bool, register: bool = True) -> dict[str, Any]:
    """``nsl train`` on the unit's data mix and parent (resumable); with a curve, every criterion to the last step."""
    from nsl.services.train import TrainOptions, train

    p = unit.params
    m = p.get("monitor") or {}
    options = TrainOptions(
        data=tuple(f"{ref}={weight!r}" for ref, weight in _data_mix(p)),
        name=p["checkpoint"],
        init=p["init_ref"],
        method=p["method"],
        steps=p["steps"],
        lr=p.get("lr"),
        seed=p["seed"],
        checkpoint_every=p["checkpoint_every"],
        target_shift=p["shift"],
        eval_every=m.get("every", 0),
        eval_episodes=m.get("episodes", 0),
        base_episodes=m.get("base_episodes", 0),
        eval_scenes=m.get("seed", 0),
        workers=workers,
        precision=p.get("precision", "fp32"),
        device=p.get("device", "auto"),
        learner=p.get("learner", "qtopt"),
        **({"shrink_perturb": tuple(p["shrink_perturb"])} if p.get("shrink_perturb") else {}),
        **({"holdout": m["holdout"]} if m.get("holdout") else {}),
        **({"criterion": m["criterion"]} if m.get("criterion") else {}),  # fqe: FQE's estimate on the curve too
    )
    result = train(
        options,
        progress=progress,
        record={
            "argv": ["nsl", "study", "unit", unit.name],
            "unit": {k: v for k, v in p.items() if k not in ("pinned", "store")},
        },
        offline=bool(m.get("holdout")),
        stop=False,
        source="study curve",
        quiet=True,
        register=register,
    )
    return {"checkpoint": result.checkpoint, "id": result.id, **({} if register else {"made": result.made})}


def _features(unit: Unit, progress: bool, register: bool = True) -> dict[str, Any]:
    """``nsl features``: the supervised features in the base's architecture (or the plan's ResNet encoder)."""
    from nsl.services.features import FeaturesConfig, features

    p = unit.params
    config = FeaturesConfig(
        like=p["like_ref"],
        encoder=p["encoder"],
        classes=p["classes"],
        frames=p["frames"],
        steps=p["steps"],
        seed=p["seed"],
        label=p.get("label", "classes"),
    )
    result = features(config, p["checkpoint"], progress=progress, register=register)
    return {"checkpoint": result.checkpoint, "id": result.id, **({} if register else {"made": str(result.path)})}


def _evaluate(unit: Unit, workers: int, progress: bool, register: bool = True) -> dict[str, Any]:
    """``nsl eval``: success with a Wilson interval on test objects, stored in the catalog."""
    from nsl.services.evaluate import EvaluateOptions, evaluate

    p = unit.params
    result = evaluate(
        [p["checkpoint_ref"]],
        EvaluateOptions(shift=p["shift"], episodes=p["episodes"], seed=p["seed"], workers=workers, num_envs=8),
        progress=progress,
        source="study",
        cluster="local",
        register=register,
    )
    (r,) = result.table[p["checkpoint_ref"]].values()
    return {"successes": r.successes, "episodes": r.episodes, **({} if register else {"made": result})}


# --- a cluster without a shared file system (--store) -----------------------------------------------------------------


def unit_trees(unit: Unit) -> dict[str, str]:
    """The folders of ``NSL_HOME`` a prepared unit reads, relative to it: every version of the datasets it
    collects into or trains on, and its pinned checkpoints (``{what: folder}``)."""
    from nsl import workspace
    from nsl.datasets import api
    from nsl.share.store import relative

    p, home = unit.params, workspace.home()
    names = []
    if unit.kind == "collect":
        names = [p["dataset"]]
    elif unit.kind == "train":
        targets = [p["target"], *p.get("more_targets", ())] if p.get("target") else []
        names = [b["dataset"] for b in p["base"]] + [t["dataset"] for t in targets]
    trees = {}
    for name in names:
        for ref in _versions_with_hash(name, None):
            trees[ref] = relative(api.open_version(ref).root, home, f"dataset {ref}")
    for ref, entry in (p.get("pinned") or {}).items():
        trees[ref] = relative(entry.path, home, f"checkpoint {ref}")
    return trees


def stage_unit(unit: Unit, store: str) -> Unit:
    """:func:`prepare_unit`, then push the folders the unit reads to the store (what the store lacks) and
    name them in ``params["store"]``.  Runs on the driver before the unit starts."""
    from dataclasses import replace

    from nsl import workspace
    from nsl.share.store import Store

    unit = prepare_unit(unit)
    trees, s, home = unit_trees(unit), Store(store), workspace.home()
    for rel in dict.fromkeys(trees.values()):
        s.push(home, rel)
    return replace(unit, params={**unit.params, "store": {"url": store, "trees": trees}})


def run_staged_unit(unit: Unit, workers: int = 1, progress: bool = True) -> dict[str, Any]:
    """:func:`run_unit` on a node with its own ``NSL_HOME``: pull the unit's folders from the store, run it
    (``register=False``), push the folders it made.  The summary names them (``trees``) for the driver, and its
    ``made`` holds paths relative to ``NSL_HOME``."""
    from dataclasses import replace

    from nsl import workspace
    from nsl.share.store import Store, relative

    p, home = unit.params, workspace.home()
    staged = p["store"]
    s = Store(staged["url"])
    for rel in dict.fromkeys(staged["trees"].values()):
        s.pull(home, rel)
    pinned = {r: replace(e, path=str(home / staged["trees"][r])) for r, e in (p.get("pinned") or {}).items()}
    out = run_unit(replace(unit, params={**p, "pinned": pinned}), workers, progress, register=False)
    made, trees = out.get("made"), []
    if unit.kind == "collect" and made is not None:
        from nsl.datasets import api

        trees = [relative(api.open_version(made).root, home, f"dataset {made}")]
    elif unit.kind == "train" and made is not None:
        trees = [relative(made.run_dir, home, f"run {made.name}")]
        made = replace(made, run_dir=Path(trees[0]), final=Path(relative(made.final, home, f"run {made.name}")))
    elif unit.kind == "features" and made is not None:
        trees = [relative(Path(made).parent, home, f"run {p['checkpoint']}")]
        made = relative(Path(made), home, f"run {p['checkpoint']}")
    for rel in trees:
        s.push(home, rel)
    return {**out, "made": made, "trees": trees}


def register_staged_unit(unit: Unit, summary: Mapping[str, Any], store: str) -> None:
    """:func:`register_unit` on the driver for a unit run by :func:`run_staged_unit`: pull the folders it made
    into this ``NSL_HOME`` first."""
    from dataclasses import replace

    from nsl import workspace
    from nsl.share.store import Store

    s, home = Store(store), workspace.home()
    for rel in summary.get("trees") or []:
        s.pull(home, rel)
    made = summary.get("made")
    if unit.kind == "train" and made is not None:
        made = replace(made, run_dir=home / made.run_dir, final=home / made.final)
    elif unit.kind == "features" and made is not None:
        made = str(home / made)
    register_unit(unit, {**summary, "made": made})
