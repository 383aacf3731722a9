"""The catalog: datasets, checkpoints, evaluations and tags in one SQLite file.

Entries are append-only.  Registering what is already there (same dataset
name, version and hash; same checkpoint id; same evaluation) returns the
existing entry (the same checkpoint under a new name gains that name as an
alias); registering something different under an existing key is refused;
nothing updates a row.  Tags are pointers and may move, but every
move is a new row, so their history is kept too.

Every write is one ``BEGIN IMMEDIATE`` transaction, so several collection,
training and evaluation processes can register at the same time: they queue
for the write lock (busy timeout plus retries) and never lose an entry.
Files come first: a checkpoint folder or dataset folder is complete on disk
before the row that points to it is committed.

Usage::

    from nsl.catalog import Catalog

    with Catalog() as cat:                       # $NSL_HOME/catalog.sqlite
        base = cat.resolve_data("data:grasp-base@v1")
        entry = cat.save_checkpoint("base", 20000, weights_bytes, config, data=[base.use(1.0)])
        cat.add_evaluation(entry.id, "base", episodes=100, successes=83, seed=1000)
"""

from __future__ import annotations

import functools
import json
import os
import re
import sqlite3
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from nsl import workspace
from nsl.errors import ConfigError, UnknownReferenceError, unknown
from nsl.stats import wilson_interval
from nsl.version import code_version as _current_code_version

from . import schema
from .folders import (
    WEIGHTS_FILE,
    checkpoint_id,
    content_digests,
    encode_config,
    folder_checkpoint_id,
    folder_digests,
    hash_tree,
    read_config,
    write_card,
    write_model_folder,
)
from .records import (
    CKPT_PREFIX,
    HEX_RE,
    RESERVED,
    CheckpointEntry,
    DatasetEntry,
    DataUse,
    EvaluationEntry,
    ResolvedData,
    check_name,
    dumps,
    parse_checkpoint_ref,
    parse_data_ref,
    short_hash,
)
from .render import render_model_card

SHIPPED_BASE = "base"  # ckpt:base falls back to the checkpoint shipped in nsl/assets/base
SHIPPED_RECORD = "command.json"  # the training command recorded beside the shipped weights


@functools.cache
def _code_version() -> str:
    return _current_code_version()


NO_CATALOG_ENV = "NSL_NO_CATALOG"  # "1": this process must not open the catalog (a study unit on a cluster node)


class Catalog:
    """An open catalog.  One per process (open it again after fork); close it or use ``with``.

    A process with ``$NSL_NO_CATALOG=1`` may not open it (a study's unit on a cluster node: its driver resolves
    the references the unit needs and registers what it made, since SQLite in WAL mode must not be shared across
    machines).
    """

    def __init__(self, path: Path | str | None = None):
        self.path = Path(path) if path is not None else workspace.catalog_path()
        if os.environ.get(NO_CATALOG_ENV) == "1":
            raise ConfigError(
                f"this process may not open the catalog {self.path} (${NO_CATALOG_ENV}=1: a study unit whose "
                "driver resolves its references and registers its outputs); open it on the driver"
            )
        self.conn = schema.connect(self.path, code_version=_code_version())

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> Catalog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def write(self) -> Iterator[sqlite3.Connection]:
        """One write transaction holding the database's write lock from its first statement."""
        schema.begin_immediate(self.conn)
        try:
            yield self.conn
            self.conn.execute("COMMIT")
        except BaseException:
            self.conn.execute("ROLLBACK")
            raise

    # ---------------------------------------------------------------- paths
    @staticmethod
    def _store_path(path: Path) -> str:
        """Paths under the workspace are stored relative to it, so NSL_HOME can move."""
        path = Path(path).resolve()
        try:
            return path.relative_to(workspace.home().resolve()).as_posix()
        except ValueError:
            return str(path)

    @staticmethod
    def _load_path(stored: str) -> str:
        p = Path(stored)
        return str(p if p.is_absolute() else workspace.home().resolve() / p)

    # ------------------------------------------------------------- datasets
    def register_dataset(
        self,
        name: str,
        version: int,
        path: Path | str,
        *,
        hash: str,
        shift: Mapping[str, Any] | str,
        episodes: int,
        provenance: Mapping[str, Any] | None = None,
    ) -> DatasetEntry:
        """Record a dataset version that is complete on disk at ``path``.

        ``hash`` is the content hash from the dataset's manifest; ``shift``
        the shift spec dict (``ShiftSpec.to_dict()``) or just its name.  The
        catalog also records a sha256 of every file under ``path`` for
        ``verify``.  Idempotent for the same hash; a different hash under an
        existing name and version is refused.
        """
        check_name("dataset", name)
        if not isinstance(version, int) or version < 1:
            raise ConfigError(f"dataset version {version!r} for {name!r} must be an integer >= 1")
        if not isinstance(hash, str) or not hash:
            raise ConfigError(f"dataset {name}@v{version} needs its content hash (from its manifest)")
        if not isinstance(episodes, int) or episodes < 0:
            raise ConfigError(f"episodes {episodes!r} for dataset {name}@v{version} must be an integer >= 0")
        shift_d = {"name": shift} if isinstance(shift, str) else dict(shift)
        if not isinstance(shift_d.get("name"), str):
            raise ConfigError(f"shift {shift!r} for dataset {name}@v{version} needs a 'name' (e.g. 'base')")
        path = Path(path)
        if not path.exists():
            raise ConfigError(f"dataset path {path} does not exist; write the dataset before registering it")
        files = hash_tree(path)
        row = (
            name,
            version,
            hash,
            dumps(shift_d),
            episodes,
            dumps(dict(provenance or {})),
            self._store_path(path),
            dumps(files),
            schema.utc_now(),
        )
        with self.write() as c:
            old = c.execute("SELECT * FROM datasets WHERE name = ? AND version = ?", (name, version)).fetchone()
            if old is None:
                c.execute(
                    "INSERT INTO datasets (name, version, hash, shift, episodes, provenance, path, files, "
                    "created) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    row,
                )
        if old is not None:
            existing = self._dataset_row(old)
            if existing.hash != hash:
                raise ConfigError(
                    f"dataset {name}@v{version} is already registered with hash {short_hash(existing.hash)}, not "
                    f"{short_hash(hash)}; catalog entries are append-only: write the new data as "
                    f"{name}@v{self.next_dataset_version(name)}"
                )
            return existing
        return self.dataset(name, version)

    def next_dataset_version(self, name: str) -> int:
        """One more than the newest registered version of ``name`` (1 if none)."""
        (v,) = self.conn.execute("SELECT MAX(version) FROM datasets WHERE name = ?", (name,)).fetchone()
        return (v or 0) + 1

    def dataset(self, name: str, version: int | None = None) -> DatasetEntry:
        """The row for ``name`` at ``version`` (default: the newest); unknown names list near matches."""
        if version is None:
            r = self.conn.execute(
                "SELECT * FROM datasets WHERE name = ? ORDER BY version DESC LIMIT 1", (name,)
            ).fetchone()
        else:
            r = self.conn.execute("SELECT * FROM datasets WHERE name = ? AND version = ?", (name, version)).fetchone()
        if r is None:
            versions = [v for (v,) in self.conn.execute("SELECT version FROM datasets WHERE name = ?", (name,))]
            if versions:
                raise unknown(f"version of dataset {name!r}", f"v{version}", [f"v{v}" for v in versions])
            names = [n for (n,) in self.conn.execute("SELECT DISTINCT name FROM datasets")]
            raise unknown("dataset", name, names, "list datasets with `nsl catalog ls datasets`")
        return self._dataset_row(r)

    def datasets(self, name: str | None = None) -> list[DatasetEntry]:
        q, a = (
            ("SELECT * FROM datasets WHERE name = ? ORDER BY seq", (name,))
            if name
            else ("SELECT * FROM datasets ORDER BY seq", ())
        )
        return [self._dataset_row(r) for r in self.conn.execute(q, a)]

    def resolve_data(self, ref: str) -> ResolvedData:
        """``data:NAME[@vN][:TIER]`` -> the dataset row plus the tier (for the datasets loader)."""
        d = parse_data_ref(ref)
        return ResolvedData(self.dataset(d.name, d.version), d.tier)

    def _dataset_row(self, r: tuple) -> DatasetEntry:
        _seq, name, version, h, shift, episodes, prov, path, files, created = r
        return DatasetEntry(
            name,
            version,
            h,
            json.loads(shift),
            episodes,
            json.loads(prov),
            self._load_path(path),
            created,
            json.loads(files),
        )

    # ---------------------------------------------------------- checkpoints
    def save_checkpoint(
        self,
        name: str,
        step: int,
        weights: bytes | Path,
        config: Mapping[str, Any],
        *,
        parent: str | None = None,
        data: Sequence[DataUse] = (),
        shift: str | None = None,
        card_info: Mapping[str, Any] | None = None,
        code_version: str | None = None,
        dest: Path | None = None,
    ) -> CheckpointEntry:
        """Write a model folder under ``$NSL_HOME/checkpoints/NAME/`` and register it.

        ``weights``: safetensors bytes or a ``.safetensors`` path; ``config``:
        the JSON-able model/training config (becomes ``config.json``);
        ``parent``: id of the checkpoint training started from (None: from
        scratch); ``data``: the datasets trained on with their batch weights;
        ``shift``: the shift it is trained for (default: the shift of the last
        dataset in ``data``, else the parent's, else "base"); ``card_info``:
        extra model-card fields (``summary``, ``tags``, ``license``); ``dest``:
        the folder to write (default ``checkpoints/NAME/{STEP:08d}-{ID12}``).
        A weights file is hard-linked into the folder, not copied (a copy is
        made only across file systems), so registering a training run's
        ``final/`` costs no second copy of the weights.

        Registering the same weights and config again returns the existing
        entry; under another name (a deterministic re-run with the same data,
        seed and parent) the name is added to that entry as an alias, so
        ``ckpt:NEWNAME`` resolves to it.
        """
        check_name("checkpoint", name)
        config_bytes = encode_config(config)
        files = content_digests(weights, config_bytes)
        stored: dict[str, Any] = json.loads(config_bytes)  # as it will read back from config.json
        entry = self._new_checkpoint(
            checkpoint_id(weights, stored), name, step, parent, data, shift, stored, code_version, Path("."), files
        )
        existing = self._checkpoint_or_none(entry.id)
        if existing is not None:
            return self._same_or_alias(existing, entry)
        dest = Path(dest) if dest is not None else workspace.checkpoints_dir() / name / f"{step:08d}-{entry.short_id}"
        write_model_folder(dest, weights, stored, self._card(entry, card_info))
        return self._insert_checkpoint(entry, dest)

    def register_checkpoint(
        self,
        folder: Path | str,
        *,
        name: str,
        step: int,
        parent: str | None = None,
        data: Sequence[DataUse] = (),
        shift: str | None = None,
        card_info: Mapping[str, Any] | None = None,
        code_version: str | None = None,
    ) -> CheckpointEntry:
        """Register a folder that already holds ``model.safetensors`` and ``config.json``.

        Writes its ``README.md`` card, then the row.  Arguments as in
        :meth:`save_checkpoint`.
        """
        check_name("checkpoint", name)
        folder = Path(folder)
        files = folder_digests(folder)
        entry = self._new_checkpoint(
            folder_checkpoint_id(folder),
            name,
            step,
            parent,
            data,
            shift,
            read_config(folder),
            code_version,
            folder,
            files,
        )
        existing = self._checkpoint_or_none(entry.id)
        if existing is not None:
            return self._same_or_alias(existing, entry)
        write_card(folder, self._card(entry, card_info))
        return self._insert_checkpoint(entry, folder)

    def _new_checkpoint(
        self,
        cid: str,
        name: str,
        step: int,
        parent: str | None,
        data: Sequence[DataUse],
        shift: str | None,
        config: dict,
        code_version: str | None,
        path: Path,
        files: dict[str, str],
    ) -> CheckpointEntry:
        if not isinstance(step, int) or step < 0:
            raise ConfigError(f"step {step!r} for checkpoint {name!r} must be an integer >= 0")
        parent_entry = self.checkpoint(parent) if parent else None
        uses = []
        for u in data:
            if not isinstance(u, DataUse):
                raise ConfigError(
                    f"data entries must be DataUse records (got {u!r}); "
                    "use cat.resolve_data('data:NAME@vN').use(weight)"
                )
            d = self.dataset(u.dataset, u.version)
            uses.append(DataUse(u.dataset, u.version, float(u.weight), u.tier, d.hash))
        if shift is None:
            shift = (
                self.dataset(uses[-1].dataset, uses[-1].version).shift_name
                if uses
                else parent_entry.shift
                if parent_entry
                else "base"
            )
        if not isinstance(shift, str) or not shift:
            raise ConfigError(f"shift {shift!r} for checkpoint {name!r} must be a shift name such as 'base'")
        return CheckpointEntry(
            cid,
            name,
            step,
            parent_entry.id if parent_entry else None,
            shift,
            tuple(uses),
            config,
            code_version or _code_version(),
            str(path),
            schema.utc_now(),
            files,
        )

    @staticmethod
    def _check_same(existing: CheckpointEntry, new: CheckpointEntry) -> None:
        """Refuse a registration of ``existing``'s content with another step, parent or data."""

        def key(e: CheckpointEntry) -> tuple:
            return e.step, e.parent, [(u.dataset, u.version, u.weight, u.tier) for u in e.data]

        if key(existing) != key(new):
            raise ConfigError(
                f"identical weights and config are already registered as ckpt:{existing.ref} "
                f"({existing.short_id}) with another step, parent or data; entries are append-only, "
                f"so use ckpt:{existing.ref} instead"
            )

    def _same_or_alias(self, existing: CheckpointEntry, new: CheckpointEntry) -> CheckpointEntry:
        """``existing`` again; under a new name (same step, parent and data) that name becomes its alias."""
        self._check_same(existing, new)
        if new.name not in self.names(existing.id):
            with self.write() as c:
                c.execute(
                    "INSERT OR IGNORE INTO checkpoint_names (name, checkpoint, created) VALUES (?, ?, ?)",
                    (new.name, existing.id, schema.utc_now()),
                )
        return existing

    def names(self, checkpoint: str) -> list[str]:
        """Every name the checkpoint with id ``checkpoint`` is registered under, the first one first."""
        return [
            n
            for (n,) in self.conn.execute(
                "SELECT name FROM checkpoint_names WHERE checkpoint = ? ORDER BY seq", (checkpoint,)
            )
        ]

    def _insert_checkpoint(self, e: CheckpointEntry, path: Path) -> CheckpointEntry:
        with self.write() as c:
            if c.execute("SELECT 1 FROM checkpoints WHERE id = ?", (e.id,)).fetchone() is None:
                c.execute(
                    "INSERT INTO checkpoints (id, name, step, parent, shift, data, config, code_version, "
                    "path, files, created) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        e.id,
                        e.name,
                        e.step,
                        e.parent,
                        e.shift,
                        dumps(
                            [
                                {
                                    "dataset": u.dataset,
                                    "version": u.version,
                                    "weight": u.weight,
                                    "tier": u.tier,
                                    "hash": u.hash,
                                }
                                for u in e.data
                            ]
                        ),
                        dumps(e.config),
                        e.code_version,
                        self._store_path(path),
                        dumps(e.files),
                        e.created,
                    ),
                )
                c.executemany(
                    "INSERT OR IGNORE INTO checkpoint_data (checkpoint, dataset, version) VALUES (?, ?, ?)",
                    [(e.id, u.dataset, u.version) for u in e.data],
                )
                c.execute(
                    "INSERT OR IGNORE INTO checkpoint_names (name, checkpoint, created) VALUES (?, ?, ?)",
                    (e.name, e.id, e.created),
                )
        return self._same_or_alias(self.checkpoint(e.id), e)  # another process may have registered it first

    def _checkpoint_row(self, r: tuple) -> CheckpointEntry:
        _seq, cid, name, step, parent, shift, data, config, code_version, path, files, created = r
        uses = tuple(DataUse(d["dataset"], d["version"], d["weight"], d["tier"], d["hash"]) for d in json.loads(data))
        return CheckpointEntry(
            cid,
            name,
            step,
            parent,
            shift,
            uses,
            json.loads(config),
            code_version,
            self._load_path(path),
            created,
            json.loads(files),
        )

    def _checkpoint_or_none(self, cid: str) -> CheckpointEntry | None:
        r = self.conn.execute("SELECT * FROM checkpoints WHERE id = ?", (cid,)).fetchone()
        return self._checkpoint_row(r) if r else None

    def checkpoint(self, ref: str) -> CheckpointEntry:
        """A checkpoint by id, id prefix or any ``ckpt:`` reference."""
        return resolve_checkpoint(self, ref)

    def checkpoints(self, name: str | None = None) -> list[CheckpointEntry]:
        """Checkpoints in registration order (all, or those registered under ``name``)."""
        q, a = (
            (
                "SELECT c.* FROM checkpoints c JOIN checkpoint_names n ON n.checkpoint = c.id WHERE n.name = ? "
                "ORDER BY n.seq",
                (name,),
            )
            if name
            else ("SELECT * FROM checkpoints ORDER BY seq", ())
        )
        return [self._checkpoint_row(r) for r in self.conn.execute(q, a)]

    def children(self, checkpoint: str) -> list[CheckpointEntry]:
        """Checkpoints fine-tuned directly from the checkpoint with id ``checkpoint``."""
        return [
            self._checkpoint_row(r)
            for r in self.conn.execute("SELECT * FROM checkpoints WHERE parent = ? ORDER BY seq", (checkpoint,))
        ]

    def trained_on(self, name: str, version: int) -> list[CheckpointEntry]:
        """Checkpoints whose training data included dataset ``name`` at ``version``."""
        return [
            self._checkpoint_row(r)
            for r in self.conn.execute(
                "SELECT c.* FROM checkpoints c JOIN checkpoint_data d ON d.checkpoint = c.id "
                "WHERE d.dataset = ? AND d.version = ? ORDER BY c.seq",
                (name, version),
            )
        ]

    def lineage(self, ref: str) -> list[CheckpointEntry]:
        """The checkpoint and its ancestors, newest first (stops at a removed parent)."""
        entry = self.checkpoint(ref)
        return [entry, *self._ancestors(entry)]

    def _ancestors(self, entry: CheckpointEntry) -> list[CheckpointEntry]:
        chain: list[CheckpointEntry] = []
        seen = {entry.id}
        parent = entry.parent
        while parent and parent not in seen and (p := self._checkpoint_or_none(parent)) is not None:
            chain.append(p)
            seen.add(p.id)
            parent = p.parent
        return chain

    def resolve_checkpoint(self, ref: str, shift: str | None = None, split: str | None = None) -> CheckpointEntry:
        """``ckpt:NAME[@STEP|@best[:SHIFT]|@latest|@TAG]`` -> the checkpoint (see :func:`resolve_checkpoint`)."""
        return resolve_checkpoint(self, ref, shift=shift, split=split)

    # ---------------------------------------------------------- model cards
    def _card(self, entry: CheckpointEntry, info: Mapping[str, Any] | None = None) -> str:
        ancestors = self._ancestors(entry)
        datasets = {}
        for u in entry.data:
            try:
                datasets[(u.dataset, u.version)] = self.dataset(u.dataset, u.version)
            except UnknownReferenceError:
                pass  # removed, or never in this workspace (the shipped base's data)
        return render_model_card(entry, ancestors, datasets, self.evaluations(entry.id), info)

    def write_model_card(self, checkpoint: str, card_info: Mapping[str, Any] | None = None) -> Path:
        """Regenerate a checkpoint's ``README.md`` (e.g. after new evaluations); returns its path."""
        entry = self.checkpoint(checkpoint)
        return write_card(Path(entry.path), self._card(entry, card_info))

    # ---------------------------------------------------------- evaluations
    def add_evaluation(
        self,
        checkpoint: str,
        shift: str,
        *,
        episodes: int,
        successes: int,
        seed: int,
        split: str = "test",
        ci: tuple[float, float] | None = None,
        extra: Mapping[str, Any] | None = None,
        precision: str = "fp32",
    ) -> EvaluationEntry:
        """Record ``successes`` out of ``episodes`` for a checkpoint on ``shift`` (a shift spec name).

        ``ci`` is the 95% interval (default: Wilson); ``extra`` any JSON
        detail (eval config, env version, code version); ``precision`` how
        the policy acted: ``fp32`` or ``bf16`` on the CPU, one state at a time,
        or ``PRECISION/cuda/N`` on a GPU, N states searched together (its
        episodes depend on N).  Re-recording the same (checkpoint,
        shift, split, seed, episodes, precision) with the same result is a
        no-op; with a different result it is refused.
        """
        entry = self.checkpoint(checkpoint)
        if not isinstance(shift, str) or not shift:
            raise ConfigError(f"evaluation shift {shift!r} must be a shift name such as 'base'")
        if not isinstance(episodes, int) or episodes < 1:
            raise ConfigError(f"evaluation episodes {episodes!r} must be an integer >= 1")
        if not isinstance(successes, int) or not 0 <= successes <= episodes:
            raise ConfigError(f"evaluation successes {successes!r} must be an integer in [0, {episodes}]")
        lo, hi = ci if ci is not None else wilson_interval(successes, episodes)
        if not 0.0 <= lo <= hi <= 1.0:
            raise ConfigError(f"evaluation interval {ci!r} must satisfy 0 <= low <= high <= 1")
        if not re.fullmatch(r"(fp32|bf16)(/cuda/[1-9][0-9]*)?", str(precision)):
            raise ConfigError(
                f"evaluation precision {precision!r} must be fp32 or bf16 (how the policy acted on the CPU), or "
                "fp32/cuda/N or bf16/cuda/N (on a GPU, N states a call)"
            )
        key = (entry.id, shift, split, int(seed), episodes, precision)
        with self.write() as c:
            old = c.execute(
                "SELECT * FROM evaluations WHERE checkpoint = ? AND shift = ? AND split = ? AND seed = ? "
                "AND episodes = ? AND precision = ?",
                key,
            ).fetchone()
            if old is None:
                cur = c.execute(
                    "INSERT INTO evaluations (checkpoint, shift, split, episodes, successes, ci_low, "
                    "ci_high, seed, extra, created, precision) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        entry.id,
                        shift,
                        split,
                        episodes,
                        successes,
                        float(lo),
                        float(hi),
                        int(seed),
                        dumps(dict(extra or {})),
                        schema.utc_now(),
                        precision,
                    ),
                )
                new_id = cur.lastrowid
        if old is not None:
            e = self._evaluation_row(old)
            if e.successes != successes:
                raise ConfigError(
                    f"an evaluation of ckpt:{entry.ref} on {shift} ({split} objects, seed {seed}, {episodes} "
                    f"episodes, {precision}) is already recorded with {e.successes} successes; "
                    "evaluate with another --seed"
                )
            return e
        return self._evaluation_row(self.conn.execute("SELECT * FROM evaluations WHERE id = ?", (new_id,)).fetchone())

    def evaluations(self, checkpoint: str | None = None, shift: str | None = None) -> list[EvaluationEntry]:
        q, a = "SELECT * FROM evaluations WHERE 1 = 1", []
        if checkpoint is not None:
            q += " AND checkpoint = ?"
            a.append(checkpoint)
        if shift is not None:
            q += " AND shift = ?"
            a.append(shift)
        return [self._evaluation_row(r) for r in self.conn.execute(q + " ORDER BY id", a)]

    @staticmethod
    def _evaluation_row(r: tuple) -> EvaluationEntry:
        eid, ckpt, shift, split, episodes, successes, lo, hi, seed, extra, created, precision = r
        return EvaluationEntry(
            eid, ckpt, shift, split, episodes, successes, lo, hi, seed, created, precision, json.loads(extra)
        )

    # ----------------------------------------------------------------- tags
    def tag(self, tag: str, checkpoint: str) -> CheckpointEntry:
        """Point ``tag`` at a checkpoint (moving it if it exists); ``ckpt:TAG`` then resolves to it."""
        check_name("tag", tag)
        if tag in RESERVED or tag.isdigit():
            raise ConfigError(f"tag {tag!r} would read as a selector (@best, @latest, @STEP); pick another name")
        if self.conn.execute("SELECT 1 FROM checkpoint_names WHERE name = ?", (tag,)).fetchone():
            raise ConfigError(f"tag {tag!r} is also a checkpoint name, and ckpt:{tag} means that name; pick another")
        entry = self.checkpoint(checkpoint)
        with self.write() as c:
            c.execute("INSERT INTO tags (tag, checkpoint, created) VALUES (?, ?, ?)", (tag, entry.id, schema.utc_now()))
        return entry

    def untag(self, tag: str) -> None:
        if tag not in self.tags():
            raise unknown("tag", tag, self.tags(), "list tags with `nsl catalog ls tags`")
        with self.write() as c:
            c.execute("INSERT INTO tags (tag, checkpoint, created) VALUES (?, NULL, ?)", (tag, schema.utc_now()))

    def tags(self, checkpoint: str | None = None) -> dict[str, str]:
        """``{tag: checkpoint id}`` for current tags (optionally only those on one checkpoint)."""
        rows = self.conn.execute(
            "SELECT t.tag, t.checkpoint FROM tags t WHERE t.seq = "
            "(SELECT MAX(seq) FROM tags u WHERE u.tag = t.tag) ORDER BY t.tag"
        )
        return {t: c for t, c in rows if c is not None and (checkpoint is None or c == checkpoint)}


# --------------------------------------------------------------- references
_HINT = "list checkpoints with `nsl catalog ls checkpoints`"


_NAMED = "SELECT c.* FROM checkpoints c JOIN checkpoint_names n ON n.checkpoint = c.id WHERE n.name = ?"


def _newest(cat: Catalog, name: str, step: int | None = None) -> CheckpointEntry | None:
    """The checkpoint most recently registered under ``name`` (at ``step``, if given)."""
    q, args = (_NAMED, (name,)) if step is None else (_NAMED + " AND c.step = ?", (name, step))
    r = cat.conn.execute(q + " ORDER BY n.seq DESC LIMIT 1", args).fetchone()
    return cat._checkpoint_row(r) if r else None


def _names(cat: Catalog) -> list[str]:
    return [n for (n,) in cat.conn.execute("SELECT DISTINCT name FROM checkpoint_names")]


def _shipped_base(cat: Catalog, name: str) -> CheckpointEntry | None:
    """Register the checkpoint shipped in ``nsl/assets/base`` as ``base`` if ``name`` asks for it and nothing else
    in this catalog is called ``base``; None otherwise."""
    folder = workspace.shipped_base_dir()
    if name != SHIPPED_BASE or SHIPPED_BASE in cat.tags() or not (folder / WEIGHTS_FILE).is_file():
        return None
    config = read_config(folder)
    record_file = folder / SHIPPED_RECORD
    record = json.loads(record_file.read_text()) if record_file.is_file() else {}
    uses = tuple(
        DataUse(d["dataset"], int(d["version"]), float(d["weight"]), d.get("tier"), d.get("hash", ""))
        for d in record.get("data", [])
    )
    entry = CheckpointEntry(
        checkpoint_id(folder / WEIGHTS_FILE, config),
        SHIPPED_BASE,
        int(config.get("step", 0)),
        None,
        record.get("target_shift") or "base",
        uses,
        config,
        str(config.get("code_version") or _code_version()),
        ".",
        schema.utc_now(),
        content_digests(folder / WEIGHTS_FILE, encode_config(config)),
    )
    existing = cat._checkpoint_or_none(entry.id)
    if existing is not None:
        return cat._same_or_alias(existing, entry)
    dest = workspace.checkpoints_dir() / SHIPPED_BASE / f"{entry.step:08d}-{entry.short_id}"
    sources = ", ".join(f"`{u.dataset}@v{u.version}` x{u.weight:g}" for u in uses) or "unrecorded data"
    info = {
        "summary": f"The base checkpoint shipped with nsl (`nsl/assets/base`), pre-trained from scratch on "
        f"{sources}; `{SHIPPED_RECORD}` there records the exact training command.",
        "tags": ["base"],
    }
    write_model_folder(dest, folder / WEIGHTS_FILE, config, cat._card(entry, info))
    return cat._insert_checkpoint(entry, dest)


def _by_id_prefix(cat: Catalog, prefix: str) -> CheckpointEntry | None:
    rows = cat.conn.execute(
        "SELECT * FROM checkpoints WHERE id >= ? AND id < ? ORDER BY seq LIMIT 5", (prefix, prefix + "g")
    ).fetchall()
    if len(rows) > 1:
        shown = ", ".join(f"{r[1][:12]} ({r[2]}@{r[3]})" for r in rows)
        raise ConfigError(f"checkpoint id prefix {prefix!r} is ambiguous ({shown}); give more digits")
    return cat._checkpoint_row(rows[0]) if rows else None


def resolve_checkpoint(cat: Catalog, ref: str, shift: str | None = None, split: str | None = None) -> CheckpointEntry:
    """Resolve ``[ckpt:]NAME[@STEP|@best[:SHIFT]|@latest|@TAG]``, a tag or an id (prefix).

    ``@best`` is defined as follows.  Among the checkpoints registered under
    NAME, take every evaluation on the ranking shift (and object split, if one is
    given), pool each checkpoint's runs (successes and episodes summed over
    seeds), and pick the highest pooled success rate.  Ties go to the checkpoint
    with more evaluated episodes, then to the newer registration.  The ranking
    shift is, in order: the ``:SHIFT`` written in the reference
    (``ckpt:harsh@best:base``), the ``shift=`` argument, and otherwise the shift
    NAME was trained for (that of its newest checkpoint).  A checkpoint never
    evaluated on that shift cannot be best.

    Name resolution for ``ckpt:X`` without a selector: a checkpoint name first
    (its newest registration), then a tag, then an id prefix of six or more hex
    digits.
    """
    if not isinstance(ref, str):
        raise ConfigError(f"checkpoint reference {ref!r} must be a string such as ckpt:base@latest")
    body = ref.strip().removeprefix(CKPT_PREFIX)
    if len(body) == 64 and HEX_RE.fullmatch(body):  # a full id: the common internal case
        r = cat.conn.execute("SELECT * FROM checkpoints WHERE id = ?", (body,)).fetchone()
        if r:
            return cat._checkpoint_row(r)
    parsed = parse_checkpoint_ref(ref)
    name, sel = parsed.name, parsed.selector
    newest = _newest(cat, name) or _shipped_base(cat, name)
    if sel is None or sel == "latest":
        if newest is not None:
            return newest
        if sel is None:
            tags = cat.tags()
            if name in tags:
                return cat.checkpoint(tags[name])
            if HEX_RE.fullmatch(name) and (entry := _by_id_prefix(cat, name)) is not None:
                return entry
        raise unknown("checkpoint", name, [*_names(cat), *cat.tags()], _HINT)
    if newest is None:
        raise unknown("checkpoint", name, _names(cat), _HINT)
    if sel.isdigit():
        entry = _newest(cat, name, int(sel))
        if entry is None:
            steps = [
                s
                for (s,) in cat.conn.execute(
                    "SELECT DISTINCT c.step FROM checkpoints c JOIN checkpoint_names n "
                    "ON n.checkpoint = c.id WHERE n.name = ? ORDER BY c.step",
                    (name,),
                )
            ]
            shown = ", ".join(map(str, steps[:10])) + (", ..." if len(steps) > 10 else "")
            raise UnknownReferenceError(
                f"checkpoint {name!r} has no step {sel}; its steps are {shown} "
                f"(e.g. ckpt:{name}@{steps[-1]}, or ckpt:{name}@latest)"
            )
        return entry
    if sel == "best":
        return best_checkpoint(cat, name, shift=parsed.shift or shift, split=split)[0]
    tags = cat.tags()
    if sel not in tags:
        own = [t for t, c in tags.items() if cat.checkpoint(c).name == name]
        raise unknown(
            "tag",
            sel,
            own or tags,
            f"selectors are @STEP, @best, @latest or @TAG; tag with `nsl catalog tag ckpt:{name}@STEP TAG`",
        )
    entry = cat.checkpoint(tags[sel])
    if name not in cat.names(entry.id):
        raise ConfigError(
            f"tag {sel!r} points to ckpt:{entry.ref}, not to a checkpoint of {name!r}; "
            f"write ckpt:{sel} for the tagged checkpoint"
        )
    return entry


def best_checkpoint(
    cat: Catalog, name: str, shift: str | None = None, split: str | None = None
) -> tuple[CheckpointEntry, dict]:
    """The best checkpoint of ``name`` (as defined in :func:`resolve_checkpoint`) and its pooled score.

    The score is ``{"shift", "split", "successes", "episodes", "rate"}``.
    """
    newest = _newest(cat, name) or _shipped_base(cat, name)
    if newest is None:
        raise unknown("checkpoint", name, _names(cat), _HINT)
    shift = shift or newest.shift
    q = (
        "SELECT n.seq, c.id, SUM(e.successes), SUM(e.episodes) FROM checkpoints c "
        "JOIN checkpoint_names n ON n.checkpoint = c.id "
        "JOIN evaluations e ON e.checkpoint = c.id WHERE n.name = ? AND e.shift = ?"
    )
    args: list = [name, shift]
    if split is not None:
        q += " AND e.split = ?"
        args.append(split)
    rows = cat.conn.execute(q + " GROUP BY c.id", args).fetchall()
    if not rows:
        shifts = [
            s
            for (s,) in cat.conn.execute(
                "SELECT DISTINCT e.shift FROM evaluations e JOIN checkpoint_names n ON e.checkpoint = n.checkpoint "
                "WHERE n.name = ?",
                (name,),
            )
        ]
        where = f"shift {shift!r}" + (f" ({split} objects)" if split else "")
        also = f"; it was evaluated on: {', '.join(sorted(shifts))} (use ckpt:{name}@best:SHIFT)" if shifts else ""
        raise UnknownReferenceError(
            f"ckpt:{name}@best: no checkpoint of {name!r} has an evaluation on {where}{also}; "
            f"run `nsl eval --checkpoint ckpt:{name}@latest --shift {shift}` first"
        )
    seq, cid, s, n = max(rows, key=lambda r: (r[2] / r[3], r[3], r[0]))
    return cat.checkpoint(cid), {"shift": shift, "split": split, "successes": s, "episodes": n, "rate": s / n}
