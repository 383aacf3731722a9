"""The catalog: datasets, checkpoints and evaluations with their lineage.

An append-only SQLite database (WAL) at ``$NSL_HOME/catalog.sqlite`` plus
checkpoint folders shaped like Hugging Face model repositories.  Public
surface (import from ``nsl.catalog``)::

    Catalog                                   # open it: Catalog() or Catalog(path)
    NO_CATALOG_ENV                            # "NSL_NO_CATALOG": 1 forbids a process to open it (cluster units)
      .register_dataset(name, version, path, *, hash, shift, episodes, provenance)
      .save_checkpoint(name, step, weights, config, *, parent, data, shift, card_info)
      .register_checkpoint(folder, *, name, step, parent, data, shift, card_info)
      .add_evaluation(checkpoint, shift, *, episodes, successes, seed, split, ci, extra)
      .resolve_checkpoint("ckpt:NAME@best"), .resolve_data("data:NAME@v2:800")
      .lineage(ref), .children(id), .trained_on(name, version), .tag(tag, ref), .untag(tag)
      .names(id)                              # every name of an entry (a re-run under a new name is an alias)
      .write_model_card(ref)
    DataUse, DatasetEntry, CheckpointEntry, EvaluationEntry, ResolvedData   # records
    parse_checkpoint_ref, parse_data_ref, best_checkpoint                    # references
    write_model_folder, checkpoint_id, folder_checkpoint_id, folder_digests  # model folders
    render_model_card
    format_lineage, format_descendants                                       # text trees (catalog/lineage.py)
    remove, gc_plan, gc_apply, verify                                        # maintenance
    Origin, record_origin, origin_of, published_lineage                      # pulled entries
    SCHEMA_VERSION, MIGRATIONS, wilson_interval

``ckpt:base`` falls back to the checkpoint shipped in ``nsl/assets/base``:
the first reference registers it, with the datasets its ``command.json``
records.  The folder format is ``nsl.checkpoint_format``'s, shared with the
learner.  The folder is a leaf: it imports no other nsl folder.
"""

from .folders import (
    CARD_FILE,
    CONFIG_FILE,
    WEIGHTS_FILE,
    checkpoint_id,
    folder_checkpoint_id,
    folder_digests,
    write_model_folder,
)
from .lineage import format_descendants, format_lineage
from .maintenance import GcItem, Problem, VerifyReport, gc_apply, gc_plan, remove, verify
from .origins import Origin, origin_of, published_lineage, record_origin
from .records import (
    CheckpointEntry,
    CheckpointRef,
    DataRef,
    DatasetEntry,
    DataUse,
    EvaluationEntry,
    ResolvedData,
    parse_checkpoint_ref,
    parse_data_ref,
    short_hash,
    wilson_interval,
)
from .render import render_model_card
from .schema import MIGRATIONS, SCHEMA_VERSION
from .store import NO_CATALOG_ENV, Catalog, best_checkpoint

__all__ = [
    "CARD_FILE",
    "NO_CATALOG_ENV",
    "CONFIG_FILE",
    "WEIGHTS_FILE",
    "Catalog",
    "CheckpointEntry",
    "CheckpointRef",
    "DataRef",
    "DataUse",
    "DatasetEntry",
    "EvaluationEntry",
    "GcItem",
    "MIGRATIONS",
    "Origin",
    "Problem",
    "ResolvedData",
    "SCHEMA_VERSION",
    "VerifyReport",
    "best_checkpoint",
    "checkpoint_id",
    "folder_checkpoint_id",
    "folder_digests",
    "format_descendants",
    "format_lineage",
    "gc_apply",
    "gc_plan",
    "origin_of",
    "parse_checkpoint_ref",
    "parse_data_ref",
    "published_lineage",
    "record_origin",
    "remove",
    "render_model_card",
    "short_hash",
    "verify",
    "wilson_interval",
    "write_model_folder",
]
