"""The catalog's SQLite file: opening it safely, its schema and its migrations.

The catalog is one SQLite database in WAL mode.  Two pragmas mark it as
ours: ``application_id`` (the four bytes ``NSLC``) and ``user_version`` (the
schema version).  Opening refuses, with a one-line error, a file that is not
an SQLite database, an SQLite database that is not an nsl catalog, and a
catalog written by a newer nsl.

Migrations are plain functions keyed by the version they produce:
``MIGRATIONS[n]`` turns a version ``n - 1`` database into version ``n``
(``MIGRATIONS[1]`` creates the schema in an empty file).  To change the
schema, append a function and nothing else; every open upgrades older files
in one write transaction and records the step in ``schema_history``.
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from nsl.errors import CorruptDataError, IncompatibleVersionError

APPLICATION_ID = 0x4E534C43  # b"NSLC": marks the file as an nsl catalog
BUSY_TIMEOUT_MS = 30_000  # how long one statement waits for another process's write lock
LOCK_RETRIES = 20  # further attempts (with back-off) after a busy timeout expires


def _v1(conn: sqlite3.Connection) -> None:
    """The first schema: datasets, checkpoints, evaluations, tags."""
    _run_script(
        conn,
        """
        CREATE TABLE schema_history (
            version      INTEGER NOT NULL,
            applied      TEXT NOT NULL,
            code_version TEXT NOT NULL
        );
        CREATE TABLE datasets (
            seq        INTEGER PRIMARY KEY AUTOINCREMENT,
            name       TEXT NOT NULL,
            version    INTEGER NOT NULL,
            hash       TEXT NOT NULL,
            shift      TEXT NOT NULL,       -- shift spec JSON ({"name": ..., "shifts": [...]})
            episodes   INTEGER NOT NULL,
            provenance TEXT NOT NULL,       -- JSON: collection config, policy, seeds, code version
            path       TEXT NOT NULL,
            files      TEXT NOT NULL,       -- JSON {relative path: sha256} taken at registration
            created    TEXT NOT NULL,
            UNIQUE (name, version)
        );
        CREATE TABLE checkpoints (
            seq          INTEGER PRIMARY KEY AUTOINCREMENT,
            id           TEXT NOT NULL UNIQUE,  -- content hash of the weights and the config
            name         TEXT NOT NULL,
            step         INTEGER NOT NULL,
            parent       TEXT,                  -- id of the checkpoint training started from
            shift        TEXT NOT NULL,         -- name of the shift it was trained for
            data         TEXT NOT NULL,         -- JSON list of dataset uses with weights
            config       TEXT NOT NULL,         -- JSON, the content of config.json
            code_version TEXT NOT NULL,
            path         TEXT NOT NULL,
            files        TEXT NOT NULL,         -- JSON {file name: sha256}
            created      TEXT NOT NULL
        );
        CREATE INDEX checkpoints_name ON checkpoints (name, step);
        CREATE INDEX checkpoints_parent ON checkpoints (parent);
        CREATE TABLE checkpoint_data (          -- one row per dataset a checkpoint was trained on
            checkpoint TEXT NOT NULL,
            dataset    TEXT NOT NULL,
            version    INTEGER NOT NULL,
            PRIMARY KEY (checkpoint, dataset, version)
        );
        CREATE INDEX checkpoint_data_dataset ON checkpoint_data (dataset, version);
        CREATE TABLE evaluations (
            id         INTEGER PRIMARY KEY AUTOINCREMENT,
            checkpoint TEXT NOT NULL,
            shift      TEXT NOT NULL,
            split      TEXT NOT NULL,
            episodes   INTEGER NOT NULL,
            successes  INTEGER NOT NULL,
            ci_low     REAL NOT NULL,
            ci_high    REAL NOT NULL,
            seed       INTEGER NOT NULL,
            extra      TEXT NOT NULL,           -- JSON: eval config, env version, code version, ...
            created    TEXT NOT NULL,
            UNIQUE (checkpoint, shift, split, seed, episodes)
        );
        CREATE INDEX evaluations_checkpoint ON evaluations (checkpoint, shift);
        CREATE TABLE tags (                      -- history: the newest row per tag wins
            seq        INTEGER PRIMARY KEY AUTOINCREMENT,
            tag        TEXT NOT NULL,
            checkpoint TEXT,                     -- NULL: the tag was removed
            created    TEXT NOT NULL
        );
        CREATE INDEX tags_tag ON tags (tag, seq);
    """,
    )


def _v2(conn: sqlite3.Connection) -> None:
    """Checkpoint names: an entry may carry several names (a deterministic re-run registered under a new one)."""
    _run_script(
        conn,
        """
        CREATE TABLE checkpoint_names (          -- every name a checkpoint is registered under
            seq        INTEGER PRIMARY KEY AUTOINCREMENT,
            name       TEXT NOT NULL,
            checkpoint TEXT NOT NULL,
            created    TEXT NOT NULL,
            UNIQUE (name, checkpoint)
        );
        CREATE INDEX checkpoint_names_name ON checkpoint_names (name, seq);
        INSERT INTO checkpoint_names (name, checkpoint, created)
            SELECT name, id, created FROM checkpoints ORDER BY seq
    """,
    )


def _run_script(conn: sqlite3.Connection, script: str) -> None:
    """Run ``;``-separated statements inside the caller's transaction (executescript would commit it)."""
    for statement in script.split(";"):
        if statement.strip():
            conn.execute(statement)


def _v3(conn: sqlite3.Connection) -> None:
    """Origins: where a pulled dataset version or checkpoint came from, and what was published with it."""
    _run_script(
        conn,
        """
        CREATE TABLE origins (
            seq       INTEGER PRIMARY KEY AUTOINCREMENT,
            kind      TEXT NOT NULL,        -- 'dataset' or 'checkpoint'
            entry     TEXT NOT NULL,        -- dataset NAME@vN, or checkpoint id
            hash      TEXT NOT NULL,        -- the content hash (dataset) or id (checkpoint) that was pulled
            url       TEXT NOT NULL,        -- the remote, without credentials
            revision  TEXT NOT NULL,        -- Hub commit id, or the remote's version / checkpoint id
            published TEXT NOT NULL,        -- JSON: the remote's manifest metadata (lineage, name, version)
            created   TEXT NOT NULL
        );
        CREATE INDEX origins_entry ON origins (kind, entry);
    """,
    )


def _v4(conn: sqlite3.Connection) -> None:
    """Evaluations keep the precision the policy acted in: the same scenes in fp32 and in bf16 are two records."""
    _run_script(
        conn,
        """
        CREATE TABLE evaluations_v4 (
            id         INTEGER PRIMARY KEY AUTOINCREMENT,
            checkpoint TEXT NOT NULL,
            shift      TEXT NOT NULL,
            split      TEXT NOT NULL,
            episodes   INTEGER NOT NULL,
            successes  INTEGER NOT NULL,
            ci_low     REAL NOT NULL,
            ci_high    REAL NOT NULL,
            seed       INTEGER NOT NULL,
            extra      TEXT NOT NULL,
            created    TEXT NOT NULL,
            precision  TEXT NOT NULL DEFAULT 'fp32',  -- the network's arithmetic while acting: fp32 or bf16
            UNIQUE (checkpoint, shift, split, seed, episodes, precision)
        );
        INSERT INTO evaluations_v4 (id, checkpoint, shift, split, episodes, successes, ci_low, ci_high, seed, extra,
                                    created, precision)
            SELECT id, checkpoint, shift, split, episodes, successes, ci_low, ci_high, seed, extra, created,
                   COALESCE(json_extract(extra, '$.precision'), 'fp32')
            FROM evaluations ORDER BY id;
        DROP TABLE evaluations;
        ALTER TABLE evaluations_v4 RENAME TO evaluations;
        CREATE INDEX evaluations_checkpoint ON evaluations (checkpoint, shift)
    """,
    )


MIGRATIONS: dict[int, Callable[[sqlite3.Connection], None]] = {1: _v1, 2: _v2, 3: _v3, 4: _v4}
SCHEMA_VERSION = max(MIGRATIONS)


def utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def _retry(fn: Callable[[], object]) -> object:
    """Run ``fn``; on "database is locked" wait and try again (beyond the busy timeout)."""
    for attempt in range(LOCK_RETRIES + 1):
        try:
            return fn()
        except sqlite3.OperationalError as e:
            msg = str(e).lower()
            if attempt == LOCK_RETRIES or ("locked" not in msg and "busy" not in msg):
                raise
            time.sleep(min(0.05 * 2**attempt, 2.0))
    raise AssertionError("unreachable")


def begin_immediate(conn: sqlite3.Connection) -> None:
    """Take the write lock now (not at the first write), waiting for other writers."""
    _retry(lambda: conn.execute("BEGIN IMMEDIATE"))


def connect(
    path: Path, migrations: Mapping[int, Callable[[sqlite3.Connection], None]] = MIGRATIONS, code_version: str = ""
) -> sqlite3.Connection:
    """Open (creating if needed) the catalog at ``path``, upgraded to the newest schema.

    ``migrations`` is a parameter so the upgrade path can be exercised with
    a longer list than this release ships.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    target = max(migrations)
    conn = sqlite3.connect(path, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
    try:
        conn.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        try:
            app_id, version, tables = _identify_snapshot(conn)
        except sqlite3.DatabaseError as e:
            if "locked" in str(e).lower() or "busy" in str(e).lower():
                app_id, version, tables = _retry(lambda: _identify_snapshot(conn))  # type: ignore[misc]
            else:
                raise CorruptDataError(
                    f"{path} is not an nsl catalog (not an SQLite database: {e}); move it away, "
                    "or set NSL_HOME to another workspace"
                ) from None
        _check_identity(path, app_id, version, tables, target)
        mode = _retry(lambda: conn.execute("PRAGMA journal_mode = WAL").fetchone()[0])
        if str(mode).lower() != "wal":
            raise CorruptDataError(
                f"{path}: could not switch the catalog to WAL mode (got {mode!r}); put NSL_HOME on a local file system"
            )
        if version < target:
            _migrate(conn, path, migrations, target, code_version)
        conn.execute("PRAGMA synchronous = NORMAL")  # safe with WAL: a crash loses no committed row
        conn.execute("PRAGMA foreign_keys = OFF")
    except BaseException:
        conn.close()
        raise
    return conn


def _identify_snapshot(conn: sqlite3.Connection) -> tuple[int, int, list[str]]:
    """``_identify`` inside one read transaction.

    In autocommit mode each statement would see its own snapshot, so a reader
    racing the creating process could see the new tables but the old (zero)
    application id, and call a half-seen catalog foreign.
    """
    conn.execute("BEGIN")
    try:
        return _identify(conn)
    finally:
        if conn.in_transaction:
            conn.execute("ROLLBACK")


def _identify(conn: sqlite3.Connection) -> tuple[int, int, list[str]]:
    app_id = conn.execute("PRAGMA application_id").fetchone()[0]
    version = conn.execute("PRAGMA user_version").fetchone()[0]
    tables = [
        r[0]
        for r in conn.execute(
            "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' ORDER BY name"
        )
    ]
    return app_id, version, tables


def _check_identity(path: Path, app_id: int, version: int, tables: list[str], target: int) -> None:
    if app_id == 0 and not tables and version == 0:
        return  # a new, empty file: the first migration creates the schema
    if app_id != APPLICATION_ID:
        shown = ", ".join(tables[:6]) + (", ..." if len(tables) > 6 else "")
        raise CorruptDataError(
            f"{path} is not an nsl catalog (an SQLite database with tables: {shown or 'none'}); "
            "move it away, or set NSL_HOME to another workspace"
        )
    if version > target:
        raise IncompatibleVersionError(
            f"{path} has catalog schema version {version}, but this nsl reads versions up to {target}; "
            "upgrade nsl (pip install -U nsl), or set NSL_HOME to another workspace"
        )


def _migrate(
    conn: sqlite3.Connection,
    path: Path,
    migrations: Mapping[int, Callable[[sqlite3.Connection], None]],
    target: int,
    code_version: str,
) -> None:
    begin_immediate(conn)
    try:
        app_id, version, tables = _identify(conn)  # another process may have migrated meanwhile
        _check_identity(path, app_id, version, tables, target)
        for v in range(version + 1, target + 1):
            if v not in migrations:
                raise IncompatibleVersionError(f"{path}: no migration to catalog schema version {v}; upgrade nsl")
            migrations[v](conn)
            conn.execute(
                "INSERT INTO schema_history (version, applied, code_version) VALUES (?, ?, ?)",
                (v, utc_now(), code_version),
            )
        if version < target:
            conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
            conn.execute(f"PRAGMA user_version = {target}")
        conn.execute("COMMIT")
    except BaseException:
        conn.execute("ROLLBACK")
        raise
