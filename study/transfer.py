"""A transfer plan: the tasks whose transfer advantages are measured, and the runs that measure them.

A transfer plan names tasks.  A task is a shift (``base`` or a spec such as ``offset_gripper@0.35``), a
catalogued checkpoint that has learned it, and its target data (a dataset and the number of episodes used).
For every ordered pair ``src != dst`` a train unit fine-tunes ``src``'s checkpoint on ``dst``'s data, and for
every ``dst`` a train unit trains from scratch on the same data; both record a success curve on ``dst``
(``curve.csv``: every ``every`` steps from step 0, ``eval_episodes`` test-object scenes, scene seed
``eval_seed``), once per training seed.  :mod:`nsl.curriculum.matrix` turns the curves into advantages.

Everything else is the study's recipe, taken from the study the plan names (``study``; it must have been
run in this workspace): the base checkpoint, and the base-task data that makes up half of every batch.
Every fine-tune uses the study's fine-tuning learning rate (25% of the base checkpoint's), whatever its
source, so that a source's own learning rate does not count as transfer; scratch runs use the base's.

Units are the study's own kinds (``collect``, ``train``), run by the study's scheduler, so they are resumable
and their outputs are ordinary catalogued datasets and checkpoints.  Names (``X`` is the plan's name)::

    base-data:NAME                      the study's base-task data, collected again if missing
    data:NAME                           a task's target data, collected when missing (if the task has a recipe)
    train:ft-SRC-to-DST-nK-kS-sSEED     fine-tune SRC's checkpoint on DST's data -> checkpoint X-ft-SRC-to-DST-...
    train:scratch-DST-nK-kS-sSEED       from scratch on DST's data -> checkpoint X-scratch-DST-...

Sections (``study/plans/transfer-small.toml`` is a commented example)::

    name, study                         the transfer's name (folder $NSL_HOME/transfers/NAME), the study it extends
    steps, every, eval_episodes, eval_seed, seeds, checkpoint_every, auc_floor, proxy_episodes
    [[tasks]]                           shift, checkpoint, data, episodes, optional collect = {policy, seed, epsilon}
"""

from __future__ import annotations

from dataclasses import MISSING, asdict, dataclass, fields, replace
from typing import Any

from nsl.errors import ConfigError, UnknownReferenceError
from nsl.refs import check_name

from .plan import _positive, _seeds, _shift, read_plan_toml
from .units import BaseSource, Unit, base_data_units, base_mix, slug

SHIPPED_TRANSFER = ("tiny", "small")  # study/plans/transfer-NAME.toml


@dataclass(frozen=True)
class TaskCollect:
    """How a task's target data is collected when the workspace lacks it (``nsl collect`` arguments)."""

    policy: str = "ckpt:base"  # collecting policy: a checkpoint reference, random or oracle[:NOISE]
    seed: int = 5  # collection seed
    epsilon: float = 0.1  # chance of a random action per step (exploration)
    batch: int = 8  # environments per worker in lock-step (does not change the data)


@dataclass(frozen=True)
class Task:
    shift: str  # the task: 'base' or a shift spec; names the task everywhere
    checkpoint: str  # a catalogued checkpoint that has learned the task (the source of its fine-tunes)
    data: str  # the task's target data: a dataset name
    episodes: int  # the first K episodes of it are used (a tier)
    collect: TaskCollect | None = None  # collect the data when missing (None: it must exist)


@dataclass(frozen=True)
class TransferPlan:
    name: str
    study: str  # the study whose base checkpoint and base-task data mix every run uses
    tasks: tuple[Task, ...] = ()
    steps: int = 300  # gradient steps of every run (fine-tune and scratch)
    every: int = 100  # steps between points of the success curve (step 0 included); must divide steps
    eval_episodes: int = 30  # test-object scenes per point
    eval_seed: int = 2000  # scene seed: every point of every run is evaluated on the same scenes
    seeds: tuple[int, ...] = (0,)  # training seeds; advantages are paired by seed
    checkpoint_every: int = 100  # a killed run resumes from its last checkpoint
    auc_floor: float | None = None  # scratch AUCs below this are raised to it; None: 1 / eval_episodes
    proxy_episodes: int = 100  # target episodes the offline proxy scores each source checkpoint on
    source: str = ""  # where the plan was read from (not part of its identity)

    @property
    def floor(self) -> float:
        return self.auc_floor if self.auc_floor is not None else 1.0 / self.eval_episodes

    @property
    def task_names(self) -> tuple[str, ...]:
        return tuple(t.shift for t in self.tasks)

    def task(self, name: str) -> Task:
        for t in self.tasks:
            if t.shift == name:
                return t
        raise UnknownReferenceError(
            f"task {name!r} is not in transfer plan {self.name!r}; its tasks: {', '.join(self.task_names)}"
        )

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("source")
        return d


def _build(cls: type, d: Any, where: str):
    """``cls(**d)`` with one-line errors for a non-table, unknown settings and missing ones."""
    if not isinstance(d, dict):
        raise ConfigError(f"transfer plan [{where}] must be a table of settings; got {d!r}")
    known = [f.name for f in fields(cls) if f.name != "source"]
    unknown = sorted(set(d) - set(known))
    if unknown:
        raise ConfigError(f"transfer plan [{where}] has unknown setting(s) {unknown}; known: {sorted(known)}")
    missing = [f.name for f in fields(cls) if f.name not in d and f.default is MISSING and f.default_factory is MISSING]
    if missing:
        raise ConfigError(f"transfer plan [{where}] lacks {missing}; see study/plans/transfer-small.toml")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


def _task(d: Any, i: int) -> Task:
    where = f"tasks[{i}]"
    if isinstance(d, dict) and "collect" in d:  # plan.json writes null for "no recipe"
        d = {**d, "collect": None if d["collect"] is None else _build(TaskCollect, d["collect"], f"{where}.collect")}
    return _build(Task, d, where)


def parse_transfer_plan(data: dict[str, Any], source: str = "", default_name: str = "transfer") -> TransferPlan:
    """A validated :class:`TransferPlan` from parsed TOML (raises one ConfigError / UnknownReferenceError)."""
    raw = data.get("tasks")
    if not isinstance(raw, (list, tuple)) or not raw:
        raise ConfigError(
            "transfer plan has no [[tasks]]; list at least two, each with shift, checkpoint, data and "
            "episodes (see study/plans/transfer-small.toml)"
        )
    tasks = tuple(_task(t, i) for i, t in enumerate(raw))
    top = {k: v for k, v in data.items() if k != "tasks"}
    top.setdefault("name", default_name)
    plan = _build(TransferPlan, top, "top level")
    plan = replace(plan, tasks=tasks, source=source)
    return validate_transfer(plan)


def _name(value: Any, what: str) -> None:
    if not isinstance(value, str) or not value or not value.replace("-", "").replace("_", "").isalnum():
        raise ConfigError(f"transfer plan {what} = {value!r} must use letters, digits, '-' and '_'")


def validate_transfer(plan: TransferPlan) -> TransferPlan:
    """Every check that needs no workspace; returns the plan with each task's shift in canonical form."""
    _name(plan.name, "name")
    _name(plan.study, "study")
    if len(plan.tasks) < 2:
        raise ConfigError(f"transfer plan lists {len(plan.tasks)} task; transfer needs at least two")
    tasks = []
    for i, t in enumerate(plan.tasks):
        shift = _shift(t.shift, f"tasks[{i}].shift") if t.shift != "base" else "base"
        if not isinstance(t.checkpoint, str) or not t.checkpoint.startswith("ckpt:"):
            raise ConfigError(
                f"transfer plan tasks[{i}] ({shift}) checkpoint = {t.checkpoint!r} must be a checkpoint "
                "reference such as 'ckpt:base'"
            )
        if not isinstance(t.data, str) or not t.data or any(c in t.data for c in ":@/ "):
            raise ConfigError(
                f"transfer plan tasks[{i}] ({shift}) data = {t.data!r} must be a dataset name (no tier "
                "or version: give the number of episodes as episodes = K)"
            )
        _positive(t.episodes, f"tasks[{i}].episodes")
        c = t.collect
        if c is not None:
            if not isinstance(c.policy, str) or not c.policy:
                raise ConfigError(f"transfer plan tasks[{i}].collect.policy = {c.policy!r} must name a policy")
            if not isinstance(c.seed, int) or c.seed < 0:
                raise ConfigError(f"transfer plan tasks[{i}].collect.seed = {c.seed!r} must be >= 0")
            if not isinstance(c.epsilon, (int, float)) or not 0.0 <= c.epsilon <= 1.0:
                raise ConfigError(f"transfer plan tasks[{i}].collect.epsilon = {c.epsilon!r} must be in [0, 1]")
            _positive(c.batch, f"tasks[{i}].collect.batch")
        tasks.append(Task(shift, t.checkpoint, t.data, t.episodes, c))
    names = [t.shift for t in tasks]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ConfigError(f"transfer plan tasks repeat the shift {dup[0]!r}; each task is one shift, listed once")
    for k in ("steps", "every", "eval_episodes", "checkpoint_every", "proxy_episodes"):
        _positive(getattr(plan, k), k)
    if plan.steps % plan.every:
        raise ConfigError(
            f"transfer plan every = {plan.every} must divide steps = {plan.steps} (the curve ends at the last step)"
        )
    if not isinstance(plan.eval_seed, int) or isinstance(plan.eval_seed, bool) or plan.eval_seed < 0:
        raise ConfigError(f"transfer plan eval_seed = {plan.eval_seed!r} must be a whole number >= 0")
    _seeds(plan.seeds, "seeds")
    if plan.auc_floor is not None and not (isinstance(plan.auc_floor, (int, float)) and 0 < plan.auc_floor <= 1):
        raise ConfigError(
            f"transfer plan auc_floor = {plan.auc_floor!r} must be in (0, 1], or left out (1 / eval_episodes)"
        )
    return replace(plan, tasks=tuple(tasks))


def load_transfer_plan(ref: str) -> TransferPlan:
    """A shipped transfer plan by name (``tiny``, ``small``) or a TOML file path."""
    data, source, default_name = read_plan_toml(ref, SHIPPED_TRANSFER, "transfer plan", prefix="transfer-")
    return parse_transfer_plan(data, source=source, default_name=default_name)


# --- units ----------------------------------------------------------------------------------------------------------


def ft_tag(plan: TransferPlan, src: str, dst: str, seed: int) -> str:
    return f"ft-{slug(src)}-to-{slug(dst)}-n{plan.task(dst).episodes}-k{plan.steps}-s{seed}"


def scratch_tag(plan: TransferPlan, dst: str, seed: int) -> str:
    return f"scratch-{slug(dst)}-n{plan.task(dst).episodes}-k{plan.steps}-s{seed}"


def build_transfer_units(plan: TransferPlan, base_ref: str, base: list[BaseSource], ft_lr: float) -> dict[str, Unit]:
    """Every unit of the transfer plan, by name (``base_ref``: the study's base; ``ft_lr``: its fine-tuning lr)."""
    units = {u.name: u for u in base_data_units(base)}
    base_deps = tuple(units)
    data_unit: dict[str, str | None] = {}
    for t in plan.tasks:
        data_unit[t.shift] = None
        if t.collect is not None:
            u = Unit(
                f"data:{t.data}",
                "collect",
                {
                    "dataset": t.data,
                    "shift": t.shift,
                    "policy": t.collect.policy,
                    "policy_ref": t.collect.policy,
                    "episodes": t.episodes,
                    "seed": t.collect.seed,
                    "epsilon": t.collect.epsilon,
                    "batch": t.collect.batch,
                },
            )
            units[u.name] = u
            data_unit[t.shift] = u.name
    monitor = {
        "every": plan.every,
        "episodes": plan.eval_episodes,
        "base_episodes": 0,
        "seed": plan.eval_seed,
        "holdout": None,
    }

    def train(tag: str, dst: Task, method: str, init_ref: str, lr: float | None) -> None:
        deps = (*base_deps, *([data_unit[dst.shift]] if data_unit[dst.shift] else []))
        check_name("checkpoint", f"{plan.name}-{tag}")  # refused before any unit runs (a shorter name fits)
        params = {
            "checkpoint": f"{plan.name}-{tag}",
            "shift": dst.shift,
            "method": method,
            "init": None,
            "init_ref": init_ref,
            "steps": plan.steps,
            "seed": seed,
            "base": base_mix(base),
            "target": {"collect": data_unit[dst.shift], "dataset": dst.data, "tier": dst.episodes, "weight": 0.5},
            "checkpoint_every": plan.checkpoint_every,
            "monitor": dict(monitor),
        }
        if lr is not None:
            params["lr"] = lr
        units[f"train:{tag}"] = Unit(f"train:{tag}", "train", params, deps)

    for seed in plan.seeds:
        for dst in plan.tasks:
            train(scratch_tag(plan, dst.shift, seed), dst, "scratch", base_ref, None)
            for src in plan.tasks:
                if src.shift != dst.shift:
                    train(ft_tag(plan, src.shift, dst.shift, seed), dst, "ft", src.checkpoint, ft_lr)
    return units
