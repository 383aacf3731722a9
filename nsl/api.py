"""The Python API: one function per user action, the same ones the ``nsl`` command line calls.

::

    import nsl

    data = nsl.collect(shift="harsh_lighting", episodes=800, policy="ckpt:base", data="grasp-harsh", epsilon=0.1)
    run = nsl.train(data=["grasp-base=0.5", f"{data.ref}=0.5"], init="ckpt:base", name="harsh")
    result = nsl.evaluate(run.checkpoint, shift="base,harsh_lighting", episodes=200, seed=nsl.REPORTING_SCENES)

Each function takes its settings either as one config object
(``nsl.CollectConfig``, ``nsl.TrainOptions``, ...) or as keyword arguments
with the same names as the command line's options; a config plus keywords
changes those fields.  Defaults live in the config dataclasses only
(``nsl.services.options``).  Every result names what the call wrote: a
dataset version (``ref``, ``hash``), a checkpoint (``checkpoint``, ``id``),
catalogued evaluations, a run folder or a report.

``import nsl`` stays cheap: this module is loaded on the first use of one of
these names, and each function loads what it needs when called.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from nsl import _API
from nsl.errors import ConfigError
from nsl.scenes import EVAL_SCENES, FINAL_REPORTING_SCENES, REPORTING_SCENES, SELECTION_SCENES  # noqa: F401  (re-exported)
from nsl.services.compare import compare  # noqa: F401  (re-exported: nsl.compare; imports nothing heavy)
from nsl.services.options import (
    CollectConfig,
    ContinualConfig,
    EfficiencyConfig,
    EvaluateOptions,
    FeaturesConfig,
    OnlineConfig,
    TrainOptions,
)

if TYPE_CHECKING:
    from nsl.learners import LeRobotActing
    from nsl.services.continual import ContinualResult
    from nsl.services.evaluate import EvaluationResult
    from nsl.services.features import FeaturesResult
    from nsl.services.online import OnlineResult
    from nsl.services.share import Pulled, Pushed
    from nsl.services.train import TrainResult

C = TypeVar("C")

__all__ = list(_API)  # the names `import nsl` offers (nsl/__init__.py lists them without importing this module)


def _settle(cls: type[C], config: C | None, fields: Mapping[str, Any], call: str) -> C:
    """``config`` with ``fields`` changed, or a new ``cls(**fields)``; unknown names fail in one line."""
    known = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    if "batch_size" in fields and "num_envs" in known:  # environments per worker: batch_size in nsl 0.1
        import warnings

        warnings.warn(
            f"nsl.{call}(batch_size=...) is now num_envs=...; the old name will go away", FutureWarning, stacklevel=3
        )
        fields = {**{k: v for k, v in fields.items() if k != "batch_size"}, "num_envs": fields["batch_size"]}
    unknown = sorted(set(fields) - known)

    if unknown:
        raise ConfigError(
            f"nsl.{call}() has no setting {', '.join(unknown)}; the settings are {', '.join(sorted(known))}"
        )
    if config is None:
        return cls(**fields)
    if not isinstance(config, cls):
        raise ConfigError(f"nsl.{call}() takes a {cls.__name__}, not {type(config).__name__}")
    return dataclasses.replace(config, **fields)  # type: ignore[type-var]


# --- datasets, training, evaluation ---------------------------------------------------------------------------------


def collect(
    config: CollectConfig | None = None,
    /,
    *,
    restart: bool = False,
    cluster: str | None = None,
    progress: bool = True,
    wait: bool = False,
    **fields: Any,
):
    """Collect episodes into a versioned dataset (``nsl collect``); returns the published DatasetVersion.

    The result's ``ref`` (``NAME@vN``), ``hash``, ``num_episodes`` and ``root`` name what was written; the version
    is registered in the catalog.  Calling it again resumes an interrupted collection.  While another process
    writes the dataset this raises :class:`~nsl.errors.LockedError` naming it; ``wait=True`` waits for it.
    """
    from nsl.services.collect import collect as run

    return run(
        _settle(CollectConfig, config, fields, "collect"),
        restart=restart,
        cluster=cluster,
        progress=progress,
        wait=wait,
    )


def train(
    options: TrainOptions | None = None, /, *, progress: bool = True, wait: bool = False, **fields: Any
) -> TrainResult:
    """Pre-train (no ``init``) or fine-tune (``init="ckpt:..."``) offline, and catalogue it (``nsl train``).

    ``data`` is a list of ``"REF[=WEIGHT]"`` strings or ``(ref, weight)`` pairs; ``net`` a list of
    ``"FIELD=VALUE"`` strings or a mapping.  Returns a :class:`~nsl.services.train.TrainResult` whose
    ``checkpoint`` (``ckpt:NAME@STEP``) and ``id`` name the catalogued checkpoint, and ``best`` the step early
    stopping chose.  While another process writes run ``name`` this raises :class:`~nsl.errors.LockedError`
    naming it; ``wait=True`` waits for it.
    """
    from nsl.services.train import train as run

    if "data" in fields:
        fields["data"] = tuple(d if isinstance(d, str) else f"{d[0]}={d[1]}" for d in fields["data"])
    if "net" in fields:
        net = fields["net"]
        fields["net"] = (
            tuple(f"{k}={','.join(map(str, v)) if isinstance(v, (list, tuple)) else v}" for k, v in net.items())
            if isinstance(net, Mapping)
            else tuple(net)
        )
    return run(_settle(TrainOptions, options, fields, "train"), progress=progress, wait=wait)


def evaluate(
    policies: str | Sequence[str],
    options: EvaluateOptions | None = None,
    /,
    *,
    progress: bool = True,
    cluster: str | None = None,
    source: str | None = None,
    **fields: Any,
) -> EvaluationResult:
    """Success rates with 95% intervals per shift (``nsl eval``); checkpoint results are stored in the catalog.

    ``policies`` is one reference or several (``ckpt:NAME[@STEP]``, ``oracle[:NOISE]``, ``random``).  Returns an
    :class:`~nsl.services.evaluate.EvaluationResult`: ``table[ref][shift]`` is a SuccessRate, ``paired`` holds
    McNemar's test for two policies, ``stored`` the catalog ids whose evaluations were recorded.
    """
    from nsl.services.evaluate import evaluate as run

    refs = [r.strip() for r in policies.split(",")] if isinstance(policies, str) else list(policies)
    return run(
        [r for r in refs if r],
        _settle(EvaluateOptions, options, fields, "evaluate"),
        progress=progress,
        source=source,
        cluster=cluster,
    )


def load_policy(
    source: str | Path,
    /,
    *,
    epsilon: float = 0.0,
    action_noise: float = 0.0,
    precision: str = "fp32",
    seed: int = 0,
    **cem: Any,
) -> LeRobotActing:
    """A checkpoint's policy, from a folder, a catalog reference (``ckpt:NAME[@STEP|@best]``) or a shared
    checkpoint (a Hub repo id ``OWNER/NAME``, ``hf://OWNER/NAME[@REV]``, ``s3://...``), as ``from_pretrained``
    loads a model; a shared one is pulled and hash-verified into the workspace's cache, not catalogued.

    It acts as nsl's policies do, ``policy(obs, rngs=...)`` on ``{"image", "state"}`` numpy batches, and as
    LeRobot's do, ``policy.select_action(batch)`` on ``observation.image`` / ``observation.state`` tensors
    (``seed`` seeds its draws; ``reset()`` starts them over).  ``epsilon``, ``action_noise``, ``precision``
    and CEM settings (``cem``) are those of ``nsl.learners.load_policy``.
    """
    from nsl.learners import LeRobotActing
    from nsl.learners import load_policy as load
    from nsl.services.share import checkpoint_folder

    folder = checkpoint_folder(source)
    policy = load(folder, epsilon=epsilon, action_noise=action_noise, precision=precision, **cem)
    return LeRobotActing(policy, seed=seed)


def continual(
    config: ContinualConfig | None = None,
    /,
    *,
    name: str = "continual",
    progress: bool = True,
    wait: bool = False,
    **fields: Any,
) -> ContinualResult:
    """Fine-tune through a sequence of shifts; the performance matrix, forgetting and transfer (``nsl continual``).

    ``sequence`` is a list of shift specs (or one comma-separated string).  Resumes a run of the same ``name``.
    """
    from nsl.services.continual import continual as run

    if isinstance(fields.get("sequence"), str):
        fields["sequence"] = tuple(s.strip() for s in fields["sequence"].split(",") if s.strip())
    elif "sequence" in fields:
        fields["sequence"] = tuple(fields["sequence"])
    return run(_settle(ContinualConfig, config, fields, "continual"), name, progress=progress, wait=wait)


def online(
    config: OnlineConfig | None = None,
    /,
    *,
    name: str = "online",
    progress: bool = True,
    wait: bool = False,
    **fields: Any,
) -> OnlineResult:
    """Online fine-tuning in rounds: the policy collects in the target shift and is fine-tuned on everything
    collected so far, mixed with base data (``nsl online``).  Resumes a run of the same ``name``."""
    from nsl.services.online import online as run

    for key in ("base_data",):
        if isinstance(fields.get(key), str):
            fields[key] = (fields[key],)
        elif key in fields:
            fields[key] = tuple(fields[key])
    return run(_settle(OnlineConfig, config, fields, "online"), name, progress=progress, wait=wait)


def features(
    config: FeaturesConfig | None = None,
    /,
    *,
    name: str = "features",
    progress: bool = True,
    wait: bool = False,
    **fields: Any,
) -> FeaturesResult:
    """Supervised features (``nsl features``): the trunk of ``like``'s architecture trained to classify the 899
    train objects from rendered frames, or a torchvision ResNet from ``encoder=PATH``, catalogued as
    ``ckpt:NAME``; fine-tune it with ``method="new_head"`` or ``"new_head_frozen"``."""
    from nsl.services.features import features as run

    return run(_settle(FeaturesConfig, config, fields, "features"), name, progress=progress, wait=wait)


def efficiency(
    config: EfficiencyConfig | None = None,
    /,
    *,
    name: str = "efficiency",
    progress: bool = True,
    wait: bool = False,
    **fields: Any,
):
    """Fine-tune on each tier of the target data and evaluate (``nsl efficiency``); returns the TierResults.

    The results are in ``$NSL_HOME/runs/NAME/tiers.json``; a run of the same ``name`` resumes.
    """
    from nsl.services.efficiency import efficiency as run

    for key in ("data", "sizes"):
        if key in fields:
            fields[key] = tuple(fields[key])
    return run(_settle(EfficiencyConfig, config, fields, "efficiency"), name, progress=progress, wait=wait)


def report(run: str | Path, *, out: str | Path | None = None, title: str | None = None):
    """Markdown and PNG plots of a run's records (``nsl report``): curves, performance matrix, tiers.

    ``run`` is a run folder or a run name under ``$NSL_HOME/runs``.  Returns the ReportResult (``markdown``,
    ``figures``).
    """
    from nsl import workspace
    from nsl.eval import write_report

    path = Path(run)
    if not path.is_dir() and (workspace.runs_dir() / str(run)).is_dir():
        path = workspace.runs_dir() / str(run)
    return write_report(path, out, title=title)


# --- sharing --------------------------------------------------------------------------------------------------------


def push(ref: str, dest: str) -> Pushed:
    """Publish ``data:NAME@vN`` or ``ckpt:NAME[@STEP]`` to the Hub or an fsspec remote (``nsl push``)."""
    from nsl.services.share import push as run

    return run(ref, dest)


def pull(src: str, *, as_name: str | None = None) -> Pulled:
    """Bring a shared dataset version or checkpoint into the workspace, verified and catalogued (``nsl pull``)."""
    from nsl.services.share import pull as run

    return run(src, as_name)


# --- the study, transfer and curricula ------------------------------------------------------------------------------


@dataclass(frozen=True)
class StudyRun:
    """A study or transfer run: its name, folder, report and the scheduler's status record."""

    name: str
    folder: Path
    report: Path
    status: dict[str, Any]


def study_run(
    plan: str,
    *,
    name: str | None = None,
    workers: int = 1,
    progress: bool = True,
    cluster: str | None = None,
    unit_cpus: float = 1.0,
    store: str | None = None,
    wait: bool = False,
) -> StudyRun:
    """Run (or resume) a study plan (``tiny``, ``small``, ``full``, ``paper`` or a TOML path) and write its report.

    ``cluster`` (``ray``, ``auto``, ``ray://HOST:PORT``; None: ``$NSL_CLUSTER``, else local) runs every unit as a
    Ray task holding ``unit_cpus`` CPUs; ``store`` (an fsspec URL; None: ``$NSL_STORE``) is for nodes that share
    no ``NSL_HOME`` (docs/scale.md).  While another process runs the study this raises
    :class:`~nsl.errors.LockedError` naming it; ``wait=True`` waits for it, then resumes."""
    from nsl.study import run_study, study_dir

    status = run_study(
        plan, name, workers=workers, progress=progress, cluster=cluster, unit_cpus=unit_cpus, store=store, wait=wait
    )
    folder = study_dir(status["study"])
    return StudyRun(status["study"], folder, folder / "report.md", status)


def study_status(name: str) -> dict[str, Any]:
    """Units done, running and left, with the time spent (``nsl study status``)."""
    from nsl.study import study_status as status

    return status(name)


def study_report(name: str) -> Path:
    """Write a study's report.md and plots from the units finished so far; returns the report's path."""
    from nsl.study import write_study_report

    return write_study_report(name)


def transfer_run(
    plan: str,
    *,
    name: str | None = None,
    workers: int = 1,
    progress: bool = True,
    cluster: str | None = None,
    unit_cpus: float = 1.0,
    store: str | None = None,
    wait: bool = False,
) -> StudyRun:
    """Measure a transfer-advantage matrix (``nsl transfer run``); the report holds matrix.json and matrix.md.

    ``cluster``, ``unit_cpus``, ``store`` and ``wait`` as for :func:`study_run`."""
    from nsl.study import run_transfer

    status, report = run_transfer(
        plan, name, workers=workers, progress=progress, cluster=cluster, unit_cpus=unit_cpus, store=store, wait=wait
    )
    folder = Path(report["matrix"]).parent
    return StudyRun(folder.name, folder, Path(report["report"]), {**status, "report": report})


def transfer_report(name: str) -> dict[str, Any]:
    """Write matrix.json and matrix.md of a transfer from the runs finished so far; returns their paths."""
    from nsl.study import write_transfer_report

    return write_transfer_report(name)


@dataclass(frozen=True)
class Curriculum:
    """The optimal and pessimal curricula of a transfer matrix, with the matrix read and the picture written."""

    trees: Any  # nsl.curriculum's result: .lines(), .to_dict()
    matrix: Path
    picture: Path


def build_curriculum(
    *,
    matrix: str | Path | None = None,
    transfer: str | None = None,
    tasks: Sequence[str] | None = None,
    out: str | Path | None = None,
) -> Curriculum:
    """The cheapest order to learn ``tasks`` from a transfer matrix (``nsl curriculum``): give ``matrix`` (a
    matrix.json) or ``transfer`` (a transfer's name)."""
    from nsl.curriculum import build_curriculum as build
    from nsl.curriculum import load_matrix, plot_curriculum
    from nsl.services.refs import transfer_matrix

    if (matrix is None) == (transfer is None):
        raise ConfigError("build_curriculum needs exactly one of matrix= (a matrix.json) or transfer= (a name)")
    path = transfer_matrix(matrix, transfer)
    trees = build(load_matrix(path), list(tasks) if tasks else None)
    picture = plot_curriculum(trees, Path(out) if out else path.parent / "curriculum.png")
    return Curriculum(trees, path, picture)
