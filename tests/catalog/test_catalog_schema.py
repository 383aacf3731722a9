"""The catalog file: WAL, schema version, refusing foreign or newer files, migrations."""

from __future__ import annotations

import sqlite3

import pytest
from catalog_factories import make_dataset

from nsl import workspace
from nsl.catalog import MIGRATIONS, SCHEMA_VERSION, Catalog
from nsl.catalog.schema import APPLICATION_ID, connect
from nsl.errors import ConfigError, CorruptDataError, IncompatibleVersionError


def test_new_catalog_is_wal_with_schema_version():
    with Catalog() as cat:
        assert cat.path == workspace.catalog_path()
        assert cat.conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert cat.conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
        assert cat.conn.execute("PRAGMA application_id").fetchone()[0] == APPLICATION_ID
        tables = {r[0] for r in cat.conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        assert {"datasets", "checkpoints", "evaluations", "tags", "schema_history"} <= tables
    with Catalog() as cat:  # reopening does not migrate again
        assert cat.conn.execute("SELECT COUNT(*) FROM schema_history").fetchone()[0] == SCHEMA_VERSION


def test_text_file_is_refused(nsl_home):
    path = workspace.catalog_path()
    path.write_text("these are my notes, not a database\n" * 50)
    with pytest.raises(CorruptDataError, match=r"catalog\.sqlite is not an nsl catalog \(not an SQLite database"):
        Catalog()
    assert path.read_text().startswith("these are my notes")  # untouched


def test_foreign_sqlite_database_is_refused():
    path = workspace.catalog_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE recipes (name TEXT)")
    con.commit()
    con.close()
    with pytest.raises(CorruptDataError, match=r"is not an nsl catalog \(an SQLite database with tables: recipes\)"):
        Catalog()
    con = sqlite3.connect(path)  # still the user's database, not converted
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
    assert con.execute("PRAGMA user_version").fetchone()[0] == 0
    con.close()


def test_newer_schema_is_refused():
    Catalog().close()
    con = sqlite3.connect(workspace.catalog_path())
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.close()
    with pytest.raises(
        IncompatibleVersionError,
        match=rf"schema version {SCHEMA_VERSION + 1}, but this nsl reads versions up to "
        rf"{SCHEMA_VERSION}; upgrade nsl",
    ):
        Catalog()


def _v2_add_notes(conn: sqlite3.Connection) -> None:
    conn.execute("ALTER TABLE checkpoints ADD COLUMN notes TEXT NOT NULL DEFAULT ''")


def test_migration_path_upgrades_old_files_and_keeps_rows(tmp_path):
    with Catalog() as cat:
        make_dataset(cat, "grasp-base")
    path = workspace.catalog_path()
    conn = connect(path, {**MIGRATIONS, SCHEMA_VERSION + 1: _v2_add_notes}, code_version="future")
    assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION + 1
    cols = [r[1] for r in conn.execute("PRAGMA table_info(checkpoints)")]
    assert "notes" in cols
    assert conn.execute("SELECT name, version FROM datasets").fetchall() == [("grasp-base", 1)]
    history = conn.execute("SELECT version, code_version FROM schema_history ORDER BY version").fetchall()
    assert history[-1] == (SCHEMA_VERSION + 1, "future")
    conn.close()
    with pytest.raises(IncompatibleVersionError, match="upgrade nsl"):
        Catalog(path)  # this release is now older than the file


def test_empty_file_becomes_a_catalog():
    path = workspace.catalog_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"")
    with Catalog() as cat:
        assert cat.datasets() == []


def test_a_version_3_catalog_keeps_its_evaluations_and_then_holds_both_precisions_on_the_same_scenes(tmp_path):
    from catalog_factories import make_checkpoint

    from nsl.catalog.schema import _v4

    with Catalog() as cat:
        ckpt = make_checkpoint(cat, tmp_path, "ft", 10, 0.5)
    # the evaluations table as version 3 wrote it (no precision column), with one record, then migration 4
    old = sqlite3.connect(workspace.catalog_path())
    old.execute("DROP TABLE evaluations")
    old.execute(
        "CREATE TABLE evaluations (id INTEGER PRIMARY KEY AUTOINCREMENT, checkpoint TEXT NOT NULL, shift TEXT NOT "
        "NULL, split TEXT NOT NULL, episodes INTEGER NOT NULL, successes INTEGER NOT NULL, ci_low REAL NOT NULL, "
        "ci_high REAL NOT NULL, seed INTEGER NOT NULL, extra TEXT NOT NULL, created TEXT NOT NULL, "
        "UNIQUE (checkpoint, shift, split, seed, episodes))"
    )
    old.execute(
        "INSERT INTO evaluations (checkpoint, shift, split, episodes, successes, ci_low, ci_high, seed, extra, "
        "created) VALUES (?, 'base', 'test', 100, 80, 0.7, 0.9, 3000, '{}', '2026-01-01T00:00:00Z')",
        (ckpt.id,),
    )
    _v4(old)
    old.commit()
    old.close()
    with Catalog() as cat:
        (e,) = cat.evaluations(ckpt.id)
        assert (e.successes, e.seed, e.precision) == (80, 3000, "fp32")
        bf16 = cat.add_evaluation(ckpt.id, "base", episodes=100, successes=78, seed=3000, precision="bf16")
        assert bf16.precision == "bf16" and len(cat.evaluations(ckpt.id)) == 2
        with pytest.raises(Exception, match="fp32\\) is already recorded with 80 successes"):
            cat.add_evaluation(ckpt.id, "base", episodes=100, successes=79, seed=3000)
        # a GPU's batched acting is a record of its own, named by the states searched together
        gpu = cat.add_evaluation(ckpt.id, "base", episodes=100, successes=81, seed=3000, precision="fp32/cuda/8")
        assert gpu.precision == "fp32/cuda/8" and len(cat.evaluations(ckpt.id)) == 3
        for bad in ("fp16", "fp32/cuda", "fp32/cuda/0", "fp32/tpu/8"):
            with pytest.raises(ConfigError, match="must be fp32 or bf16"):
                cat.add_evaluation(ckpt.id, "base", episodes=100, successes=1, seed=3000, precision=bad)
