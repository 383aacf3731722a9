"""The training loop: pre-training and the study's fine-tuning methods, resumable.

``train(config, sampler, out_dir, init_checkpoint=..., method=...)`` runs
``config.steps`` QT-Opt updates and leaves in ``out_dir``::

    run.json                      what this run is (config, method, parent, data, architecture)
    metrics.csv                   one row every log_every steps (losses/..., q/..., charts/...)
    eval.jsonl                    one line per eval_fn call
    tb/                           TensorBoard event files
    checkpoints/step-000002000/   periodic checkpoints (the newest also hold the trainer state)
    final/                        the last checkpoint (weights and config only)

Methods (``init_checkpoint`` is the parent):

* ``scratch``: random initialisation (the parent, if any, only gives the architecture);
* ``ft``: all parameters from the parent (the study's method);
* ``new_head``: the parent's conv trunk, a freshly initialised head;
* ``new_head_frozen``: the same with the trunk frozen (supervised features fine-tuned with their trunk fixed);
* ``pnn``: a progressive network: the parent's columns frozen plus a new column with lateral connections;
* ``ft_pnn``: the same, with the new column initialised from the parent's last column.

With ``TrainConfig.shrink_perturb = (alpha, sigma)`` the starting network's trainable weights become
``alpha * w + sigma * w_init`` (Ash and Adams 2020), ``w_init`` a fresh initialisation drawn from ``seed + 1``.

The learning rate defaults to 3e-4 from scratch and to 25% of the parent's
when fine-tuning.  Running the same call again after a crash or kill resumes
from the newest checkpoint and, on the same machine and thread count, ends
with bit-identical weights; on a finished run it returns at once.
"""

from __future__ import annotations

import copy
import csv
import json
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from nsl.errors import ConfigError
from nsl.progress import progress_bar
from nsl.workspace import atomic_write_bytes

from .algorithm import Algorithm
from .checkpoint import (
    TRAINER_FILE,
    Checkpoint,
    checkpoint_config,
    checkpoint_id,
    load_checkpoint,
    load_trainer_state,
    read_config,
    save_checkpoint,
    write_json,
)
from .config import FINE_TUNE_CONSERVATIVE, FINE_TUNE_LR_FACTOR, METHODS, NetConfig, TrainConfig
from .device import resolve_device
from .networks import QNetwork, freeze_trunk, grow_column, reinit_head, shrink_perturb
from .policy import CEMPolicy, acting_policy
from .precision import resolve_precision
from .qtopt import batch_to_torch
from .registry import find_learner
from .sampler import Sampler

DEFAULT_LR = 3e-4
CHECKPOINT_DIR = "checkpoints"
FINAL_DIR = "final"
RUN_FILE = "run.json"
METRICS_FILE = "metrics.csv"
EVAL_FILE = "eval.jsonl"
# Settings that may change between a run and its resumption (they do not change the weights).
RESUMABLE_CHANGES = ("steps", "log_every", "checkpoint_every", "eval_every", "keep_trainer_state")

EvalFn = Callable[[int, CEMPolicy], dict[str, Any]]


@dataclass
class TrainResult:
    checkpoint: Path  # the final checkpoint folder
    step: int
    stopped_early: bool  # eval_fn asked to stop
    metrics: dict[str, float] = field(default_factory=dict)  # the last logged row
    evals: list[dict[str, Any]] = field(default_factory=list)  # eval_fn results of this invocation


INHERITED = ("n_step", "augment_crop")  # how the parent read its data: a fine-tune keeps it unless told otherwise


def inherited_settings(init_checkpoint: str | Path) -> dict[str, Any]:
    """The parent's training settings a fine-tune keeps unless told otherwise: its n-step horizon and crop.

    A parent trained on Monte-Carlo-like returns (``n_step`` 8) and fine-tuned on one-step targets changes
    what its Q-values mean in the first steps of the fine-tune; measured in docs/experiments/fine-tuning.md.
    """
    training = read_config(Path(init_checkpoint))["training"]
    defaults = TrainConfig()
    return {k: training.get(k, getattr(defaults, k)) for k in INHERITED}


def resolve_lr(config: TrainConfig, method: str, parent: Checkpoint | None) -> float:
    """The explicit ``config.lr``, else 3e-4 (scratch: the parent's), else 25% of the parent's."""
    if config.lr is not None:
        return config.lr
    if parent is None:
        return DEFAULT_LR
    return parent.lr if method == "scratch" else parent.lr * FINE_TUNE_LR_FACTOR


def resolve_conservative(config: TrainConfig, parent: Checkpoint | None, algo: Algorithm | None = None) -> float:
    """The explicit ``config.conservative``, else 0 from scratch and FINE_TUNE_CONSERVATIVE with a parent; always 0
    for a learner without the term."""
    if algo is not None and not algo.conservative:
        if config.conservative:
            raise ConfigError(
                f"learner {algo.name!r} has no conservative term; drop --conservative (or use learner qtopt)"
            )
        return 0.0
    if config.conservative is not None:
        return config.conservative
    return 0.0 if parent is None else FINE_TUNE_CONSERVATIVE


def initial_network(method: str, parent: Checkpoint | None, net: NetConfig | None, seed: int) -> QNetwork:
    """The network a run starts from (random parts drawn from ``seed``)."""
    torch.manual_seed(seed)
    if method == "scratch":
        if net is None:
            if parent is None:
                raise ConfigError("a network from scratch needs an architecture (net) or a parent checkpoint")
            net = NetConfig.from_dict({**parent.architecture.to_dict(), "columns": 1})
        return QNetwork(net)
    if parent is None:
        raise ConfigError(f"method {method!r} fine-tunes a parent; pass its checkpoint")
    base = copy.deepcopy(parent.net).train()
    if method == "ft":
        return base
    if method in ("new_head", "new_head_frozen"):
        reinit_head(base)
        if method == "new_head_frozen":
            freeze_trunk(base)
        return base
    return grow_column(base, copy_last=(method == "ft_pnn")).train()


def train(
    config: TrainConfig,
    sampler: Sampler,
    out_dir: str | Path,
    *,
    init_checkpoint: str | Path | None = None,
    method: str | None = None,
    net: NetConfig | None = None,
    eval_fn: EvalFn | None = None,
    progress: bool = True,
) -> TrainResult:
    """Train (or resume training) a Q-function from ``sampler``'s transitions into ``out_dir``.

    ``config.learner`` names the learner that takes the gradient steps (``qtopt``, ``iql`` or a plugin's;
    learners/algorithm.py); everything else here is the same for every learner.

    ``net`` is the architecture for a run from scratch without a parent; with
    ``init_checkpoint`` the architecture comes from the parent.  ``eval_fn(step,
    policy)`` is called every ``config.eval_every`` steps with a CEM policy
    over a snapshot of the online network; if its result has a true ``"stop"``
    the run ends there (the final checkpoint is that step's).
    """
    out = Path(out_dir)
    method = method or ("ft" if init_checkpoint is not None else "scratch")
    if method not in METHODS:
        raise ConfigError(f"method {method!r} is unknown; use one of {', '.join(METHODS)}")
    algo, plugin = find_learner(config.learner)
    if method not in algo.methods:
        raise ConfigError(
            f"learner {algo.name!r} does not support method {method!r}; use one of {', '.join(algo.methods)}"
        )
    if eval_fn is not None and config.eval_every and not algo.early_stopping:
        raise ConfigError(f"learner {algo.name!r} does not support early stopping; drop --eval-every")
    options = algo.options(config.learner_options)
    if init_checkpoint is None and method != "scratch":
        raise ConfigError(f"method {method!r} fine-tunes a parent; pass init_checkpoint (or use method 'scratch')")
    if init_checkpoint is not None and net is not None:
        raise ConfigError("the architecture comes from init_checkpoint; do not pass net as well")
    data = sampler.describe()
    if (data.get("n_step", 1), data.get("gamma", config.gamma)) != (config.n_step, config.gamma):
        raise ConfigError(
            f"the sampler gives {data.get('n_step', 1)}-step transitions (gamma {data.get('gamma')}) but "
            f"the config asks for n_step {config.n_step}, gamma {config.gamma}; build the sampler with "
            "the config's values"
        )
    parent = load_checkpoint(Path(init_checkpoint)) if init_checkpoint is not None else None
    lr = resolve_lr(config, method, parent)
    device = resolve_device(config.device)
    resolved = config.replace(
        lr=lr,
        conservative=resolve_conservative(config, parent, algo),
        precision=resolve_precision(config.precision, device),
        device=device,
        learner_options=algo.option_dict(options),
    )
    model = initial_network(method, parent, net or (None if parent else NetConfig()), config.seed)
    if config.shrink_perturb is not None:
        if parent is None or method == "scratch":
            raise ConfigError(
                "shrink_perturb changes a parent's weights; use it with init_checkpoint and a "
                "fine-tuning method (not scratch)"
            )
        alpha, sigma = config.shrink_perturb
        shrink_perturb(model, alpha, sigma, seed=config.seed + 1)
    # The parent by content id, not by folder: the config is part of the checkpoint's id, which must not depend
    # on where the workspace is (a dataset collected by this checkpoint records that id).
    parent_info = (
        None
        if parent is None
        else {"id": checkpoint_id(parent.path), "step": parent.step, "method": parent.config["method"]}
    )
    run: dict[str, Any] = {
        "training": resolved.to_dict(),
        "method": method,
        "parent": parent_info,
        "architecture": model.cfg.to_dict(),
        "data": data,
    }
    learner_record = None if plugin is None else {"name": algo.name, "plugin": dict(plugin)}
    if learner_record is not None:
        run["learner"] = learner_record  # a plugin learner: its package and version (nsl.plugins)
    _check_same_run(out, run)

    learner = algo.create(model, lr, resolved, options)
    rng = np.random.default_rng(config.seed)
    step = 0
    resume = _latest_trainer_state(out)
    if resume is not None:
        state = load_trainer_state(resume)
        assert state is not None  # resume is a folder with a trainer state file
        learner.load_state_dict(state["learner"])
        rng.bit_generator.state = state["numpy_rng"]
        torch.set_rng_state(state["torch_rng"])
        step = int(state["step"])
    write_json(out / RUN_FILE, run)
    final = out / FINAL_DIR
    if step >= config.steps and final.is_dir() and load_checkpoint(final).step == step:
        return TrainResult(final, step, False)

    def ckpt_config(at: int) -> dict:
        return checkpoint_config(
            learner.online,
            training=resolved,
            method=method,
            data=run["data"],
            parent=parent_info,
            step=at,
            learner=learner_record,
        )

    log = _Logger(out, step)
    evals: list[dict[str, Any]] = []
    stop = False
    window: dict[str, float] = {}
    last_row: dict[str, float] = {}
    t0, n0 = time.perf_counter(), 0
    bar = progress_bar(
        total=config.steps, initial=step, unit="step", disable=not progress, dynamic_ncols=True, desc=f"train {method}"
    )
    try:
        if eval_fn is not None and config.eval_every and step == 0:
            stop = _evaluate(eval_fn, algo, learner.online, resolved, 0, out, log, evals)
        while step < config.steps and not stop:
            batch = batch_to_torch(sampler.sample(config.batch_size, rng))
            step_lr = resolved.lr_at(step)
            learner.set_lr(step_lr)
            metrics = algo.update(learner, batch, resolved, step, options)
            step += 1
            n0 += 1
            for k, v in metrics.items():
                window[k] = window.get(k, 0.0) + v
            bar.update(1)
            if step % config.log_every == 0 or step == config.steps:
                dt = time.perf_counter() - t0
                last_row = {k: float(v) / n0 for k, v in window.items()} | {  # the device's metrics, read here
                    "charts/steps_per_s": n0 / max(dt, 1e-9),
                    "charts/lr": step_lr,
                }
                log.metrics(step, last_row)
                bar.set_postfix(
                    loss=f"{last_row['losses/q_loss']:.4f}",
                    q=f"{last_row['q/mean']:.3f}",
                    target=f"{last_row['q/target_mean']:.3f}",
                    refresh=False,  # the bar redraws on its own schedule (in a log: a line every 30 s)
                )
                window, t0, n0 = {}, time.perf_counter(), 0
            evaluated = eval_fn is not None and config.eval_every and step % config.eval_every == 0
            if evaluated and eval_fn is not None:
                stop = _evaluate(eval_fn, algo, learner.online, resolved, step, out, log, evals)
            if step % config.checkpoint_every == 0 or step == config.steps or stop or evaluated:
                _save_periodic(out, learner, rng, step, ckpt_config(step), config.keep_trainer_state)
    finally:
        bar.close()
        log.close()
    save_checkpoint(final, learner.online, ckpt_config(step))
    return TrainResult(final, step, stop, last_row, evals)


def _evaluate(
    eval_fn: EvalFn,
    algo: Algorithm,
    online: QNetwork,
    cfg: TrainConfig,
    step: int,
    out: Path,
    log: _Logger,
    evals: list,
) -> bool:
    # The simulator's policy acts on the CPU (its workers must not inherit a CUDA context); a run trained on a GPU
    # is evaluated in float32 there, as the study evaluates every checkpoint.
    snapshot = copy.deepcopy(online).cpu().eval()
    kwargs: dict[str, Any] = {
        "name": f"{out.name}@{step}",
        "info": {"run": str(out), "step": step},
        "precision": cfg.precision if cfg.device == "cpu" else "fp32",
    }
    policy = acting_policy(algo, snapshot, cfg.cem, **kwargs)
    result = dict(eval_fn(step, policy) or {})
    evals.append({"step": step, **result})
    log.eval(step, result)
    return bool(result.get("stop", False))


def _checkpoint_dirs(out: Path) -> list[Path]:
    root = out / CHECKPOINT_DIR
    if not root.is_dir():
        return []
    return sorted(p for p in root.iterdir() if p.is_dir() and p.name.startswith("step-"))


def _latest_trainer_state(out: Path) -> Path | None:
    root = out / CHECKPOINT_DIR
    if root.is_dir():
        for p in root.iterdir():  # folders a crash left half-written
            if p.name.startswith(".") and p.name.endswith(".tmp"):
                shutil.rmtree(p, ignore_errors=True)
    with_state = [p for p in _checkpoint_dirs(out) if (p / TRAINER_FILE).is_file()]
    return with_state[-1] if with_state else None


def _save_periodic(out: Path, learner: Any, rng: np.random.Generator, step: int, config: dict, keep: int) -> None:
    state = {
        "learner": learner.state_dict(),
        "numpy_rng": rng.bit_generator.state,
        "torch_rng": torch.get_rng_state(),
        "step": step,
    }
    save_checkpoint(out / CHECKPOINT_DIR / f"step-{step:09d}", learner.online, config, trainer_state=state)
    with_state = [p for p in _checkpoint_dirs(out) if (p / TRAINER_FILE).is_file()]
    for p in with_state[:-keep]:
        os.remove(p / TRAINER_FILE)


def _check_same_run(out: Path, run: dict) -> None:
    f = out / RUN_FILE
    if not f.is_file():
        return
    old = json.loads(f.read_text())
    for section in ("method", "parent", "architecture", "data", "training"):
        a, b = old.get(section), json.loads(json.dumps(run[section]))
        if section == "parent" and isinstance(a, dict):
            a = {k: v for k, v in a.items() if k != "path"}  # older runs also recorded the parent's folder
        if section == "training":
            a = TrainConfig.from_dict(a).to_dict() if a else {}  # settings added since then take their defaults
            if a and a.get("conservative") is None:
                a["conservative"] = 0.0  # recorded before the term existed: the run had none
            a = {k: v for k, v in a.items() if k not in RESUMABLE_CHANGES}
            b = {k: v for k, v in b.items() if k not in RESUMABLE_CHANGES}
        if a != b:
            diff = (
                sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
                if isinstance(a, dict) and isinstance(b, dict)
                else []
            )
            raise ConfigError(
                f"{out} holds a run with a different {section}{f' ({diff})' if diff else ''}; "
                "resume with the same settings or choose another output folder"
            )


class _Logger:
    """metrics.csv, eval.jsonl and TensorBoard; on resume, rows after the resumed step are dropped."""

    def __init__(self, out: Path, step: int):
        from torch.utils.tensorboard import SummaryWriter

        self.out = out
        out.mkdir(parents=True, exist_ok=True)
        self._truncate(out / METRICS_FILE, step, csv_file=True)
        self._truncate(out / EVAL_FILE, step, csv_file=False)
        self.tb = SummaryWriter(log_dir=str(out / "tb"), purge_step=step if step > 0 else None)
        self._fields: list[str] | None = None
        if (out / METRICS_FILE).is_file():
            with open(out / METRICS_FILE, newline="") as f:
                self._fields = next(csv.reader(f), None)

    @staticmethod
    def _truncate(path: Path, step: int, csv_file: bool) -> None:
        if not path.is_file():
            return
        if step == 0:  # a fresh start: nothing before it survives
            path.unlink()
            return
        lines = path.read_text().splitlines(keepends=True)
        keep = lines[:1] if csv_file else []
        for line in lines[1:] if csv_file else lines:
            if not line.endswith("\n"):
                break  # a line cut short by a kill
            try:
                s = int(line.split(",", 1)[0]) if csv_file else int(json.loads(line)["step"])
            except (ValueError, KeyError, json.JSONDecodeError):
                break
            if s > step:
                break
            keep.append(line)
        atomic_write_bytes(path, "".join(keep).encode())

    def metrics(self, step: int, row: dict[str, float]) -> None:
        path = self.out / METRICS_FILE
        if self._fields is None:
            self._fields = ["step", *row]
            atomic_write_bytes(path, (",".join(self._fields) + "\n").encode())
        with open(path, "a", newline="") as f:
            csv.writer(f).writerow([step, *(f"{row.get(k, float('nan')):.6g}" for k in self._fields[1:])])
        for k, v in row.items():
            self.tb.add_scalar(k, v, step)

    def eval(self, step: int, result: dict[str, Any]) -> None:
        with open(self.out / EVAL_FILE, "a") as f:
            f.write(json.dumps({"step": step, **result}, sort_keys=True, default=str) + "\n")
        for k, v in result.items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                self.tb.add_scalar(k if "/" in k else f"eval/{k}", v, step)

    def close(self) -> None:
        self.tb.close()
