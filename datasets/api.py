"""Public surface of ``nsl.datasets``: versioned episode datasets in LeRobot v3.0 layout.

Other folders import only this module (``from nsl.datasets import api``)::

    parse_ref, resolve, dataset_names, list_versions     # references NAME[@vN][:K]
    dataset_root                                         # $NSL_HOME/datasets/NAME (versions, .staging)
    open_version, open_view, episode_split               # reading (DatasetVersion, DatasetView)
    frame_labels, FrameLabels                            # per-frame success, next-frame masks, MC returns
    Collection, write_dataset, unfinished                # writing (resumable, append-only)
    make_sampler, Sampler                                # the training loader
    verify, tiers, list_datasets, export                 # maintenance
    to_hf_dataset                                        # an Arrow-backed Hugging Face datasets.Dataset

The learner's contract: ``make_sampler([(ref, weight), ...])`` returns an object
with ``sample(batch_size, rng) -> dict`` (keys from ``nsl.keys``), ``__len__``
(transitions) and ``describe()``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from . import layout
from .collection import Collection, unfinished, write_dataset
from .export import export as _export
from .hf import to_hf_dataset
from .labels import FrameLabels, frame_labels
from .loader import Sampler, TransitionSource, image_cache, make_sampler
from .reader import DatasetVersion, DatasetView, open_version, open_view
from .versions import STANDARD_TIERS, Ref, dataset_names, dataset_root, list_versions, parse_ref, resolve
from .versions import verify as _verify
from .writer import EpisodeLike

__all__ = [
    "Collection",
    "DatasetVersion",
    "DatasetView",
    "EpisodeLike",
    "FrameLabels",
    "frame_labels",
    "Ref",
    "STANDARD_TIERS",
    "Sampler",
    "TransitionSource",
    "dataset_names",
    "dataset_root",
    "episode_split",
    "export",
    "image_cache",
    "layout",
    "list_datasets",
    "list_versions",
    "make_sampler",
    "open_version",
    "open_view",
    "parse_ref",
    "resolve",
    "tiers",
    "to_hf_dataset",
    "unfinished",
    "verify",
    "write_dataset",
]


def verify(ref: str) -> dict[str, Any]:
    """Re-hash every file of a version; CorruptDataError names the first bad file."""
    r, root = resolve(ref)
    assert r.version is not None  # resolve() fills in the version
    label = f"{r.name}@v{r.version}"
    h = _verify(root, label=label)
    v = DatasetVersion(r.name, r.version, root)
    v.episodes  # noqa: B018  # metadata must agree with info.json
    return {"ref": label, "hash": h, "files": len(v.manifest["files"]), "episodes": v.num_episodes}


def episode_split(ref: str | DatasetView, holdout: int | float) -> tuple[DatasetView, DatasetView]:
    """(train, held-out) views: the held-out part is the last ``holdout`` episodes (or that fraction).

    Tiers are prefixes, so a tier of the train view never contains held-out episodes.
    """
    return open_view(ref).split(holdout)


def tiers(ref: str, sizes: tuple[int, ...] = STANDARD_TIERS) -> list[dict[str, Any]]:
    """The nested first-K views of a version that fit in it (plus the whole version)."""
    v = open_version(ref)
    ks = sorted({k for k in sizes if k <= v.num_episodes} | {v.num_episodes})
    return [v.view(0, k).describe() for k in ks]


def list_datasets() -> list[dict[str, Any]]:
    """One summary per published version, every dataset."""
    out = []
    for name in dataset_names():
        for ver in list_versions(name):
            v = open_version(f"{name}@v{ver}")
            spec = v.provenance["collections"][-1]["spec"]
            out.append(
                {
                    "ref": v.ref,
                    "hash": v.hash,
                    "episodes": v.num_episodes,
                    "frames": v.num_frames,
                    "success_rate": float(v.episodes.success.mean()),
                    "shift": spec.get("env", {}).get("shift"),
                    "policy": spec.get("policy_ref"),
                    "created": v.manifest.get("created", {}).get("time"),
                }
            )
    return out


def export(ref: str | DatasetView, out: Path, repo_id: str | None = None) -> Path:
    """Write a version or tier as a plain LeRobot v3.0 directory (see :mod:`.export`)."""
    return _export(open_view(ref), Path(out), repo_id)
