"""A study plan: the TOML file that names every experiment of the study, parsed and checked up front.

A plan is plain data (frozen dataclasses).  :func:`load_plan` reads a TOML
file or a shipped plan name (``tiny``, ``small``, ``full``, ``paper``) and
checks everything that needs no workspace: known shifts, methods and
criteria, tiers within the collection size, positive counts.  What needs the
workspace (the base checkpoint and its data) is checked when the unit graph is
built (:mod:`nsl.study.units`), still before any unit runs.  Every problem is
one ``nsl.errors`` exception, raised before any work starts.

Sections (see ``study/plans/small.toml`` for a commented example)::

    name, base, shifts                 the study's name, base checkpoint, challenge shifts
    learner, precision, device         how every training unit learns (default qtopt, fp32, auto: a GPU if any)
    [base_data]                        base-task data: the checkpoint's own (hash-checked) or listed here
    [collect]                          target data: episodes per shift, exploration epsilon, seed
    [eval]                             evaluation episodes and scene seed (every table)
    [finetune]                         Table 5.2: tiers, steps, seeds, baselines at the top tier
    [continual]                        Table 5.3: the sequence, episodes and steps per stage
    [curves]                           Figs. 5.4/5.9: methods on one shift, success over steps, seeds
    [early_stop]                       Fig. 5.7: shifts trained past their best point (seeds, extra runs); criteria
    [online]                           Figs. 5.10/5.11: online fine-tuning in rounds, round 1's method, ratios
    [supervised]                       Table 5.2's ImageNet column: the supervised features the baselines
                                       ``supervised`` and ``supervised_frozen`` fine-tune (nsl features)
"""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, field, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, UnknownReferenceError, unknown
from nsl.learners.config import FINE_TUNE_STEPS, TrainConfig
from nsl.scenes import REPORTING_SCENES, SELECTION_SCENES
from nsl.services.options import FeaturesConfig

SHIPPED = (
    "tiny",
    "small",
    "full",
    "full-seeds",
    "full-sequence",
    "headline",
    "cross-engine",
    "early-stop",
    "supervised",
    "plasticity",
    "efficiency",
    "online",
    "paper",
)
BASE_DATA_SOURCES = ("checkpoint", "plan")
# Baselines that are not a fine-tuning method of their own: what each one leaves out separates a cause of the gain.
#   scratch_target  random initialisation, trained on the target data alone (no base half)
#   no_target       the base fine-tuned with the same recipe and steps on the base data alone (no target data)
#   supervised      supervised features ([supervised], nsl features) with a fresh head, fine-tuned like the others
#   supervised_frozen  the same with the features frozen: only the head learns (Table 5.2's ImageNet column)
STUDY_BASELINES = ("scratch_target", "no_target", "supervised", "supervised_frozen")
SUPERVISED_BASELINES = {"supervised": "new_head", "supervised_frozen": "new_head_frozen"}  # baseline -> method


@dataclass(frozen=True)
class BaseDataset:
    """One base-task dataset and the recipe that collects it (``nsl collect`` arguments)."""

    name: str  # dataset name in the workspace
    policy: str  # collecting policy: random, oracle[:NOISE]
    seed: int  # collection seed (episode i is a pure function of (seed, i))
    episodes: int  # episodes the dataset holds
    shift: str = "base"
    weight: float = (
        1.0  # share within the base half of each batch (source "plan"; "checkpoint" uses the recorded weights)
    )


@dataclass(frozen=True)
class BaseData:
    source: str = (
        "checkpoint"  # "checkpoint": the base checkpoint's own pre-training data, hash-checked; "plan": datasets below
    )
    datasets: tuple[BaseDataset, ...] = ()  # recipes (source "checkpoint": to collect a missing recorded dataset again)
    verify: bool = True  # the data must have the hashes the base checkpoint records for it (source "plan": the
    # datasets whose name and size the checkpoint records, e.g. the scripted data it was pre-trained on)


@dataclass(frozen=True)
class Collect:
    episodes: int = 800  # target episodes the base policy collects per shift; tiers are its first-K views
    epsilon: float = 0.1  # probability of a random action per step while collecting (exploration)
    seed: int = 5  # collection seed of every target collection
    batch: int = 8  # environments per worker in lock-step (does not change the data)


@dataclass(frozen=True)
class Eval:
    episodes: int = 50  # test-object episodes per (checkpoint, task); every table uses these
    seed: int = REPORTING_SCENES  # reporting scenes: every table's evaluations are paired on them
    selection_seed: int = SELECTION_SCENES  # selection scenes: every choice (the early-stopping curve's criteria)


@dataclass(frozen=True)
class Finetune:
    tiers: tuple[int, ...] = (25, 50, 100, 200, 400, 800)  # target episodes, nested first-K views
    steps: int = FINE_TUNE_STEPS  # gradient steps per fine-tuning run (the fine-tuning recipe's)
    seeds: tuple[int, ...] = (0,)  # training seeds of the top tier and the baselines (mean over seeds, and pooled)
    tier_seeds: tuple[int, ...] | None = None  # training seeds of the lower tiers (None: the same as seeds)
    baseline_seeds: tuple[int, ...] | None = None  # training seeds of the baselines (None: the same as seeds)
    collections: tuple[int, ...] | None = None  # the top tier's independent target collections, by collection seed
    # (None: collect.seed's alone); each trains every seed of the top tier, so its interval covers the data's
    # variation as well as the seeds' and the scenes' (nsl.stats.hierarchical_gain)
    baselines: tuple[str, ...] = ("scratch", "new_head")  # trained at the top tier: methods, or STUDY_BASELINES
    cross_shift: bool = False  # evaluate the top tier's fine-tunes on every other shift too (forgetting of shifts)
    base_task: bool = False  # also fine-tune on base-task episodes the base collects (Table 5.2's validation row),
    # the measure of where the weights change (Fig. 5.8)

    def seeds_of(self, tier: int) -> tuple[int, ...]:
        """The training seeds of a tier."""
        return self.seeds if tier == self.tiers[-1] or self.tier_seeds is None else self.tier_seeds

    def seeds_of_baselines(self) -> tuple[int, ...]:
        """The training seeds of the baselines."""
        return self.seeds if self.baseline_seeds is None else self.baseline_seeds

    def collections_of(self, collect_seed: int) -> tuple[int, ...]:
        """The top tier's target collections by collection seed; the plan's collection (``collect_seed``) first."""
        more = () if self.collections is None else tuple(c for c in self.collections if c != collect_seed)
        return (collect_seed, *more)


@dataclass(frozen=True)
class Continual:
    sequence: tuple[str, ...] = (
        "harsh_lighting",
        "transparent_objects",
        "checkerboard_backing",
        "extend_gripper",
        "offset_gripper",
    )
    episodes: int = 800  # episodes each stage's policy collects in its shift
    steps: int = FINE_TUNE_STEPS  # gradient steps per stage (the fine-tuning recipe's)
    seeds: tuple[int, ...] = (0,)  # training seeds: one whole sequence each (a plan's ``seed = S`` is ``seeds = [S]``)


@dataclass(frozen=True)
class Curves:
    shift: str = "transparent_objects"
    episodes: int = 75  # target episodes (a tier of the shift's collection)
    methods: tuple[str, ...] = ("ft", "pnn", "ft_pnn", "scratch")
    steps: int = 1000
    every: int = 250  # gradient steps between evaluations on the curve
    eval_episodes: int = 30  # episodes per point, on the target shift and on the base task
    seeds: tuple[int, ...] = (0, 1, 2)


@dataclass(frozen=True)
class EarlyStopRun:
    """One more long fine-tune of [early_stop] (``[[early_stop.runs]]``): a shift at a tier, with the plan's base
    data or only the base datasets it names (e.g. the README quick start's oracle episodes)."""

    shift: str
    episodes: int
    base: tuple[str, ...] = ()  # names from [[base_data.datasets]]; empty: all of them, as every other unit


@dataclass(frozen=True)
class EarlyStop:
    """Fig. 5.7: fine-tunes trained far past their best point, evaluated every ``every`` steps on the selection
    scenes of their shift and of the base task, each evaluated checkpoint kept; criteria choose on the curves."""

    shift: str = "offset_gripper"
    episodes: int = 400  # target episodes (a tier of the shift's collection); holdout is taken from them
    steps: int = 3000  # far past the best point
    every: int = 250
    eval_episodes: int = 30  # episodes per point, target and base
    criteria: tuple[str, ...] = ("eval", "softopc", "auc", "td")
    patience: int = 4  # evaluations without improvement before a criterion stops (replayed on the full curve)
    holdout: float = 0.2  # fraction of the target episodes held out for the offline criteria
    seed: int = 0
    shifts: tuple[str, ...] = ()  # several shifts at `episodes` (empty: `shift` alone); the first is the report's
    seeds: tuple[int, ...] = ()  # training seeds of every run (empty: `seed` alone)
    runs: tuple[EarlyStopRun, ...] = ()  # more runs, each with every seed

    @property
    def all_shifts(self) -> tuple[str, ...]:
        return self.shifts or (self.shift,)

    @property
    def all_seeds(self) -> tuple[int, ...]:
        return self.seeds or (self.seed,)


@dataclass(frozen=True)
class Online:
    """Online fine-tuning in rounds (Sec. 5.10.2): the policy keeps collecting in the target shift, and each round
    fine-tunes the last round's policy on every round's data so far, mixed with base data (``nsl online``)."""

    shift: str = "transparent_objects"
    rounds: int = 6  # rounds of collection and fine-tuning
    episodes: int = 800  # grasps per round (round 1's are the base policy's collection: at most collect.episodes)
    steps: int = FINE_TUNE_STEPS  # gradient steps per round (the fine-tuning recipe's)
    ratio: float = 0.5  # target data's share of each batch in Fig. 5.10's runs
    methods: tuple[str, ...] = ("ft", "new_head")  # round 1's method (Fig. 5.10); later rounds continue with ft
    ratios: tuple[float, ...] = (0.01, 0.24, 0.44, 0.71, 0.99)  # Fig. 5.11: target shares, with ft
    seed: int = 0  # training seed of every round


@dataclass(frozen=True)
class Supervised:
    """The supervised features (``nsl features``): the trunk of the base's architecture trained on rendered frames of
    the train objects (the project's ImageNet) to classify them or to locate them, or a torchvision ResNet from a
    file."""

    label: str = FeaturesConfig.label  # what the trunk learns: classes, pose (relative to the camera) or both
    classes: int = FeaturesConfig.classes  # train objects to tell apart (0: all 899)
    frames: int = FeaturesConfig.frames  # rendered frames per object
    steps: int = FeaturesConfig.steps  # classifier gradient steps
    seed: int = FeaturesConfig.seed
    encoder: str | None = None  # a torchvision ResNet state dict on disk instead (e.g. ImageNet weights)


@dataclass(frozen=True)
class Plasticity:
    """Plasticity or data (finding (d)): why the continual sequence's late stage learns its shift less than a
    single step does.  A 2x2 on ``shift``: start from {the base, the continual sequence's stage ``stage`` policy
    (its first seed)} and fine-tune on {the base's ``episodes`` episodes of the shift, that policy's own}, each with
    every seed; plus shrink and perturb of the stage's policy (``alpha`` * its weights + ``sigma`` * a fresh
    initialisation; empty: none) on the base's episodes."""

    shift: str = "offset_gripper@0.25"
    stage: int = 4  # the continual stage whose policy is the second start and the second collector
    episodes: int = 800
    steps: int = FINE_TUNE_STEPS
    seeds: tuple[int, ...] = (0, 1, 2)
    shrink_perturb: tuple[float, ...] = (0.8, 0.01)  # (alpha, sigma); () leaves the arm out


EFFICIENCY_METHODS = ("ft", "scratch", "scratch_target")


@dataclass(frozen=True)
class Efficiency:
    """Target data needed from scratch (finding (c)): at every tier of each shift's collection (the plan's
    [collect] episodes, by the base; tiers are first-K views), FT from the base (``ft_steps``), scratch with the
    recipe's base half and scratch on the target data alone (``scratch_steps``, longer), each with every seed, on
    the reporting scenes.  Scratch keeps a curve on ``curve_episodes`` selection scenes every ``curve_every`` steps
    (0: none), so the report can say whether it had stopped improving by its last step."""

    shifts: tuple[str, ...] = ("harsh_lighting@2", "offset_gripper@0.25")
    tiers: tuple[int, ...] = (25, 100, 400, 800, 1600, 3200)
    methods: tuple[str, ...] = EFFICIENCY_METHODS
    seeds: tuple[int, ...] = (0, 1, 2)
    ft_steps: int = FINE_TUNE_STEPS
    scratch_steps: int = 8000
    curve_every: int = 2000
    curve_episodes: int = 200
    reference: int = 800  # the FT tier that scratch is measured against


@dataclass(frozen=True)
class Plan:
    name: str  # default study name (folder $NSL_HOME/studies/NAME)
    base: str = "ckpt:base"  # the base checkpoint
    shifts: tuple[str, ...] = (
        "harsh_lighting",
        "transparent_objects",
        "checkerboard_backing",
        "extend_gripper",
        "offset_gripper",
    )  # the challenge shifts (Tables 5.1 and 5.2)
    checkpoint_every: int = 500  # a killed training resumes from its last checkpoint
    precision: str = (
        TrainConfig.precision
    )  # training units' arithmetic: fp32, bf16 (CPU bfloat16 autocast) or auto (bf16 if the CPU
    # has it); evaluations and collections act in fp32, which is faster for CEM's one-state searches on the CPU
    device: str = "auto"  # training units' device: cpu, cuda, or auto (cuda on a node whose torch sees a GPU);
    # collections and evaluations act on the CPU cores
    learner: str = (
        TrainConfig.learner
    )  # every training unit's learner (nsl train --learner): qtopt, iql[:OPTS] or a plugin's
    base_data: BaseData = field(default_factory=BaseData)
    collect: Collect = field(default_factory=Collect)
    eval: Eval = field(default_factory=Eval)
    finetune: Finetune = field(default_factory=Finetune)
    continual: Continual | None = field(default_factory=Continual)
    curves: Curves | None = field(default_factory=Curves)
    early_stop: EarlyStop | None = field(default_factory=EarlyStop)
    supervised: Supervised | None = None  # set when a supervised baseline is asked for (defaults if not given)
    online: Online | None = None  # online fine-tuning in rounds (off unless the plan has [online])
    plasticity: Plasticity | None = None  # plasticity or data, a 2x2 (off unless the plan has [plasticity])
    efficiency: Efficiency | None = None  # target data needed from scratch (off unless the plan has [efficiency])
    source: str = ""  # where the plan was read from (not part of its identity)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("source")
        for key in ("supervised", "online", "plasticity", "efficiency"):
            if d[key] is None:
                del d[key]  # an absent section: plans made before it keep their record
        return d


SECTIONS = {
    "base_data": BaseData,
    "collect": Collect,
    "eval": Eval,
    "finetune": Finetune,
    "continual": Continual,
    "curves": Curves,
    "early_stop": EarlyStop,
    "supervised": Supervised,
    "online": Online,
    "plasticity": Plasticity,
    "efficiency": Efficiency,
}


def _build(cls: type, d: Any, where: str):
    if not isinstance(d, dict):
        raise ConfigError(f"plan [{where}] must be a table of settings; got {d!r}")
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(set(d) - set(known))
    if unknown:
        raise ConfigError(f"plan [{where}] has unknown setting(s) {unknown}; known: {sorted(known)}")
    out = {}
    for k, v in d.items():
        if k == "datasets" and cls is BaseData:
            if not isinstance(v, list):
                raise ConfigError(f"plan [{where}] datasets must be an array of tables ([[base_data.datasets]])")
            v = tuple(_build(BaseDataset, x, f"{where}.datasets") for x in v)
        elif k == "runs" and cls is EarlyStop:
            if not isinstance(v, list):
                raise ConfigError(f"plan [{where}] runs must be an array of tables ([[early_stop.runs]])")
            v = tuple(_build(EarlyStopRun, x, f"{where}.runs") for x in v)
        elif isinstance(v, list):
            v = tuple(v)
        out[k] = v
    try:
        return cls(**out)
    except TypeError as e:  # a required field is missing
        raise ConfigError(f"plan [{where}]: {e}; see study/plans/small.toml for a complete plan") from None


OPTIONAL_SECTIONS = ("continual", "curves", "early_stop", "online", "plasticity", "efficiency")  # `= false`: off


def parse_plan(data: dict[str, Any], source: str = "", default_name: str = "study") -> Plan:
    """A :class:`Plan` from parsed TOML, validated (raises ConfigError / UnknownReferenceError)."""
    top = {k: v for k, v in data.items() if k not in SECTIONS}
    sections = {}
    for key, cls in SECTIONS.items():
        if key not in data:
            continue
        if data[key] in (False, None) and key in OPTIONAL_SECTIONS:
            sections[key] = None  # `continual = false` switches an experiment off
            continue
        table = data[key]
        if key == "continual" and isinstance(table, dict) and "seed" in table:
            if "seeds" in table:
                raise ConfigError("plan [continual] sets both seed and seeds; keep seeds = [...]")
            table = {**{k: v for k, v in table.items() if k != "seed"}, "seeds": [table["seed"]]}
        sections[key] = _build(cls, table, key)
    top.setdefault("name", default_name)
    plan = _build(Plan, {**top}, "plan")
    baselines = sections["finetune"].baselines if "finetune" in sections else plan.finetune.baselines
    if "supervised" not in sections and set(baselines) & set(SUPERVISED_BASELINES):
        sections["supervised"] = Supervised()
    plan = replace(plan, **sections, source=source)
    validate(plan)
    return plan


def read_plan_toml(
    ref: str, shipped: tuple[str, ...] | list[str], what: str = "plan", prefix: str = ""
) -> tuple[dict[str, Any], str, str]:
    """(parsed TOML, source, default name) of a shipped plan ``plans/PREFIX+REF.toml`` or a TOML file path."""
    path = Path(ref)
    if ref in shipped and not path.is_file():
        text = resources.files("nsl.study").joinpath("plans", f"{prefix}{ref}.toml").read_text()
        source, default_name = f"shipped {what} {ref!r}", f"{prefix}{ref}"
    elif path.is_file():
        text, source, default_name = path.read_text(), str(path), path.stem
    else:
        raise UnknownReferenceError(
            f"{what} {ref!r} is neither a file nor a shipped plan; use one of "
            f"{', '.join(shipped)} or a path to a TOML plan"
        )
    try:
        return tomllib.loads(text), source, default_name
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{what} {source} is not valid TOML: {e}") from None


def load_plan(ref: str) -> Plan:
    """A shipped plan by name (``tiny``, ``small``, ``full``, ``paper``) or a TOML file path."""
    data, source, default_name = read_plan_toml(ref, SHIPPED)
    return parse_plan(data, source=source, default_name=default_name)


def plan_header(ref: str) -> str:
    """The comment lines at the top of a shipped plan (its description and cost estimate)."""
    text = resources.files("nsl.study").joinpath("plans", f"{ref}.toml").read_text()
    lines = []
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("# ").rstrip())
    return "\n".join(lines)


# --- validation -------------------------------------------------------------------------------------------------------


def _positive(value: Any, what: str) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise ConfigError(f"plan {what} = {value!r} must be a whole number of at least 1")


def _seeds(values: tuple, what: str) -> None:
    if not values or any(not isinstance(s, int) or s < 0 for s in values) or len(set(values)) != len(values):
        raise ConfigError(f"plan {what} = {list(values)!r} must be a non-empty list of distinct seeds >= 0")


def _shift(name: str, what: str) -> str:
    from nsl.collectors import parse_shift

    if not isinstance(name, str):
        raise ConfigError(f"plan {what} = {name!r} must be a shift name")
    try:
        spec = parse_shift(name)
    except UnknownReferenceError as e:  # it names the shift and the closest known ones; add where it is
        raise UnknownReferenceError(f"plan {what}: {e}") from None
    if what != "base_data.datasets.shift" and not spec.shifts and spec.engine == "mujoco":
        raise ConfigError(
            f"plan {what} = 'base': the base task is evaluated everywhere already; name a shift (or engine:pybullet)"
        )
    return spec.name


def _method(name: str, what: str, also: tuple[str, ...] = ()) -> None:
    from nsl.learners import METHODS

    if name not in METHODS:
        raise unknown("method", name, (*METHODS, *also), f"(plan {what})")


def validate(plan: Plan) -> None:
    """Every check that needs no workspace; raises one ConfigError/UnknownReferenceError."""
    from nsl.errors import unknown
    from nsl.eval import CRITERIA

    if not isinstance(plan.name, str) or not plan.name.replace("-", "").replace("_", "").isalnum():
        raise ConfigError(f"plan name {plan.name!r} must use letters, digits, '-' and '_' (it names datasets and runs)")
    if not str(plan.base).startswith("ckpt:"):
        raise ConfigError(f"plan base = {plan.base!r} must be a checkpoint reference such as 'ckpt:base'")
    if not plan.shifts:
        raise ConfigError("plan shifts is empty; name at least one challenge shift, e.g. ['harsh_lighting']")
    names = [_shift(s, "shifts") for s in plan.shifts]
    if len(set(names)) != len(names):
        raise ConfigError(f"plan shifts {list(plan.shifts)} repeat a shift")
    _positive(plan.checkpoint_every, "checkpoint_every")
    from nsl.services.options import DEVICES, PRECISIONS

    if plan.precision not in PRECISIONS:
        raise ConfigError(f"plan precision = {plan.precision!r} is unknown; use one of {', '.join(PRECISIONS)}")
    if plan.device not in DEVICES:
        raise ConfigError(f"plan device = {plan.device!r} is unknown; use one of {', '.join(DEVICES)}")
    from nsl.learners.registry import learner_names, parse_learner

    learner, _ = parse_learner(str(plan.learner))
    if learner not in learner_names():
        raise unknown("learner", learner, learner_names(), "(plan learner; a plugin's comes from nsl.learners)")
    bd = plan.base_data
    if bd.source not in BASE_DATA_SOURCES:
        raise ConfigError(f"plan base_data.source = {bd.source!r}; use 'checkpoint' (the base's own data) or 'plan'")
    if not isinstance(bd.verify, bool):
        raise ConfigError(f"plan base_data.verify = {bd.verify!r} must be true or false")
    if bd.source == "plan" and not bd.datasets:
        raise ConfigError("plan base_data.source = 'plan' lists no [[base_data.datasets]]; add at least one")
    for d in bd.datasets:
        _positive(d.episodes, f"base_data.datasets {d.name!r} episodes")
        _shift(d.shift, "base_data.datasets.shift")
        if not isinstance(d.seed, int) or d.seed < 0:
            raise ConfigError(f"plan base_data.datasets {d.name!r} seed = {d.seed!r} must be >= 0")
        if not d.weight > 0:
            raise ConfigError(f"plan base_data.datasets {d.name!r} weight = {d.weight!r} must be positive")
        if d.policy.startswith("ckpt:"):
            raise ConfigError(
                f"plan base_data.datasets {d.name!r}: policy {d.policy!r} must be scripted "
                "(random or oracle[:NOISE]); base data does not depend on a checkpoint"
            )
    if len({d.name for d in bd.datasets}) != len(bd.datasets):
        raise ConfigError("plan [[base_data.datasets]] repeat a dataset name")
    c = plan.collect
    _positive(c.episodes, "collect.episodes")
    _positive(c.batch, "collect.batch")
    if not 0.0 <= c.epsilon <= 1.0:
        raise ConfigError(f"plan collect.epsilon = {c.epsilon!r} must be in [0, 1]")
    _positive(plan.eval.episodes, "eval.episodes")
    e = plan.eval
    for k in ("seed", "selection_seed"):
        if not isinstance(getattr(e, k), int) or getattr(e, k) < 0:
            raise ConfigError(f"plan eval.{k} = {getattr(e, k)!r} must be a scene seed >= 0")
    if e.seed == e.selection_seed:
        raise ConfigError(
            f"plan eval.seed and eval.selection_seed are both {e.seed}: the same scenes would choose and report; "
            "give the reporting scenes another seed"
        )
    f = plan.finetune
    if not f.tiers or list(f.tiers) != sorted(set(f.tiers)):
        raise ConfigError(f"plan finetune.tiers = {list(f.tiers)!r} must be increasing episode counts")
    for k in f.tiers:
        _positive(k, "finetune.tiers")
    if f.tiers[-1] > c.episodes:
        raise ConfigError(
            f"plan finetune.tiers has tier {f.tiers[-1]} above the collection size collect.episodes = "
            f"{c.episodes}; raise collect.episodes or drop the tier"
        )
    _positive(f.steps, "finetune.steps")
    _seeds(f.seeds, "finetune.seeds")
    if f.tier_seeds is not None:
        _seeds(f.tier_seeds, "finetune.tier_seeds")
    if f.baseline_seeds is not None:
        _seeds(f.baseline_seeds, "finetune.baseline_seeds")
    if f.collections is not None:
        _seeds(f.collections, "finetune.collections")
        if c.seed not in f.collections:
            raise ConfigError(
                f"plan finetune.collections = {list(f.collections)!r} leaves out collect.seed = {c.seed}: the lower "
                "tiers and the baselines use that collection; list it first"
            )
    if not isinstance(f.cross_shift, bool):
        raise ConfigError(f"plan finetune.cross_shift = {f.cross_shift!r} must be true or false")
    for m in f.baselines:
        if m not in STUDY_BASELINES:
            _method(m, "finetune.baselines", STUDY_BASELINES)
    if len(set(f.baselines)) != len(f.baselines):
        raise ConfigError(f"plan finetune.baselines = {list(f.baselines)!r} repeats a baseline")
    if plan.online is not None:
        o = plan.online
        _shift(o.shift, "online.shift")
        for k in ("rounds", "episodes", "steps"):
            _positive(getattr(o, k), f"online.{k}")
        if o.episodes > c.episodes:
            raise ConfigError(
                f"plan online.episodes = {o.episodes} is above the collection size collect.episodes = {c.episodes} "
                "(round 1 trains on the base policy's collection)"
            )
        for m in o.methods:
            if m not in ("ft", "new_head"):
                raise ConfigError(f"plan online.methods has {m!r}; online rounds start with ft or new_head")
        for r in (o.ratio, *o.ratios):
            if not isinstance(r, (int, float)) or not 0 < r <= 1:
                raise ConfigError(f"plan online ratio {r!r} is the target data's share of each batch; use (0, 1]")
        if not o.methods and not o.ratios:
            raise ConfigError("plan [online] has no methods and no ratios; name at least one run")
        if not isinstance(o.seed, int) or o.seed < 0:
            raise ConfigError(f"plan online.seed = {o.seed!r} must be a seed >= 0")
    if plan.plasticity is not None:
        pl = plan.plasticity
        _shift(pl.shift, "plasticity.shift")
        for k in ("stage", "episodes", "steps"):
            _positive(getattr(pl, k), f"plasticity.{k}")
        _seeds(pl.seeds, "plasticity.seeds")
        stages = 0 if plan.continual is None else len(plan.continual.sequence)
        if pl.stage > stages:
            raise ConfigError(
                f"plan plasticity.stage = {pl.stage} needs a continual sequence of at least {pl.stage} stages; "
                f"this plan's has {stages} (set [continual] sequence)"
            )
        if pl.episodes > c.episodes:
            raise ConfigError(
                f"plan plasticity.episodes = {pl.episodes} is above the collection size collect.episodes = {c.episodes}"
            )
        sp = pl.shrink_perturb
        if sp and (len(sp) != 2 or not 0 < sp[0] <= 1 or sp[1] < 0):
            raise ConfigError(
                f"plan plasticity.shrink_perturb = {list(sp)} must be [alpha, sigma] with 0 < alpha <= 1 and "
                "sigma >= 0, or [] for no such arm"
            )
    if plan.efficiency is not None:
        ef = plan.efficiency
        for name in ef.shifts:
            _shift(name, "efficiency.shifts")
        for k in ("ft_steps", "scratch_steps", "curve_episodes", "reference"):
            _positive(getattr(ef, k), f"efficiency.{k}")
        if not isinstance(ef.curve_every, int) or ef.curve_every < 0:
            raise ConfigError(f"plan efficiency.curve_every = {ef.curve_every!r} must be steps >= 0 (0: no curve)")
        _seeds(ef.seeds, "efficiency.seeds")
        if not ef.tiers or list(ef.tiers) != sorted(set(ef.tiers)) or ef.tiers[0] <= 0:
            raise ConfigError(f"plan efficiency.tiers = {list(ef.tiers)} must be increasing episode counts above 0")
        if ef.tiers[-1] > c.episodes:
            raise ConfigError(
                f"plan efficiency.tiers go to {ef.tiers[-1]} episodes, above the collection size collect.episodes = "
                f"{c.episodes}; raise [collect] episodes"
            )
        if ef.reference not in ef.tiers:
            raise ConfigError(f"plan efficiency.reference = {ef.reference} must be one of its tiers {list(ef.tiers)}")
        for m in ef.methods:
            if m not in EFFICIENCY_METHODS:
                raise ConfigError(f"plan efficiency.methods has {m!r}; use {', '.join(EFFICIENCY_METHODS)}")
        if "ft" not in ef.methods:
            raise ConfigError("plan efficiency.methods needs ft: scratch is measured against FT at the reference")
    if plan.supervised is not None:
        sv = plan.supervised
        for k in ("frames", "steps"):
            _positive(getattr(sv, k), f"supervised.{k}")
        if sv.label not in ("classes", "pose", "both"):
            raise ConfigError(f"plan supervised.label = {sv.label!r} is unknown; use classes, pose or both")
        if not isinstance(sv.classes, int) or sv.classes < 0:
            raise ConfigError(f"plan supervised.classes = {sv.classes!r} must be 0 (all train objects) or a count")
        if sv.encoder is not None and not Path(sv.encoder).is_file():
            raise ConfigError(
                f"plan supervised.encoder = {sv.encoder!r} is not a file; give a torchvision ResNet state dict's path"
            )
    if plan.continual is not None:
        s = plan.continual
        seq = [_shift(x, "continual.sequence") for x in s.sequence]
        if not seq or len(set(seq)) != len(seq):
            raise ConfigError(f"plan continual.sequence = {list(s.sequence)!r} must name distinct shifts")
        _positive(s.episodes, "continual.episodes")
        _seeds(s.seeds, "continual.seeds")
        _positive(s.steps, "continual.steps")
        if s.episodes > c.episodes:
            raise ConfigError(
                f"plan continual.episodes = {s.episodes} is above the collection size collect.episodes "
                f"= {c.episodes} (its first stage uses the base policy's collection)"
            )
    if plan.curves is not None:
        cv = plan.curves
        _shift(cv.shift, "curves.shift")
        for m in cv.methods:
            _method(m, "curves.methods")
        if not cv.methods:
            raise ConfigError("plan curves.methods is empty; name at least one method, e.g. ['ft']")
        for k in ("episodes", "steps", "every", "eval_episodes"):
            _positive(getattr(cv, k), f"curves.{k}")
        if cv.episodes > c.episodes:
            raise ConfigError(
                f"plan curves.episodes = {cv.episodes} is above the collection size collect.episodes = {c.episodes}"
            )
        _seeds(cv.seeds, "curves.seeds")
    if plan.early_stop is not None:
        es = plan.early_stop
        _shift(es.shift, "early_stop.shift")
        for s in es.shifts:
            _shift(s, "early_stop.shifts")
        if es.seeds:
            _seeds(es.seeds, "early_stop.seeds")
        for k in ("episodes", "steps", "every", "eval_episodes", "patience"):
            _positive(getattr(es, k), f"early_stop.{k}")
        names = {d.name for d in plan.base_data.datasets}
        for r in es.runs:
            _shift(r.shift, "early_stop.runs.shift")
            _positive(r.episodes, "early_stop.runs.episodes")
            missing = sorted(set(r.base) - names)
            if missing:
                raise ConfigError(
                    f"plan early_stop.runs.base names {missing}, which [[base_data.datasets]] does not list; "
                    f"use some of {sorted(names)} (or none: all of them)"
                )
        for n in (es.episodes, *(r.episodes for r in es.runs)):
            if n > c.episodes:
                raise ConfigError(
                    f"plan early_stop episodes = {n} is above the collection size collect.episodes = {c.episodes}"
                )
        for crit in es.criteria:
            if crit not in CRITERIA:
                raise unknown("stopping criterion", crit, CRITERIA, "(plan early_stop.criteria)")
        if not 0.0 < es.holdout < 1.0 or round(es.holdout * es.episodes) < 2:
            raise ConfigError(
                f"plan early_stop.holdout = {es.holdout!r} must be in (0, 1) and hold out at least 2 "
                f"of the {es.episodes} episodes"
            )
