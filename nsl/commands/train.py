"""``nsl train``: pre-train or fine-tune a QT-Opt Q-function offline, and catalogue the result."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from nsl.commands._options import add_parser, add_seed, add_workers

METHOD_HELP = ("ft = fine-tune all parameters of --init (the study's method); scratch = random init; "
               "new_head = parent's trunk, re-initialised head; pnn = progressive network (frozen parent column "
               "plus a new one); ft_pnn = pnn whose new column starts as a copy of the parent")


METHODS = ("scratch", "ft", "new_head", "pnn", "ft_pnn")  # nsl.learners.METHODS (not imported: it loads torch)
CRITERIA = ("eval", "softopc", "auc", "td")  # nsl.eval.CRITERIA


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub, "train", help="pre-train (no --init) or fine-tune (--init CKPT) a Q-function offline",
        description="Offline QT-Opt on one or more dataset versions mixed by weight. Without --init this is "
                    "pre-training; with --init it fine-tunes from a catalogued checkpoint with the fine-tuning "
                    "recipe: 2,000 steps at 25% of its learning rate, keeping its n-step returns and crop, with the "
                    "conservative term at 0.1 (mix the target data 50/50 with the base data, as the study did; "
                    "docs/learners.md). Running the same "
                    "command again resumes from the last checkpoint. The final checkpoint (and, with early "
                    "stopping, every evaluated one) is registered in the catalog under --name.")
    p.add_argument("--data", action="append", required=True, metavar="REF[=WEIGHT]",
                   help="dataset NAME[@vN][:TIER] with its share of each batch; repeat for a mix "
                        "(default weights equal), e.g. --data grasp-base=0.5 --data grasp-harsh:100=0.5")
    p.add_argument("--init", default=None, metavar="CKPT", help="parent checkpoint, e.g. ckpt:base or ckpt:run@best")
    p.add_argument("--method", default=None, choices=METHODS,
                   help=METHOD_HELP + " (default: ft with --init, else scratch)")
    p.add_argument("--lr", type=float, default=None,
                   help="learning rate (default: 3e-4; fine-tuning: 25%% of the parent's)")
    p.add_argument("--steps", type=int, default=None,
                   help="gradient steps (required for pre-training; fine-tuning: 2000)")
    p.add_argument("--lr-decay", type=int, default=0, metavar="STEPS",
                   help="cosine-decay the learning rate to 5%% of --lr over STEPS steps, then keep it there; the "
                        "late checkpoints then move less from one to the next (0 = constant)")
    p.add_argument("--weight-decay", type=float, default=0.0, metavar="L2",
                   help="L2 penalty on the weights, added to the gradient by Adam")
    p.add_argument("--name", required=True, help="checkpoint name in the catalog (also the run folder)")
    p.add_argument("--batch-size", type=int, default=64, help="transitions per gradient step")
    add_seed(p, help="seed of initialisation, sampling, augmentation and CEM; the same seed gives the same weights")
    p.add_argument("--checkpoint-every", type=int, default=2000,
                   help="steps between checkpoints (a killed run resumes from the last one)")
    p.add_argument("--no-augment", action="store_true", help="switch image augmentation off")
    p.add_argument("--conservative", type=float, default=None, metavar="ALPHA",
                   help="weight of scoring random actions as failures, which keeps offline Q values of unseen "
                        "actions down (0 = plain QT-Opt; default: 0 for pre-training, 0.1 for fine-tuning)")
    p.add_argument("--shrink-perturb", default=None, metavar="ALPHA,SIGMA",
                   help="with --init: start from ALPHA * the parent's weights + SIGMA * a fresh initialisation "
                        "(shrink and perturb, Ash and Adams 2020), e.g. 0.8,0.01; recorded in the run's config")
    p.add_argument("--n-step", type=int, default=None, metavar="N",
                   help="n-step returns: bootstrap after up to N steps of the data's own actions, so fewer "
                        "Bellman maximisations stack up offline (default: 1; fine-tuning: the parent's)")
    p.add_argument("--crop", type=int, default=None, metavar="PIXELS",
                   help="random-shift augmentation in pixels (default: 4; fine-tuning: the parent's; 0 keeps the "
                        "colour jitter only)")
    p.add_argument("--net", action="append", default=[], metavar="FIELD=VALUE",
                   help="architecture for pre-training (a field of NetConfig; repeatable), e.g. --net pool=spatial "
                        "--net hidden=32 --net action_dims=0,1,3; fine-tuning keeps the parent's")
    es = p.add_argument_group("early stopping (evaluates every --eval-every steps)")
    es.add_argument("--eval-every", type=int, default=0, help="steps between evaluations; 0 = no early stopping")
    es.add_argument("--eval-episodes", type=int, default=50,
                    help="simulator episodes per evaluation on the target shift (0 = offline criteria only)")
    es.add_argument("--base-episodes", type=int, default=0,
                    help="episodes per evaluation on the base task, to watch forgetting (0 = skip)")
    es.add_argument("--target-shift", default=None, help="shift to evaluate on (default: the last dataset's shift)")
    es.add_argument("--patience", type=int, default=5, help="evaluations without improvement before stopping")
    es.add_argument("--criterion", default="eval", choices=CRITERIA,
                    help="what early stopping follows: eval = simulator success on the target shift; softopc, auc = "
                         "Q-values of held-out target episodes (higher is better); td = TD error on held-out target "
                         "transitions (lower is better); the offline ones need no simulator")
    es.add_argument("--holdout", type=float, default=0.1,
                    help="fraction of the last dataset's episodes held out (its last ones) for the offline criteria")
    es.add_argument("--eval-scenes", type=int, default=3000, metavar="SEED",
                    help="the scenes of every evaluation, those of `nsl eval --seed SEED`: by default the selection "
                         "scenes (3000), so the chosen step is reported on others (`nsl eval --seed 2000`)")
    add_workers(es, help="evaluation worker processes")
    p.set_defaults(func=run)


def _parse_data(specs: list[str]) -> list[tuple[str, float | None]]:
    from nsl.errors import ConfigError

    out = []
    for s in specs:
        ref, sep, w = s.partition("=")
        ref = ref.removeprefix("data:")
        if sep:
            try:
                weight = float(w)
            except ValueError:
                raise ConfigError(f"--data {s!r}: weight {w!r} is not a number; write e.g. grasp-base=0.5") from None
        else:
            weight = None
        out.append((ref, weight))
    if any(w is None for _, w in out) and any(w is not None for _, w in out):
        raise ConfigError("--data: give a weight to every dataset or to none (equal shares)")
    return [(r, 1.0 / len(out) if w is None else w) for r, w in out]


def _parse_shrink_perturb(spec: str | None, init: str | None) -> tuple[float, float] | None:
    """``"0.8,0.01"`` -> (0.8, 0.01); None stays None."""
    if spec is None:
        return None
    from nsl.errors import ConfigError

    if not init:
        raise ConfigError("--shrink-perturb changes a parent's weights; give --init CKPT as well")
    try:
        alpha, sigma = (float(v) for v in spec.split(","))
    except ValueError:
        raise ConfigError(f"--shrink-perturb {spec!r}: write ALPHA,SIGMA, e.g. 0.8,0.01") from None
    return alpha, sigma


def _parse_net(specs: list[str]):
    """``["pool=spatial", "hidden=32"]`` -> a NetConfig (None when empty); values take the field's type."""
    if not specs:
        return None
    from dataclasses import fields

    from nsl.errors import ConfigError
    from nsl.learners import NetConfig

    defaults = {f.name: getattr(NetConfig(), f.name) for f in fields(NetConfig)}
    changes = {}
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


def run(args: argparse.Namespace) -> int:
    train(data=args.data, steps=args.steps, name=args.name, init=args.init, method=args.method, lr=args.lr,
          lr_decay=args.lr_decay, weight_decay=args.weight_decay, batch_size=args.batch_size, seed=args.seed,
          checkpoint_every=args.checkpoint_every, no_augment=args.no_augment, conservative=args.conservative,
          n_step=args.n_step, shrink_perturb=args.shrink_perturb, crop=args.crop, net=args.net,
          eval_every=args.eval_every, eval_episodes=args.eval_episodes, base_episodes=args.base_episodes,
          target_shift=args.target_shift, patience=args.patience, criterion=args.criterion, holdout=args.holdout,
          eval_scenes=args.eval_scenes, workers=args.workers)
    return 0


def train(*, data: list[str], steps: int | None, name: str, init: str | None = None, method: str | None = None,
          lr: float | None = None, lr_decay: int = 0, weight_decay: float = 0.0, batch_size: int = 64, seed: int = 0,
          checkpoint_every: int = 2000, no_augment: bool = False, conservative: float | None = None,
          n_step: int | None = None, shrink_perturb: str | None = None, crop: int | None = None, net: list[str] = (),
          eval_every: int = 0, eval_episodes: int = 50, base_episodes: int = 0, target_shift: str | None = None,
          patience: int = 5, criterion: str = "eval", holdout: float = 0.1, eval_scenes: int = 3000, workers: int = 1):
    """Train (or resume) run ``name`` and catalogue its checkpoints; returns the final CheckpointEntry.

    The keyword arguments are those of ``nsl train`` (``data`` holds the
    ``REF[=WEIGHT]`` strings of its repeated ``--data``).  ``steps`` and
    ``conservative`` None are the fine-tuning recipe's with ``init``
    (``nsl.learners.FINE_TUNE_STEPS``, ``FINE_TUNE_CONSERVATIVE``).
    """
    from nsl import code_version, workspace
    from nsl.catalog import Catalog
    from nsl.datasets import api
    from nsl.errors import ConfigError
    from nsl.learners import TrainConfig, config as learner_config, inherited_settings
    from nsl.learners import train as train_learner
    from nsl.commands._refs import dataset_uses, resolve_init

    if steps is None:
        if not init:
            raise ConfigError("--steps is required for pre-training; give the number of gradient steps, e.g. "
                              "--steps 20000 (fine-tuning with --init defaults to the recipe's "
                              f"{learner_config.FINE_TUNE_STEPS})")
        steps = learner_config.FINE_TUNE_STEPS
    if steps < 1:
        raise ConfigError(f"--steps {steps} must be at least 1")
    if criterion not in CRITERIA:
        raise ConfigError(f"--criterion {criterion!r} is unknown; use one of {', '.join(CRITERIA)}")
    mix = _parse_data(list(data))
    sp = _parse_shrink_perturb(shrink_perturb, init)
    net_config = _parse_net(list(net))
    if net_config is not None and init:
        raise ConfigError("--net sets the architecture of a new network; with --init the parent's is kept "
                          "(drop --net, or drop --init to pre-train)")
    options = {k: v for k, v in locals().items() if k in TRAIN_OPTIONS}
    cat = Catalog()
    uses = dataset_uses(cat, mix)  # validates the refs and registers unknown versions
    parent = resolve_init(cat, init) if init else None
    views = [api.open_view(ref) for ref, _ in mix]
    for view in views:
        _check_env_version(view)
    target_view = views[-1]
    target_shift = target_shift or view_shift(target_view)

    sources = [(ref, w) for ref, w in mix]
    held_out = None
    if eval_every and criterion != "eval":
        train_view, held_out = api.episode_split(target_view, holdout)
        sources[-1] = (train_view, mix[-1][1])
    inherited = inherited_settings(parent.path) if parent else {}  # a fine-tune keeps the parent's n-step and crop
    n_step = n_step if n_step is not None else inherited.get("n_step", 1)
    crop = crop if crop is not None else inherited.get("augment_crop")
    config = TrainConfig(steps=steps, batch_size=batch_size, lr=lr, seed=seed,
                         checkpoint_every=checkpoint_every, eval_every=eval_every,
                         conservative=conservative, n_step=n_step, lr_decay=lr_decay,
                         weight_decay=weight_decay, shrink_perturb=sp,
                         **({"augment_crop": 0, "augment_colour": 0.0} if no_augment else {}),
                         **({"augment_crop": crop} if crop is not None and not no_augment else {}))
    sampler = api.make_sampler(sources, n_step=config.n_step, gamma=config.gamma)
    run_dir = workspace.runs_dir() / name
    run_dir.mkdir(parents=True, exist_ok=True)
    workspace.atomic_write_json(run_dir / "command.json", {
        "argv": sys.argv, "options": options, "data": [u.__dict__ for u in uses],
        "init": parent.id if parent else None, "target_shift": target_shift, "code_version": code_version()})

    monitor = None
    if eval_every:
        monitor = _monitor(run_dir, target_shift, held_out, every=eval_every, episodes=eval_episodes,
                           base_episodes=base_episodes, patience=patience, criterion=criterion, holdout=holdout,
                           seed=eval_scenes, workers=workers, gamma=config.gamma)
    result = train_learner(config, sampler, run_dir, init_checkpoint=parent.path if parent else None, method=method,
                           eval_fn=monitor, **({"net": net_config} if net_config is not None else {}))
    entry = _register(cat, name, result.checkpoint, parent, uses, target_shift)
    print(f"checkpoint ckpt:{name}@{result.step} ({entry.id[:12]}) -> {entry.path}")
    if monitor is not None:
        _register_evaluated(cat, name, run_dir, parent, uses, target_shift, monitor.config.seed)
        best_step = monitor.stopper.best_step
        if best_step is None:
            best = "no step (every evaluation failed)"
        elif (run_dir / "checkpoints" / f"step-{best_step:09d}").is_dir():
            best = f"ckpt:{name}@{best_step}"
        else:  # step 0 is the starting point, which has no folder of its own
            best = f"step {best_step}, the starting point" + (f" ({parent.ref})" if parent else " (untrained)")
        print(f"best by {criterion}: {best}; curve in {run_dir / 'curve.csv'}; plot it with `nsl report {run_dir}`")
    return entry


TRAIN_OPTIONS = ("data", "steps", "name", "init", "method", "lr", "lr_decay", "weight_decay", "batch_size", "seed",
                 "checkpoint_every", "no_augment", "conservative", "n_step", "shrink_perturb", "crop", "net",
                 "eval_every", "eval_episodes", "base_episodes", "target_shift", "patience", "criterion", "holdout",
                 "eval_scenes", "workers")


def _check_env_version(view) -> None:
    """Refuse data from an older simulator: its pictures and physics differ from what evaluation runs."""
    from nsl.collectors import ENV_VERSION
    from nsl.errors import IncompatibleVersionError

    for c in view.version.provenance.get("collections", []):
        got = c.get("spec", {}).get("env", {}).get("env_version")
        if got is not None and got != ENV_VERSION:
            raise IncompatibleVersionError(
                f"dataset {view.version.ref} was collected in environment {got}, but this nsl simulates "
                f"{ENV_VERSION} (wrist camera, 7 cm jaw); collect it again, or set NSL_HOME to a new workspace")


def view_shift(view) -> str:
    spec = view.version.provenance["collections"][-1]["spec"]
    return spec.get("env", {}).get("shift", "base")


def _monitor(run_dir: Path, target_shift: str, held_out, *, every: int, episodes: int, base_episodes: int,
             patience: int, criterion: str, holdout: float, seed: int, workers: int, gamma: float):
    from nsl.collectors import parse_shift
    from nsl.eval import EarlyStopConfig, EarlyStopMonitor, simulator_scorer

    cfg = EarlyStopConfig(every=every, episodes=episodes, base_episodes=base_episodes, patience=patience,
                          criterion=criterion, held_out=holdout, seed=seed)
    score_target = score_base = None
    if episodes:
        score_target = simulator_scorer(parse_shift(target_shift), cfg.eval_config(workers=workers))
    if base_episodes:
        score_base = simulator_scorer(parse_shift("base"), cfg.eval_config(base=True, workers=workers))
    offline = _offline_scorer(held_out, gamma, criterion) if held_out is not None else None
    return EarlyStopMonitor(cfg, run_dir, score_target=score_target, score_base=score_base, offline=offline)


TD_SEED = 2000  # CEM noise for the held-out next states: the same draw at every evaluation


def _offline_scorer(view, gamma: float, criterion: str):
    """Offline scores of a policy on a fixed held-out slice of the target data (no simulator).

    SoftOPC and AUC rank the Q-values of held-out transitions by their
    episode's success.  The TD error compares Q(s, a) with the one-step
    Bellman target r + gamma * (1 - done) * Q(s', a*), a* = CEM's maximum
    (each transition's CEM noise is fixed, so evaluations differ only by the
    network); transitions whose episode was truncated after them have no
    known target and are left out.  Lower is better.
    """
    import numpy as np

    from nsl import keys
    from nsl.errors import ConfigError
    from nsl.eval import q_ranking_auc, soft_opc, td_error

    arrays = view.episodes_arrays()
    episode = arrays[keys.EPISODE_INDEX]
    success_by_episode = {e: bool(arrays[keys.SUCCESS][episode == e].any()) for e in np.unique(episode)}
    labels = np.array([success_by_episode[e] for e in episode])
    obs = {"image": arrays[keys.OBS_IMAGE], "state": arrays[keys.OBS_STATE]}
    reward = arrays[keys.REWARD].astype(np.float64)
    done = arrays[keys.DONE].astype(bool)
    n = len(episode)
    following = np.zeros(n, dtype=bool)
    following[:-1] = episode[1:] == episode[:-1]  # frame i + 1 is the next observation of frame i
    live = np.flatnonzero(following & ~done)
    known = done | following

    def score(policy) -> dict:
        q = _q_values(policy, obs, arrays[keys.ACTION])
        out = {}
        for key, fn in (("softopc", soft_opc), ("auc", q_ranking_auc)):
            try:
                out[key] = fn(q, labels)
            except ConfigError:  # e.g. no failed episode held out: only fatal when it is the criterion
                if criterion == key:
                    raise
        if criterion == "td":
            nxt = {"image": obs["image"][live + 1], "state": obs["state"][live + 1]}
            best = policy(nxt, rngs=[np.random.default_rng([TD_SEED, int(j)]) for j in live])
            value = np.zeros(n)
            value[live] = _q_values(policy, nxt, best)
            target = reward + gamma * (~done) * value
            out["td_error"] = td_error(q[known], target[known])
        return out

    return score


def _q_values(policy, obs: dict, actions, chunk: int = 512):
    """The policy's Q-values of ``actions`` in ``obs``, in chunks of ``chunk`` transitions."""
    import numpy as np

    parts = [policy.q_values({k: v[i:i + chunk] for k, v in obs.items()}, actions[i:i + chunk])
             for i in range(0, len(actions), chunk)]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.float32)


def _register(cat, name: str, folder: Path, parent, uses, shift: str):
    config = json.loads((folder / "config.json").read_text())
    return cat.save_checkpoint(name, int(config.get("step", 0)), folder / "model.safetensors", config,
                               parent=parent.id if parent else None, data=uses, shift=shift)


def _register_evaluated(cat, name, run_dir: Path, parent, uses, shift: str, seed: int) -> None:
    """Catalogue every evaluated checkpoint (so ckpt:NAME@STEP resolves) with its simulator evaluations.

    ckpt:NAME@best follows the simulator evaluations.
    """
    from nsl.eval import read_curve

    for row in read_curve(run_dir / "curve.csv"):
        folder = run_dir / "checkpoints" / f"step-{row.step:09d}"
        if not folder.is_dir():
            continue
        entry = _register(cat, name, folder, parent, uses, shift)
        if row.target is None:
            continue
        t = row.target
        cat.add_evaluation(entry.id, shift, episodes=t.episodes, successes=round(t.success_rate * t.episodes),
                           seed=seed, extra={"source": "early stopping", "step": row.step})
        if row.base is not None and row.base.episodes:
            b = row.base
            cat.add_evaluation(entry.id, "base", episodes=b.episodes, successes=round(b.success_rate * b.episodes),
                               seed=seed, extra={"source": "early stopping", "step": row.step})
