"""What each user action is asked to do: one frozen dataclass per action, the one source of its defaults.

The command line builds its options from these fields (default and help, see
``nsl/commands/_options.py``), and the Python API (``nsl.collect``,
``nsl.train``, ...) takes the same names as keyword arguments.  Settings that
belong to a lower layer take their default from that layer's own config
(``TrainConfig``, ``EarlyStopConfig``, ``EvalConfig``), so no default is written
twice.  This module is light: it loads neither PyTorch nor MuJoCo, so the
command line's start-up stays quick.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from nsl.errors import ConfigError
from nsl.eval.config import EarlyStopConfig, EvalConfig
from nsl.learners.config import (
    FINE_TUNE_CONSERVATIVE,
    FINE_TUNE_LR_FACTOR,
    FINE_TUNE_STEPS,
    FeatureConfig,
    TrainConfig,
)

PRECISIONS = ("fp32", "bf16", "auto")  # nsl.learners.precision.PRECISIONS (that module loads torch)
DEVICES = ("cpu", "cuda", "auto")  # nsl.learners.device.DEVICES (that module loads torch)
ENGINES = ("mujoco", "pybullet")  # nsl.collectors.ENGINES (that package loads gymnasium)
ENGINE_HELP = "physics engine and renderer: mujoco or pybullet (the same task, objects and scenes per seed)"
METHOD_HELP = (
    "ft = fine-tune all parameters of --init (the study's method); scratch = random init; "
    "new_head = parent's trunk, re-initialised head; new_head_frozen = the same with the trunk frozen "
    "(supervised features, nsl features); pnn = progressive network (frozen parent column "
    "plus a new one); ft_pnn = pnn whose new column starts as a copy of the parent"
)


def option(default: Any, help: str, **metadata: Any) -> Any:
    """A dataclass field whose default and help text the command line reads."""
    return field(default=default, metadata={"help": help, **metadata})


# --- collect --------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CollectConfig:
    """What ``nsl collect`` was asked to do (recorded in the dataset's metadata)."""

    shift: str = option(None, "shift spec: base, harsh_lighting, checkerboard_backing@0.5, ...")
    episodes: int = option(None, "total episodes the dataset should hold")
    policy: str = option(
        None,
        "policy: random, oracle[:NOISE] (noise std, e.g. oracle:0.5), or a checkpoint, "
        "ckpt:NAME[@STEP] (its CEM policy; see --epsilon)",
    )
    data: str = option(None, "name of the dataset to write (an existing name resumes or appends)")
    workers: int = option(1, "simulator processes (the data does not depend on it)")
    seed: int = option(0, "collection seed: episode i is a pure function of (seed, i)")
    num_envs: int = option(1, "environments per worker stepping in lock-step; the policy acts on them as one batch")
    split: str = option("train", "object split", choices=("train", "test"))
    image_size: int = option(64, "camera resolution in pixels")
    episodes_per_file: int = option(100, "episodes per Parquet file, also the resume granularity")
    epsilon: float = option(0.0, "with a ckpt: policy, chance of a random action per step (exploration)")
    action_noise: float = option(
        0.0,
        "with a ckpt: policy, Gaussian noise of this std (action units; 1 unit moves "
        "the wrist 3 cm) added to every action: exploration near what the policy would do",
    )
    precision: str = option(
        "fp32",
        "with a ckpt: policy, the precision its network acts in: fp32, bf16 (CPU bfloat16) or auto (bf16 where "
        "the CPU has it); recorded in the dataset",
        choices=PRECISIONS,
    )
    engine: str = option("mujoco", ENGINE_HELP + "; recorded in the dataset", choices=ENGINES)
    device: str = option(
        "cpu",
        "with a ckpt: policy, where its network runs: cpu (one state at a time), cuda (the --num-envs states "
        "searched in one batch on the GPU) or auto (cuda when torch sees a GPU); recorded in the dataset",
        choices=DEVICES,
    )

    def __post_init__(self) -> None:
        for name in ("shift", "episodes", "policy", "data"):
            if getattr(self, name) is None:
                raise ConfigError(f"collect needs {name}; give --{name.replace('_', '-')}")
        if self.episodes < 1:
            raise ConfigError(f"--episodes {self.episodes} must be at least 1")
        if self.workers < 1 or self.num_envs < 1:
            raise ConfigError(f"--workers {self.workers} and --num-envs {self.num_envs} must be at least 1")
        if self.episodes_per_file < 1:
            raise ConfigError(f"--episodes-per-file {self.episodes_per_file} must be at least 1")
        if not 0.0 <= self.epsilon <= 1.0:
            raise ConfigError(f"--epsilon {self.epsilon} must be in [0, 1]")
        if not 0.0 <= self.action_noise <= 2.0:
            raise ConfigError(f"--action-noise {self.action_noise} must be a standard deviation in [0, 2] action units")
        if self.action_noise > 0 and not (self.policy.startswith("ckpt:") or self.policy == "base"):
            raise ConfigError(
                f"--action-noise applies to checkpoint policies (ckpt:NAME), not {self.policy!r}; "
                "for the oracle use oracle:NOISE"
            )
        if self.seed < 0:
            raise ConfigError(f"--seed {self.seed} must be non-negative")


# --- evaluate -------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EvaluateOptions:
    """``nsl eval``: which scenes, how many, how fast (the scenes' defaults are :class:`EvalConfig`'s)."""

    shift: str = option(
        "base",
        "comma-separated shift specs, or 'all' (base and the five at severity 1), or 'study' "
        "(base and the five at the severities calibrated to ckpt:base)",
    )
    severity: float | None = option(None, "severity for shifts given without @X")
    episodes: int = option(EvalConfig.episodes, "episodes per shift")
    workers: int = option(EvalConfig.workers, "worker processes (the results do not depend on it)")
    num_envs: int = option(
        EvalConfig.batch, "environments per worker stepping in lock-step; the policy acts on them as one batch"
    )
    split: str = option(EvalConfig.split, "object split", choices=("train", "test"))
    seed: int = option(EvalConfig.seed, "scene seed: episode i is scene (seed, i), the same for every policy")
    precision: str = option(
        "fp32",
        "the precision checkpoint policies act in: fp32, bf16 (CPU bfloat16) or auto (bf16 where the CPU has it); "
        "reported with the results",
        choices=PRECISIONS,
    )
    engine: str = option(
        "mujoco",
        ENGINE_HELP + "; for the shifts that name none (engine:pybullet+SHIFT names its own), and part of each "
        "result's name off MuJoCo",
        choices=ENGINES,
    )
    device: str = option(
        "cpu",
        "where checkpoint policies act: cpu (one state at a time: an episode does not depend on its batch), or cuda "
        "(the --num-envs states of a worker searched in one call on the GPU; results recorded as PRECISION/cuda/N, "
        "apart from the CPU's) or auto",
        choices=DEVICES,
    )


# --- train ----------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrainOptions:
    """``nsl train``: pre-training (no ``init``) or fine-tuning (``init``), with optional early stopping.

    ``None`` means "the recipe's": a fine-tune takes :data:`FINE_TUNE_STEPS`,
    the conservative term :data:`FINE_TUNE_CONSERVATIVE`, 25% of the parent's
    learning rate and the parent's n-step returns and crop.
    """

    data: tuple[str, ...] = option(
        (),
        "dataset NAME[@vN][:TIER] with its share of each batch; repeat for a mix "
        "(default weights equal), e.g. --data grasp-base=0.5 --data grasp-harsh:100=0.5",
    )
    name: str = option(None, "checkpoint name in the catalog (also the run folder)")
    init: str | None = option(None, "parent checkpoint, e.g. ckpt:base or ckpt:run@best")
    method: str | None = option(None, METHOD_HELP + " (default: ft with --init, else scratch)")
    learner: str = option(
        TrainConfig.learner,
        "the offline learner: qtopt (QT-Opt, CEM maximum in the target), iql (implicit Q-learning: targets through "
        "an expectile of Q over the data's actions, acting by CEM), or a plugin's PACKAGE.NAME; NAME:KEY=VALUE,... "
        "sets its options, e.g. iql:expectile=0.9 (docs/learners.md)",
        metavar="NAME[:OPTS]",
    )
    lr: float | None = option(
        TrainConfig.lr, f"learning rate (default: 3e-4; fine-tuning: {FINE_TUNE_LR_FACTOR:.0%} of the parent's)"
    )
    steps: int | None = option(None, f"gradient steps (required for pre-training; fine-tuning: {FINE_TUNE_STEPS})")
    lr_decay: int = option(
        TrainConfig.lr_decay,
        "cosine-decay the learning rate to 5% of --lr over STEPS steps, "
        "then keep it there; the late checkpoints then move less from one "
        "to the next (0 = constant)",
        metavar="STEPS",
    )
    weight_decay: float = option(
        TrainConfig.weight_decay, "L2 penalty on the weights, added to the gradient by Adam", metavar="L2"
    )
    batch_size: int = option(TrainConfig.batch_size, "transitions per gradient step")
    seed: int = option(
        TrainConfig.seed, "seed of initialisation, sampling, augmentation and CEM; the same seed gives the same weights"
    )
    checkpoint_every: int = option(
        TrainConfig.checkpoint_every, "steps between checkpoints (a killed run resumes from the last one)"
    )
    no_augment: bool = option(False, "switch image augmentation off")
    conservative: float | None = option(
        TrainConfig.conservative,
        "weight of scoring random actions as failures, "
        "which keeps offline Q values of unseen actions down (0 = plain QT-Opt; "
        f"default: 0 for pre-training, {FINE_TUNE_CONSERVATIVE} for fine-tuning)",
        metavar="ALPHA",
    )
    shrink_perturb: str | tuple[float, float] | None = option(
        None,
        "with --init: start from ALPHA * the parent's weights + SIGMA * a fresh initialisation (shrink and "
        "perturb, Ash and Adams 2020), e.g. 0.8,0.01; recorded in the run's config",
        metavar="ALPHA,SIGMA",
    )
    n_step: int | None = option(
        None,
        "n-step returns: bootstrap after up to N steps of the data's own actions, so "
        "fewer Bellman maximisations stack up offline (default: 1; fine-tuning: the "
        "parent's)",
        metavar="N",
    )
    crop: int | None = option(
        None,
        f"random-shift augmentation in pixels (default: {TrainConfig.augment_crop}; "
        "fine-tuning: the parent's; 0 keeps the colour jitter only)",
        metavar="PIXELS",
    )
    net: tuple[str, ...] = option(
        (),
        "architecture for pre-training (a field of NetConfig; repeatable), e.g. --net "
        "pool=spatial --net hidden=32 --net action_dims=0,1,3; fine-tuning keeps the "
        "parent's",
        metavar="FIELD=VALUE",
    )
    eval_every: int = option(0, "steps between evaluations; 0 = no early stopping")
    eval_episodes: int = option(
        EarlyStopConfig.episodes, "simulator episodes per evaluation on the target shift (0 = offline criteria only)"
    )
    base_episodes: int = option(
        EarlyStopConfig.base_episodes, "episodes per evaluation on the base task, to watch forgetting (0 = skip)"
    )
    target_shift: str | None = option(None, "shift to evaluate on (default: the last dataset's shift)")
    patience: int = option(EarlyStopConfig.patience, "evaluations without improvement before stopping")
    criterion: str = option(
        EarlyStopConfig.criterion,
        "what early stopping follows: eval = simulator success on the "
        "target shift; softopc, auc = Q-values of held-out target episodes (higher is better); "
        "td = TD error on held-out target transitions (lower is better); qmean = their average Q, "
        "stopping after its peak (Kumar et al. 2021); fqe = fitted Q evaluation's estimate of the "
        "success rate from them; the offline ones need no simulator",
    )
    holdout: float = option(
        EarlyStopConfig.held_out,
        "fraction of the last dataset's episodes held out (its last ones) for the offline criteria",
    )
    eval_scenes: int = option(
        EarlyStopConfig.seed,
        "the scenes of every evaluation, those of `nsl eval --seed SEED`: "
        f"by default the selection scenes ({EarlyStopConfig.seed}), so the chosen step is "
        "reported on others",
        metavar="SEED",
    )
    workers: int = option(1, "evaluation worker processes")
    precision: str = option(
        TrainConfig.precision,
        "the network's passes: fp32, or bf16 (bfloat16 autocast; weights and optimiser stay fp32), or auto "
        "(bf16 where the CPU or GPU has it); recorded in the checkpoint",
        choices=PRECISIONS,
    )
    device: str = option(
        "auto",
        "where the gradient steps run: cpu, cuda, or auto (cuda when torch sees a GPU); a GPU run is recorded "
        "in the checkpoint, and its early-stopping evaluations act on the CPU",
        choices=DEVICES,
    )


# --- continual and efficiency ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ContinualConfig:
    """One continual run; saved as RUN/config.json."""

    sequence: tuple[str, ...] = option(
        (),
        "comma-separated shifts, e.g. harsh_lighting,transparent_objects,"
        "checkerboard_backing,extend_gripper,offset_gripper",
    )
    init: str = option("ckpt:base", "starting checkpoint")
    base_data: str = option("grasp-base", "base dataset mixed 50/50 into every stage", metavar="REF")
    episodes: int = option(800, "attempts collected per stage")
    steps: int = option(FINE_TUNE_STEPS, "gradient steps per stage (the fine-tuning recipe's)")
    eval_episodes: int = option(EvalConfig.episodes, "evaluation episodes per task and stage")
    epsilon: float = option(0.1, "exploration during collection")
    workers: int = option(1, "simulator processes for collection and evaluation")
    seed: int = option(0, "seed of stage i's collection is seed + i; training uses seed")
    single: bool = option(False, "also fine-tune each shift in one step from --init")


@dataclass(frozen=True)
class OnlineConfig:
    """One online fine-tuning run in rounds (``nsl online``); saved as RUN/config.json."""

    shift: str = option("", "the target shift the policy keeps collecting in, e.g. harsh_lighting@2")
    init: str = option("ckpt:base", "the starting checkpoint (round 0)")
    base_data: tuple[str, ...] = option(
        ("grasp-base",),
        "base dataset(s) REF[=WEIGHT] mixed into every round at 1 - --ratio; repeat for a mix (default: grasp-base)",
        metavar="REF[=WEIGHT]",
    )
    rounds: int = option(5, "rounds of collection and fine-tuning")
    episodes: int = option(800, "grasps the current policy collects per round")
    steps: int = option(FINE_TUNE_STEPS, "gradient steps per round (the fine-tuning recipe's)")
    ratio: float = option(0.5, "the target data's share of each batch (Fig. 5.11 sweeps 0.01-0.99)")
    method: str = option("ft", "round 1's method: ft (all parameters) or new_head (a fresh head); later rounds ft")
    learner: str = option(TrainConfig.learner, "the offline learner of every round (nsl train --learner)")
    epsilon: float = option(0.1, "exploration while collecting: chance of a random action per step")
    eval_episodes: int = option(EvalConfig.episodes, "evaluation episodes after each round")
    eval_scenes: int = option(EvalConfig.seed, "scene seed of the evaluations (nsl eval --seed)")
    workers: int = option(1, "simulator processes for collection and evaluation")
    num_envs: int | None = option(
        None,
        "environments per worker stepping in lock-step, in collection and evaluation (default: nsl collect's and "
        "nsl eval's)",
    )
    seed: int = option(0, "round i collects with scene seed SEED + i; every round trains with SEED")

    precision: str = option(
        TrainConfig.precision,
        "every round's training passes: fp32, bf16 (CPU bfloat16 autocast) or auto (bf16 where the CPU has it); "
        "collection and evaluation act in fp32",
        choices=PRECISIONS,
    )
    device: str = option(
        "auto",
        "where every round's training runs: cpu, cuda, or auto (cuda when torch sees a GPU); collection and "
        "evaluation act on the CPU",
        choices=DEVICES,
    )
    engine: str = option(
        "mujoco",
        ENGINE_HELP + " of the target shift (engine:pybullet+SHIFT names its own; engine:pybullet alone is the base "
        "task on PyBullet)",
        choices=ENGINES,
    )

    @property
    def target(self) -> str:
        """The target's one name, its engine included off MuJoCo (engine:pybullet+harsh_lighting@2)."""
        from nsl.collectors import parse_shift

        return parse_shift(self.shift, engine=self.engine).name


@dataclass(frozen=True)
class FeaturesConfig:
    """Supervised features (``nsl features``): a trunk trained to classify the train objects, or imported."""

    like: str = option(
        "ckpt:base",
        "checkpoint whose architecture and training recipe the features take: fine-tunes from them keep its "
        "n-step and crop and start at 25% of its rate, as fine-tunes of it do",
    )
    encoder: str | None = option(
        None,
        "a torchvision ResNet-18/34/50 state dict on disk (e.g. real ImageNet weights): the trunk is that ResNet, "
        "not trained here",
        metavar="PATH",
    )
    label: str = option(
        "classes",
        "what the trunk learns to predict from the frames: classes (which train object), pose (the object's position "
        "relative to the camera: a grasp-relevant label the simulator gives for free) or both",
        choices=("classes", "pose", "both"),
    )
    classes: int = option(0, "train objects to tell apart; 0: all 899 (the test objects are never shown)")
    frames: int = option(
        24, f"rendered frames per object; the last {FeatureConfig.holdout} of each measure held-out accuracy"
    )
    steps: int = option(FeatureConfig.steps, "gradient steps of the classifier")
    batch_size: int = option(FeatureConfig.batch_size, "frames per step")
    lr: float = option(FeatureConfig.lr, "the classifier's Adam learning rate")
    seed: int = option(0, "seed of the frames and of the training (the same seed gives the same weights)")


@dataclass(frozen=True)
class EfficiencyConfig:
    """One sample-efficiency run; saved as RUN/config.json."""

    data: tuple[str, ...] = option(
        (), "target dataset NAME[@vN] whose first-K tiers are used; repeat for one row per shift"
    )
    sizes: tuple[int, ...] = option(
        (25, 50, 100, 200, 400, 800),
        "comma-separated tier sizes (target episodes); sizes above a dataset's size are skipped",
    )
    init: str = option("ckpt:base", "checkpoint every fine-tune starts from")
    base_data: str = option("grasp-base", "base dataset mixed 50/50 into each fine-tune", metavar="REF")
    steps: int = option(FINE_TUNE_STEPS, "gradient steps per fine-tune (the fine-tuning recipe's)")
    eval_episodes: int = option(EvalConfig.episodes, "evaluation episodes per cell")
    workers: int = option(1, "simulator processes for evaluation")
    seed: int = option(0, "training seed of every fine-tune")
    scratch: bool = option(False, "also train from scratch on the largest tier's mix (a comparison column)")


__all__ = [
    "CollectConfig",
    "ContinualConfig",
    "EfficiencyConfig",
    "EvaluateOptions",
    "FeaturesConfig",
    "OnlineConfig",
    "TrainOptions",
    "option",
]
