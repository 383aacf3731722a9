"""The learner's settings: the network architecture, CEM, and a training run.

Three plain dataclasses, each checked in ``__post_init__`` and saved as JSON in
every checkpoint's ``config.json``:

* :class:`NetConfig` is the architecture (what the weights mean).  A
  checkpoint's weights are refused if their shapes do not match it.
* :class:`CemConfig` is the action search, used for Bellman targets during
  training and for acting.
* :class:`TrainConfig` is one run: optimisation, stabilisers, augmentation,
  schedule and seed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from nsl.errors import ConfigError
from nsl.keys import ACTION_DIM, STATE_DIM

POOLS = ("flatten", "max", "spatial")
NORMS = ("none", "group")
METHODS = ("scratch", "ft", "new_head", "new_head_frozen", "pnn", "ft_pnn")
# The conv trunk of a column: the network's own ("conv"), or a torchvision ResNet (weights imported with
# ``nsl features --encoder PATH``; learners/features.py).  A ResNet's output is 1/32 of the image's side.
ENCODERS = ("conv", "resnet18", "resnet34", "resnet50")
FINE_TUNE_LR_FACTOR = 0.25  # fine-tuning learning rate = 25% of the parent's (the study's recipe)
# The fine-tuning recipe's other two settings, chosen on selection scenes: the conservative term's weight and the
# number of gradient steps (docs/experiments/conservative-fine-tune.md).
FINE_TUNE_CONSERVATIVE = 0.1
FINE_TUNE_STEPS = 2000


def _tuple(v: Any) -> tuple:
    return tuple(v) if isinstance(v, (list, tuple)) else v


@dataclass(frozen=True)
class NetConfig:
    """Architecture of one Q-network column: Q(image, state, action) -> P(success)."""

    image_size: int = 64  # square input images (pixels)
    conv_channels: tuple[int, ...] = (32, 32, 64, 64)  # one conv layer each
    conv_strides: tuple[int, ...] = (2, 2, 2, 1)  # stride of each conv layer (kernel 3, padding 1)
    coord_channels: bool = True  # append x/y coordinate planes to the image (CoordConv)
    norm: str = "none"  # after each conv: "none" or "group" (GroupNorm, per sample, so CEM stays batch-independent)
    pool: str = "flatten"  # trunk output: "flatten" (position-specific), "max" (global max over positions), or
    # "spatial" (the state-action embedding is added to every position of the feature map, a 1x1 conv
    # follows, then a max over positions: QT-Opt's tile-and-add merge, evaluated per candidate)
    state_dim: int = STATE_DIM  # length of the gripper state vector the network reads
    hidden: int = 128  # width of the merged state-action layers
    head_layers: int = 2  # hidden layers evaluated once per candidate action
    action_dims: tuple[int, ...] = (0, 1, 3, 5)  # action components the network reads and CEM searches
    default_action: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, -1.0, -1.0)  # values of the other components
    columns: int = 1  # progressive-network columns; 1 is a plain network, k > 1 freezes the first k-1
    encoder: str = "conv"  # the trunk: "conv" (conv_channels, conv_strides) or a torchvision ResNet (ENCODERS)

    def __post_init__(self) -> None:
        for name in ("conv_channels", "conv_strides", "action_dims", "default_action"):
            object.__setattr__(self, name, _tuple(getattr(self, name)))
        if not isinstance(self.image_size, int) or not 16 <= self.image_size <= 256:
            raise ConfigError(f"net.image_size {self.image_size!r} is out of range; use 16..256 (64 is standard)")
        if not self.conv_channels or len(self.conv_channels) != len(self.conv_strides):
            raise ConfigError(
                f"net.conv_channels {self.conv_channels} and net.conv_strides {self.conv_strides} "
                "must be non-empty and of equal length (one entry per conv layer)"
            )
        if any(c < 1 for c in self.conv_channels) or any(s not in (1, 2) for s in self.conv_strides):
            raise ConfigError(
                f"net.conv_channels {self.conv_channels} must be positive and "
                f"net.conv_strides {self.conv_strides} each 1 or 2"
            )
        if self.norm not in NORMS:
            raise ConfigError(f"net.norm {self.norm!r} is unknown; use one of {NORMS}")
        if self.pool not in POOLS:
            raise ConfigError(f"net.pool {self.pool!r} is unknown; use one of {POOLS}")
        if self.hidden < 1 or self.head_layers < 1:
            raise ConfigError(f"net.hidden {self.hidden} and net.head_layers {self.head_layers} must be at least 1")
        dims = self.action_dims
        if (
            not dims
            or len(set(dims)) != len(dims)
            or any(not 0 <= d < ACTION_DIM for d in dims)
            or list(dims) != sorted(dims)
        ):
            raise ConfigError(
                f"net.action_dims {dims} must be distinct increasing indices in 0..{ACTION_DIM - 1} "
                "(0 dx, 1 dy, 2 dz, 3 dyaw, 4 close, 5 terminate)"
            )
        if len(self.default_action) != ACTION_DIM or any(not -1.0 <= v <= 1.0 for v in self.default_action):
            raise ConfigError(f"net.default_action {self.default_action} must hold {ACTION_DIM} values in [-1, 1]")
        if self.state_dim < 1:
            raise ConfigError(f"net.state_dim {self.state_dim} must be at least 1")
        if self.pool == "spatial" and self.columns > 1:
            raise ConfigError(
                "net.pool 'spatial' has no progressive-network laterals yet; use pool 'flatten' "
                "for the pnn and ft_pnn methods"
            )
        if self.columns < 1:
            raise ConfigError(f"net.columns {self.columns} must be at least 1")
        if self.encoder not in ENCODERS:
            raise ConfigError(f"net.encoder {self.encoder!r} is unknown; use one of {ENCODERS}")
        if self.encoder != "conv" and (self.columns > 1 or self.coord_channels or self.pool == "spatial"):
            raise ConfigError(
                f"net.encoder {self.encoder!r} reads the three colour channels and has no progressive-network "
                "laterals; use it with coord_channels false, one column and pool flatten or max"
            )

    @property
    def feature_dim(self) -> int:
        """Length of the trunk's output vector."""
        return self.feature_channels * (self.feature_size**2 if self.pool == "flatten" else 1)

    @property
    def feature_channels(self) -> int:
        """Channels of the trunk's output feature map."""
        return {"resnet18": 512, "resnet34": 512, "resnet50": 2048}.get(self.encoder, self.conv_channels[-1])

    @property
    def feature_size(self) -> int:
        """Side length of the trunk's output feature map."""
        n = self.image_size
        strides = (2,) * 5 if self.encoder != "conv" else self.conv_strides  # a ResNet halves it five times
        for s in strides:
            n = (n + 1) // s if s == 2 else n
        return n

    def to_dict(self) -> dict[str, Any]:
        d = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
        if d["encoder"] == "conv":
            del d["encoder"]  # absent means the conv trunk: architectures (and checkpoint ids) made before hold
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> NetConfig:
        return cls(**_known(cls, d, "architecture"))


@dataclass(frozen=True)
class CemConfig:
    """Cross-entropy method over the active action components (QT-Opt's defaults)."""

    samples: int = 64  # candidate actions per iteration
    elites: int = 6  # best candidates that refit the Gaussian
    iterations: int = 2
    init_std: float = 1.0  # standard deviation of the first Gaussian (mean 0), before clipping to [-1, 1]
    min_std: float = 0.05  # floor on the refitted standard deviation

    def __post_init__(self) -> None:
        if self.samples < 1 or self.iterations < 1:
            raise ConfigError(f"cem samples {self.samples} and iterations {self.iterations} must be at least 1")
        if not 1 <= self.elites <= self.samples:
            raise ConfigError(f"cem elites {self.elites} must be in 1..samples ({self.samples})")
        if self.init_std <= 0 or self.min_std < 0:
            raise ConfigError(f"cem init_std {self.init_std} must be positive and min_std {self.min_std} non-negative")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CemConfig:
        return cls(**_known(cls, d, "cem"))


@dataclass(frozen=True)
class TrainConfig:
    """One offline run (pre-training or fine-tuning) of a learner, QT-Opt by default."""

    steps: int = 20_000  # gradient steps (the run's total, also after a resume)
    batch_size: int = 64
    lr: float | None = None  # None: 3e-4 from scratch, 25% of the parent's learning rate when fine-tuning
    lr_decay: int = (
        0  # cosine decay of the learning rate to lr_floor * lr over this many steps, then flat; 0 = constant
    )
    lr_floor: float = 0.05  # the decayed learning rate as a fraction of lr
    weight_decay: float = 0.0
    grad_clip: float = 10.0  # max gradient norm; 0 disables clipping
    gamma: float = 0.9  # discount
    n_step: int = 1  # transitions span up to n steps of the data (n-step returns); the sampler must match
    # Target network 1, every step: theta_bar <- polyak * theta_bar + tau * theta, tau = 1 - polyak.  State one of
    # them (SB3 and d3rlpy state tau = 0.005); neither means polyak 0.995.  The stated one is recorded.
    polyak: float | None = None  # the fraction of the target kept (None when tau is stated)
    tau: float | None = None  # the fraction of the target updated toward the online network (None: polyak stated)
    lag_period: int = 1000  # target network 2: a copy of the online network, refreshed every lag_period steps
    cem: CemConfig = field(default_factory=CemConfig)  # action maximisation for the Bellman target
    conservative: float | None = None  # weight of scoring uniform random actions as failures (keeps unseen actions
    # down); 0 disables; None: 0 from scratch, FINE_TUNE_CONSERVATIVE when fine-tuning from a parent
    conservative_samples: int = 16  # uniform random actions per state for that term
    shrink_perturb: tuple[float, float] | None = None  # (alpha, sigma): fine-tuning starts from alpha * parent +
    # sigma * a fresh initialisation (Ash and Adams 2020); None keeps the parent's weights
    augment_crop: int = 4  # random-shift augmentation: pad by this many pixels and crop back; 0 disables
    augment_colour: float = 0.1  # colour jitter strength (brightness, contrast, per-channel gain); 0 disables
    seed: int = 0
    precision: str = "fp32"  # network passes: fp32, bf16 (CPU autocast; weights and optimiser stay fp32) or auto
    device: str = "cpu"  # where the arithmetic runs: cpu, cuda or auto (CUDA when torch sees a GPU); learners/device.py
    log_every: int = 100  # steps between metric rows (CSV and TensorBoard)
    checkpoint_every: int = 2000  # steps between checkpoints (a killed run resumes from the last one)
    eval_every: int = 0  # steps between eval_fn calls; 0 disables
    keep_trainer_state: int = 1  # how many of the newest checkpoints keep their trainer state (resume data)
    learner: str = "qtopt"  # the offline learner (learners/algorithm.py): qtopt, iql, or a plugin's name
    learner_options: dict[str, Any] = field(default_factory=dict)  # that learner's own settings

    def __post_init__(self) -> None:
        if isinstance(self.cem, dict):
            object.__setattr__(self, "cem", CemConfig.from_dict(self.cem))
        if self.steps < 0 or self.batch_size < 1:
            raise ConfigError(f"steps {self.steps} must be >= 0 and batch_size {self.batch_size} >= 1")
        if self.lr is not None and not 0 < self.lr < 1:
            raise ConfigError(f"learning rate {self.lr} is out of range; use e.g. 3e-4 (or leave it unset)")
        if not 0 <= self.gamma <= 1:
            raise ConfigError(f"gamma {self.gamma} must be in [0, 1]")
        self._check_target_rate()
        if self.lr_decay < 0 or not 0 <= self.lr_floor <= 1:
            raise ConfigError(
                f"lr_decay {self.lr_decay} must be >= 0 (0 = constant) and lr_floor {self.lr_floor} in [0, 1]"
            )
        if self.n_step < 1:
            raise ConfigError(f"n_step {self.n_step} must be at least 1 (1 = one-step QT-Opt)")
        if self.lag_period < 1 or self.log_every < 1 or self.checkpoint_every < 1 or self.eval_every < 0:
            raise ConfigError(
                "lag_period, log_every and checkpoint_every must be >= 1 and eval_every >= 0 "
                f"(got {self.lag_period}, {self.log_every}, {self.checkpoint_every}, {self.eval_every})"
            )
        if self.augment_crop < 0 or self.augment_colour < 0 or self.grad_clip < 0 or self.weight_decay < 0:
            raise ConfigError("augment_crop, augment_colour, grad_clip and weight_decay must be non-negative")
        if (self.conservative is not None and self.conservative < 0) or self.conservative_samples < 1:
            raise ConfigError(
                f"conservative {self.conservative} must be >= 0 and conservative_samples "
                f"{self.conservative_samples} >= 1"
            )
        if self.shrink_perturb is not None:
            sp = _tuple(self.shrink_perturb)
            if (
                not isinstance(sp, tuple)
                or len(sp) != 2
                or not all(isinstance(v, (int, float)) for v in sp)
                or not 0 < sp[0] <= 1
                or sp[1] < 0
            ):
                raise ConfigError(
                    f"shrink_perturb {sp!r} must be (alpha, sigma) with 0 < alpha <= 1 and sigma >= 0, e.g. (0.8, 0.01)"
                )
            object.__setattr__(self, "shrink_perturb", (float(sp[0]), float(sp[1])))
        if self.precision not in ("fp32", "bf16", "auto"):
            raise ConfigError(f"precision {self.precision!r} is unknown; use fp32, bf16 or auto")
        if self.device not in ("cpu", "cuda", "auto"):
            raise ConfigError(f"device {self.device!r} is unknown; use cpu, cuda or auto")
        if not isinstance(self.learner, str) or not self.learner:
            raise ConfigError(f"learner {self.learner!r} must be a learner's name, e.g. qtopt or iql")
        if not isinstance(self.learner_options, dict):
            raise ConfigError(f"learner_options {self.learner_options!r} must be a table of the learner's settings")
        if self.keep_trainer_state < 1:
            raise ConfigError(f"keep_trainer_state {self.keep_trainer_state} must be at least 1 (resume needs one)")

    def _check_target_rate(self) -> None:
        polyak, tau = self.polyak, self.tau
        if polyak is not None and tau is not None:
            raise ConfigError(f"polyak {polyak:g} and tau {tau:g} both given; state one of them (tau = 1 - polyak)")
        if tau is not None:
            if not 0 < tau < 1:
                raise ConfigError(f"tau {tau:g} is out of range; use (0, 0.5], e.g. 0.005")
            if tau > 0.5:
                raise ConfigError(
                    f"tau {tau:g} replaces {tau:.1%} of the target each step; "
                    f"you probably mean polyak={tau:g} (tau={1 - tau:g})"
                )
            return
        if polyak is None:
            object.__setattr__(self, "polyak", polyak := 0.995)
        if not 0 <= polyak < 1:
            raise ConfigError(f"polyak {polyak:g} is out of range; use [0.5, 1), e.g. 0.995 (or tau=0.005)")
        if polyak < 0.5:
            raise ConfigError(
                f"polyak {polyak:g} keeps only {polyak:.1%} of the target each step; "
                f"you probably mean tau={polyak:g} (polyak={1 - polyak:g})"
            )

    @property
    def target_polyak(self) -> float:
        """The fraction of the target network kept each step: ``polyak``, or ``1 - tau`` when tau was stated."""
        return self.polyak if self.polyak is not None else 1.0 - float(self.tau or 0.0)

    def lr_at(self, step: int) -> float:
        """The learning rate of gradient step ``step`` (0-based): ``lr``, cosine-decayed when ``lr_decay`` > 0."""
        if self.lr is None:
            raise ConfigError("lr is unresolved; resolve it (train() does) before asking for the schedule")
        if not self.lr_decay:
            return self.lr
        frac = min(step, self.lr_decay) / self.lr_decay
        return self.lr * (self.lr_floor + (1 - self.lr_floor) * 0.5 * (1 + math.cos(math.pi * frac)))

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["cem"] = self.cem.to_dict()
        if d["precision"] == "fp32":
            del d["precision"]  # absent means fp32: configs (and checkpoint ids) made before the option hold
        if d["device"] == "cpu":
            del d["device"]  # absent means the CPU, for the same reason
        del d["tau" if self.tau is None else "polyak"]  # the stated one: configs made before tau keep their ids
        if d["learner"] == "qtopt" and not d["learner_options"]:
            del d["learner"], d["learner_options"]  # absent means QT-Opt: the same for the learner interface
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        return cls(**_known(cls, d, "training"))

    def replace(self, **changes: Any) -> TrainConfig:
        """A copy with ``changes``; stating ``polyak`` or ``tau`` drops the other."""
        for one, other in (("polyak", "tau"), ("tau", "polyak")):
            if one in changes and other not in changes:
                changes[other] = None
        return dataclasses.replace(self, **changes)


FEATURE_LABELS = ("classes", "pose", "both")  # what the supervised trunk learns to predict (nsl.learners.features)


@dataclass(frozen=True)
class FeatureConfig:
    """Training the trunk on labelled frames: as a classifier, a pose regressor, or both."""

    steps: int = 3000  # gradient steps
    batch_size: int = 128
    lr: float = 1e-3  # Adam
    weight_decay: float = 1e-4
    augment_crop: int = 4  # random-shift augmentation (as in Q-learning)
    holdout: int = 2  # frames per class kept out of training to measure accuracy
    seed: int = 0
    label: str = "classes"  # classes | pose | both (FEATURE_LABELS)

    def __post_init__(self) -> None:
        if self.steps < 1 or self.batch_size < 1 or self.holdout < 0:
            raise ConfigError(
                f"features: steps {self.steps} and batch_size {self.batch_size} must be >= 1, holdout "
                f"{self.holdout} >= 0"
            )
        if not 0 < self.lr < 1:
            raise ConfigError(f"features: learning rate {self.lr} is out of range; use e.g. 1e-3")
        if self.label not in FEATURE_LABELS:
            raise ConfigError(f"features: label {self.label!r} is unknown; use one of {', '.join(FEATURE_LABELS)}")


def _known(cls: type, d: dict[str, Any], what: str) -> dict[str, Any]:
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(d) - names)
    if unknown:
        raise ConfigError(f"{what} config has unknown field(s) {unknown}; known fields: {sorted(names)}")
    return {k: _tuple(v) for k, v in d.items()}
