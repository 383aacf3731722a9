"""Train (pre-train or fine-tune) a Q-function offline and catalogue what it made: the one training path.

``nsl train``, the Python API (``nsl.train``), the study's training units and
the continual and efficiency pipelines all call :func:`train`:

1. resolve the data mix and the parent in the catalog (unknown dataset
   versions on disk are registered first);
2. settle the recipe: a fine-tune keeps its parent's n-step returns and crop
   and takes :data:`~nsl.learners.FINE_TUNE_STEPS` steps unless told;
3. with early stopping, hold out the target's last episodes for the offline
   criteria (:mod:`nsl.services.scoring`) and evaluate in the simulator on the
   selection scenes;
4. train (a killed run resumes from its last checkpoint), then catalogue every
   evaluated step with its evaluations, and the final checkpoint last.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, IncompatibleVersionError

from .options import TrainOptions


@dataclass(frozen=True)
class TrainResult:
    """What a training run wrote: the final checkpoint's catalog ref and id, its folder, and the run folder."""

    checkpoint: str  # ckpt:NAME@STEP of the final checkpoint
    id: str | None  # its catalog id (content hash); None until registered (register=False)
    path: Path  # its folder
    step: int
    run_dir: Path  # $NSL_HOME/runs/NAME (metrics, curve.csv with early stopping)
    best: str | None = None  # with early stopping: ckpt:NAME@STEP of the chosen step (or the parent's ref)
    best_step: int | None = None
    made: TrainingOutput | None = None  # with register=False: what to register (id is None until then)


@dataclass(frozen=True)
class TrainingOutput:
    """What a training run wrote, for the catalog: :func:`register_training` records it (in any process that
    sees the same ``NSL_HOME``; a study on a cluster does it on its driver)."""

    name: str  # the run's name (checkpoints ckpt:NAME@STEP)
    run_dir: Path
    final: Path  # the last checkpoint's folder
    parent: str | None  # the parent checkpoint's catalog id (None: from scratch)
    uses: tuple  # DataUse of every dataset trained on
    shift: str  # the shift it was trained for
    scenes: int | None  # with a curve: the scene seed of its simulator evaluations
    source: str = "early stopping"  # label of the curve's catalogued evaluations


def register_training(made: TrainingOutput):
    """Catalogue a finished run: every evaluated step of its curve with its evaluations, then the final
    checkpoint (returned).  Idempotent."""
    from nsl.catalog import Catalog

    with Catalog() as cat:
        if made.scenes is not None:
            register_evaluated(
                cat, made.name, made.run_dir, made.parent, made.uses, made.shift, made.scenes, made.source
            )
        return register_checkpoint(cat, made.name, made.final, made.parent, made.uses, made.shift)


def parse_data(specs: list[str] | tuple[str, ...]) -> list[tuple[str, float]]:
    """``["grasp-base=0.5", "grasp-harsh:100=0.5"]`` -> ``[(ref, weight)]`` (equal shares when none is given)."""
    out: list[tuple[str, float | None]] = []
    for s in specs:
        ref, sep, w = s.partition("=")
        ref = ref.removeprefix("data:")
        if sep:
            try:
                weight: float | None = float(w)
            except ValueError:
                raise ConfigError(f"--data {s!r}: weight {w!r} is not a number; write e.g. grasp-base=0.5") from None
        else:
            weight = None
        out.append((ref, weight))
    if not out:
        raise ConfigError("no training data; give --data NAME (repeat it for a mix)")
    if any(w is None for _, w in out) and any(w is not None for _, w in out):
        raise ConfigError("--data: give a weight to every dataset or to none (equal shares)")
    return [(r, 1.0 / len(out) if w is None else w) for r, w in out]


def parse_shrink_perturb(spec: str | tuple[float, float] | None, init: str | None) -> tuple[float, float] | None:
    """``"0.8,0.01"`` or ``(0.8, 0.01)`` -> (0.8, 0.01); None stays None."""
    if spec is None:
        return None
    if not init:
        raise ConfigError("--shrink-perturb changes a parent's weights; give --init CKPT as well")
    if isinstance(spec, str):
        try:
            alpha, sigma = (float(v) for v in spec.split(","))
        except ValueError:
            raise ConfigError(f"--shrink-perturb {spec!r}: write ALPHA,SIGMA, e.g. 0.8,0.01") from None
        return alpha, sigma
    alpha, sigma = spec
    return float(alpha), float(sigma)


def parse_net(specs: list[str] | tuple[str, ...]):
    """``["pool=spatial", "hidden=32"]`` -> a NetConfig (None when empty); values take the field's type."""
    if not specs:
        return None
    from nsl.learners import NetConfig

    defaults = {f.name: getattr(NetConfig(), f.name) for f in fields(NetConfig)}
    changes: dict[str, Any] = {}
    for spec in specs:
        key, sep, value = spec.partition("=")
        if not sep or key not in defaults:
            raise ConfigError(f"--net {spec!r}: write FIELD=VALUE with FIELD one of {sorted(defaults)}")
        default = defaults[key]
        try:
            if isinstance(default, tuple):
                kind = type(default[0]) if default else int
                changes[key] = tuple(kind(v) for v in value.split(",") if v.strip())
            elif isinstance(default, bool):
                if value.lower() not in ("true", "false", "1", "0"):
                    raise ValueError(value)
                changes[key] = value.lower() in ("true", "1")
            else:
                changes[key] = type(default)(value)
        except ValueError:
            raise ConfigError(f"--net {spec!r}: {value!r} is not a valid {key} (default {default!r})") from None
    return NetConfig.from_dict({**NetConfig().to_dict(), **changes})


def check_env_version(view) -> None:
    """Refuse data from an older simulator: its pictures and physics differ from what evaluation runs."""
    from nsl.collectors import ENV_VERSION

    for c in view.version.provenance.get("collections", []):
        got = c.get("spec", {}).get("env", {}).get("env_version")
        if got is not None and got != ENV_VERSION:
            raise IncompatibleVersionError(
                f"dataset {view.version.ref} was collected in environment {got}, but this nsl simulates "
                f"{ENV_VERSION} (wrist camera, 7 cm jaw); collect it again, or set NSL_HOME to a new workspace"
            )


def view_shift(view) -> str:
    """The shift a dataset view was collected in (its last collection's), with its engine off MuJoCo
    (``engine:pybullet+harsh_lighting``)."""
    env = view.version.provenance["collections"][-1]["spec"].get("env", {})
    shift, engine = env.get("shift", "base"), env.get("engine", "mujoco")
    if engine == "mujoco":
        return shift  # as recorded (a test's synthetic data names a shift no simulator has)
    from nsl.collectors import parse_shift

    return parse_shift(shift, engine=engine).name


def train(
    options: TrainOptions,
    *,
    progress: bool = True,
    record: Mapping[str, Any] | None = None,
    offline: bool | None = None,
    stop: bool = True,
    source: str = "early stopping",
    quiet: bool = False,
    register: bool = True,
    wait: bool = False,
) -> TrainResult:
    """Train (or resume) run ``options.name`` and catalogue its checkpoints.

    One process writes a run at a time: while another holds the run's writer lock this raises LockedError
    naming it, or with ``wait`` waits for it and then resumes (or finds finished) what it wrote.

    ``record`` adds fields to the run's ``command.json`` (``argv`` replaces
    the process's).  ``offline`` holds out the target's last episodes and
    records the offline criteria at every evaluation (None: when the
    criterion is an offline one).  ``stop=False`` never stops early: the
    curve is recorded to the last step, so each criterion can be replayed on
    it afterwards (the study does).  ``source`` labels the catalogued
    early-stopping evaluations.  ``register=False`` writes nothing to the
    catalog: the result's ``made`` goes to :func:`register_training` later
    (a study unit on a cluster node, registered by its driver).
    """
    from nsl.locks import run_lock

    if not options.name:
        raise ConfigError("train needs a name for its checkpoint; give --name NAME")
    with run_lock(options.name, wait=wait):
        return _train(options, progress, record, offline, stop, source, quiet, register)


def _train(
    options: TrainOptions,
    progress: bool,
    record: Mapping[str, Any] | None,
    offline: bool | None,
    stop: bool,
    source: str,
    quiet: bool,
    register: bool,
) -> TrainResult:
    """:func:`train` under the run's writer lock."""
    from nsl import code_version, workspace
    from nsl.catalog import Catalog
    from nsl.datasets import api
    from nsl.learners import TrainConfig, inherited_settings, parse_learner
    from nsl.learners import config as learner_config
    from nsl.learners import train as train_learner

    o = options
    if not o.name:
        raise ConfigError("train needs a name for its checkpoint; give --name NAME")
    steps = o.steps
    if steps is None:
        if not o.init:
            raise ConfigError(
                "--steps is required for pre-training; give the number of gradient steps, e.g. "
                "--steps 20000 (fine-tuning with --init defaults to the recipe's "
                f"{learner_config.FINE_TUNE_STEPS})"
            )
        steps = learner_config.FINE_TUNE_STEPS
    if steps < 1:
        raise ConfigError(f"--steps {steps} must be at least 1")
    from nsl.learners.device import resolve_device

    resolve_device(o.device)  # --device cuda on a machine without a GPU: one line, before any data is read
    from nsl.eval.config import CRITERIA

    if o.criterion not in CRITERIA:
        raise ConfigError(f"--criterion {o.criterion!r} is unknown; use one of {', '.join(CRITERIA)}")
    mix = parse_data(list(o.data))
    sp = parse_shrink_perturb(o.shrink_perturb, o.init)
    net_config = parse_net(list(o.net))
    if net_config is not None and o.init:
        raise ConfigError(
            "--net sets the architecture of a new network; with --init the parent's is kept "
            "(drop --net, or drop --init to pre-train)"
        )
    from .refs import dataset_uses, pinned, resolve_init

    parent = pinned(o.init) if o.init else None
    if register or (o.init and parent is None):
        with Catalog() as cat:
            uses = dataset_uses(cat, mix)  # validates the refs and registers unknown versions
            parent = resolve_init(cat, o.init) if o.init else None
    else:  # nothing to look up (the parent is pinned): the catalog is left to whoever registers the run
        uses = dataset_uses(None, mix)
    views = [api.open_view(ref) for ref, _ in mix]
    for view in views:
        check_env_version(view)
    target_shift = o.target_shift or view_shift(views[-1])

    sources: list[tuple[Any, float]] = list(mix)
    held_out = None
    if offline is None:
        offline = bool(o.eval_every) and o.criterion != "eval"
    if o.eval_every and offline:
        train_view, held_out = api.episode_split(views[-1], o.holdout)
        sources[-1] = (train_view, mix[-1][1])
    inherited = inherited_settings(parent.path) if parent else {}  # a fine-tune keeps the parent's n-step and crop
    n_step = o.n_step if o.n_step is not None else inherited.get("n_step", 1)
    crop = o.crop if o.crop is not None else inherited.get("augment_crop")
    augment: dict[str, Any] = (
        {"augment_crop": 0, "augment_colour": 0.0}
        if o.no_augment
        else ({"augment_crop": crop} if crop is not None else {})
    )
    learner, learner_options = parse_learner(o.learner)
    config = TrainConfig(
        learner=learner,
        learner_options=learner_options,
        steps=steps,
        batch_size=o.batch_size,
        lr=o.lr,
        seed=o.seed,
        checkpoint_every=min(o.checkpoint_every, steps),
        eval_every=o.eval_every,
        conservative=o.conservative,
        n_step=n_step,
        lr_decay=o.lr_decay,
        weight_decay=o.weight_decay,
        shrink_perturb=sp,
        precision=o.precision,
        device=o.device,
        **augment,
    )
    sampler = api.make_sampler(sources, n_step=config.n_step, gamma=config.gamma)
    run_dir = workspace.runs_dir() / o.name
    run_dir.mkdir(parents=True, exist_ok=True)
    workspace.atomic_write_json(
        run_dir / "command.json",
        {
            "argv": sys.argv,
            "options": _jsonable(asdict(o)),
            "data": [u.__dict__ for u in uses],
            "init": parent.id if parent else None,
            "target_shift": target_shift,
            "code_version": code_version(),
            **(dict(record) if record else {}),
        },
    )

    monitor = (
        _monitor(
            o,
            run_dir,
            target_shift,
            held_out,
            gamma=config.gamma,
            patience=o.patience if stop else steps // o.eval_every + 2,
        )
        if o.eval_every
        else None
    )
    result = train_learner(
        config,
        sampler,
        run_dir,
        init_checkpoint=parent.path if parent else None,
        method=o.method,
        eval_fn=monitor,
        progress=progress,
        **({"net": net_config} if net_config is not None else {}),
    )
    made = TrainingOutput(
        name=o.name,
        run_dir=run_dir,
        final=Path(result.checkpoint),
        parent=parent.id if parent else None,
        uses=tuple(uses),
        shift=target_shift,
        scenes=monitor.config.seed if monitor is not None else None,
        source=source,
    )
    if register:
        entry = register_training(made)
        out = TrainResult(f"ckpt:{o.name}@{result.step}", entry.id, Path(entry.path), result.step, run_dir)
        if not quiet:
            print(f"checkpoint {out.checkpoint} ({entry.id[:12]}) -> {entry.path}")
    else:
        out = TrainResult(f"ckpt:{o.name}@{result.step}", None, made.final, result.step, run_dir, made=made)
    if monitor is None:
        return out
    best_step = monitor.stopper.best_step
    if best_step is None:
        best, text = None, "no step (every evaluation failed)"
    elif (run_dir / "checkpoints" / f"step-{best_step:09d}").is_dir():
        best = text = f"ckpt:{o.name}@{best_step}"
    else:  # step 0 is the starting point, which has no folder of its own
        best = parent.ref if parent else None
        text = f"step {best_step}, the starting point" + (f" ({parent.ref})" if parent else " (untrained)")
    if not quiet:
        print(f"best by {o.criterion}: {text}; curve in {run_dir / 'curve.csv'}; plot it with `nsl report {run_dir}`")
    return TrainResult(out.checkpoint, out.id, out.path, out.step, run_dir, best, best_step, out.made)


def _jsonable(d: dict[str, Any]) -> dict[str, Any]:
    return json.loads(json.dumps(d, default=list))


def _monitor(o: TrainOptions, run_dir: Path, target_shift: str, held_out, *, gamma: float, patience: int):
    """The trainer's ``eval_fn``: simulator success on target and base, offline scores on held-out episodes."""
    from nsl.collectors import parse_shift
    from nsl.eval import EarlyStopConfig, EarlyStopMonitor, simulator_scorer

    from .scoring import offline_scorer

    cfg = EarlyStopConfig(
        every=o.eval_every,
        episodes=o.eval_episodes,
        base_episodes=o.base_episodes,
        patience=patience,
        criterion=o.criterion,
        held_out=o.holdout,
        seed=o.eval_scenes,
    )
    score_target = score_base = None
    if o.eval_episodes:
        score_target = simulator_scorer(parse_shift(target_shift), cfg.eval_config(workers=o.workers))
    if o.base_episodes:
        score_base = simulator_scorer(parse_shift("base"), cfg.eval_config(base=True, workers=o.workers))
    offline = offline_scorer(held_out, gamma, o.criterion) if held_out is not None else None
    return EarlyStopMonitor(cfg, run_dir, score_target=score_target, score_base=score_base, offline=offline)


def register_checkpoint(cat, name: str, folder: Path, parent: str | None, uses, shift: str):
    """Catalogue one checkpoint folder of run ``name`` (its step from its config) with parent id, data and shift."""
    config = json.loads((Path(folder) / "config.json").read_text())
    return cat.save_checkpoint(
        name,
        int(config.get("step", 0)),
        Path(folder) / "model.safetensors",
        config,
        parent=parent,
        data=uses,
        shift=shift,
    )


def register_evaluated(
    cat, name: str, run_dir: Path, parent: str | None, uses, shift: str, seed: int, source: str = "early stopping"
) -> None:
    """Catalogue every evaluated checkpoint (so ckpt:NAME@STEP resolves) with its simulator evaluations.

    ``ckpt:NAME@best`` follows the simulator evaluations.
    """
    from nsl.eval import read_curve

    for row in read_curve(run_dir / "curve.csv"):
        folder = run_dir / "checkpoints" / f"step-{row.step:09d}"
        if not folder.is_dir():
            continue
        entry = register_checkpoint(cat, name, folder, parent, uses, shift)
        for task, r in ((shift, row.target), ("base", row.base)):
            if r is not None and r.episodes:
                cat.add_evaluation(
                    entry.id,
                    task,
                    episodes=r.episodes,
                    successes=round(r.success_rate * r.episodes),
                    seed=seed,
                    extra={"source": source, "step": row.step},
                )


def fine_tune_half_half(
    base_data: str, target: str, init: str | None, name: str, *, steps: int, seed: int, shift: str, progress: bool
) -> TrainResult:
    """The study's recipe: ``init`` (None: from scratch) trained on ``target`` mixed 50/50 with ``base_data``."""
    options = TrainOptions(
        data=(f"{base_data}=0.5", f"{target}=0.5"), init=init, steps=steps, name=name, seed=seed, target_shift=shift
    )
    return train(options, progress=progress)
