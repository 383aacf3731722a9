"""Sharing: move a dataset version or a checkpoint to and from a remote, hash-verified.

A remote is the Hugging Face Hub (``hf://datasets/OWNER/NAME`` for datasets,
``hf://OWNER/NAME`` for models) or any fsspec URL (``s3://bucket/prefix``,
``gs://...``, ``file:///path`` or a plain path).  Every item travels with a
manifest of per-file sha256 digests; a pull checks each file against it before
the caller registers anything, downloads under a temporary name and renames,
and skips files it already verified (so a killed pull resumes).  A push
compares with the manifest already on the remote and uploads only what differs
(so pushing the same version twice uploads nothing).

This package knows nothing of the workspace or the catalog: it is given folders
and metadata, and the CLI (``nsl push``, ``nsl pull``) wires it to the rest::

    push_dataset(root, name=..., version=..., dest=..., card=...)   -> PushResult
    push_checkpoint(folder, dest=..., card=..., checkpoint=..., lineage=...)   -> PushResult
    pull(src, staging_root)                                          -> Pulled
    dataset_card(...), parse_remote(url)
    store.Store(url).push(home, rel) / .pull(home, rel)              # study units' folders (--store)
"""

from .cards import dataset_card
from .remotes import Location, parse_remote
from .transfer import Pulled, PushResult, pull, push_checkpoint, push_dataset

__all__ = [
    "Location",
    "PushResult",
    "Pulled",
    "dataset_card",
    "parse_remote",
    "pull",
    "push_checkpoint",
    "push_dataset",
]
