"""Glue: turn command-line references into objects from the folders.

``policy_factory`` maps a policy reference to a picklable zero-argument
callable that builds the policy inside each worker process.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import Any

_PINNED: dict[str, Any] = {}  # ref -> CheckpointEntry resolved elsewhere (a cluster unit's driver): see pin()


def pin(entries: Mapping[str, Any]) -> None:
    """Resolve these checkpoint references to these catalog entries in this process, without the catalog.

    A study unit on a cluster node gets them from its driver (which alone opens the catalog); ``pin({})``
    forgets them.
    """
    _PINNED.clear()
    _PINNED.update(entries)


def pinned(ref: str):
    """The entry pinned for ``ref``, else None."""
    return _PINNED.get(ref)


def policy_factory(
    ref: str,
    env_config,
    epsilon: float = 0.0,
    action_noise: float = 0.0,
    precision: str = "fp32",
    device: str = "cpu",
) -> Callable:
    """``random`` | ``oracle[:NOISE]`` | ``ckpt:NAME[@...]`` -> a picklable policy factory.

    A checkpoint becomes its CEM policy (``nsl.learners.load_policy``), built
    once in each worker; ``epsilon`` adds epsilon-greedy exploration,
    ``action_noise`` Gaussian noise on every action, and ``precision`` is what
    its network computes in and ``device`` where (``auto`` is resolved here, once, for every worker).  On a
    GPU each worker process (started by a fork server, never forked from a process that holds CUDA) acts in
    batches there.
    """
    if ref.startswith("ckpt:") or ref == "base":
        from nsl.catalog import Catalog
        from nsl.learners import load_policy
        from nsl.learners.device import resolve_device
        from nsl.learners.precision import resolve_precision

        entry = pinned(ref)
        device = resolve_device(device)
        if entry is None:
            with Catalog() as cat:
                entry = resolve_init(cat, ref)
        factory = functools.partial(
            load_policy,
            str(entry.path),
            epsilon=epsilon,
            action_noise=action_noise,
            precision=resolve_precision(precision, device),
            **({} if device == "cpu" else {"device": device}),
        )
    else:
        from nsl.collectors import scripted_policy

        factory = functools.partial(
            scripted_policy,
            ref,
            control=env_config.control,
            move_step=env_config.move_step,
            yaw_step=env_config.yaw_step,
        )
    factory()  # validate the reference now, before any worker starts
    return factory


def dataset_uses(cat, mix: list[tuple[str, float]]) -> list:
    """Resolve ``[(NAME[@vN][:TIER], weight)]`` to catalog ``DataUse`` records.

    A dataset version that exists on disk but is not yet in the catalog is
    registered first (the dataset folder is the record of truth); with
    ``cat=None`` nothing is registered (whoever registers the run does).
    """
    from nsl.catalog import DataUse
    from nsl.datasets import api
    from nsl.errors import UnknownReferenceError

    uses = []
    for ref, weight in mix:
        view = api.open_view(ref)
        v = view.version
        try:
            known = cat is None or cat.dataset(v.name, v.version).hash == v.hash
        except UnknownReferenceError:
            known = False
        if not known:  # (a different hash under that version is refused by the catalog)
            register_dataset(cat, v)
        uses.append(DataUse(v.name, v.version, weight=weight, tier=api.parse_ref(ref).tier, hash=v.hash))
    return uses


def register_dataset(cat, version) -> None:
    """Record a dataset version (``nsl.datasets`` DatasetVersion) in the catalog; idempotent."""
    spec = version.provenance["collections"][-1]["spec"]
    cat.register_dataset(
        version.name,
        version.version,
        version.root,
        hash=version.hash,
        shift=spec.get("env", {}).get("shift_spec", spec.get("env", {}).get("shift", "base")),
        episodes=version.num_episodes,
        provenance=version.provenance,
    )


def resolve_init(cat, ref: str):
    """A parent checkpoint from the catalog (``ckpt:base`` falls back to the one shipped with nsl), or pinned."""
    entry = pinned(ref)
    return entry if entry is not None else cat.resolve_checkpoint(ref)


def transfer_matrix(matrix=None, transfer: str | None = None):
    """The matrix.json named by a path (``matrix``) or by a transfer's name (its ``$NSL_HOME/transfers/NAME/``)."""
    from pathlib import Path

    if matrix is not None:
        return Path(matrix)
    from nsl import workspace
    from nsl.errors import UnknownReferenceError

    path = workspace.home() / "transfers" / str(transfer) / "matrix.json"
    if not path.is_file():
        raise UnknownReferenceError(
            f"transfer {transfer!r} has no matrix in {workspace.home()}; run "
            f"`nsl transfer run PLAN` (or `nsl transfer report {transfer}`) first"
        )
    return path


def open_run(name: str, config):
    """The run folder ``$NSL_HOME/runs/NAME`` of a pipeline, holding ``config`` (a dataclass) as config.json.

    A run of that name with another configuration is refused, so running the same call again resumes it.
    A setting added after the run was made matches it at its default (e.g. ``OnlineConfig.num_envs``).
    """
    import json
    from dataclasses import MISSING, asdict, fields

    from nsl import workspace
    from nsl.errors import ConfigError

    run_dir = workspace.runs_dir() / name
    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / "config.json"
    want = json.loads(json.dumps(asdict(config)))
    defaults = json.loads(json.dumps({f.name: f.default for f in fields(config) if f.default is not MISSING}))
    stored = json.loads(path.read_text()) if path.exists() else want
    stored.update({k: v for k, v in want.items() if k not in stored and k in defaults and v == defaults[k]})
    if stored != want:
        raise ConfigError(
            f"run {name!r} exists with a different configuration ({path}); "
            "use another --name or the same options to resume"
        )
    workspace.atomic_write_json(path, asdict(config))
    return run_dir
