"""Registration shares a run's weights file, names a re-registered checkpoint as an alias, and knows the shipped
base (``ckpt:base``) in every catalog command of an empty workspace."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest
from catalog_factories import make_dataset, weights_file

from nsl import checkpoint_format, workspace
from nsl.catalog import CONFIG_FILE, WEIGHTS_FILE, Catalog, folder_checkpoint_id
from nsl.errors import ConfigError, UnknownReferenceError
from tests.conftest import run_cli

SHIPPED = workspace.shipped_base_dir()


@pytest.fixture
def cat():
    with Catalog() as c:
        yield c


def _run_folder(tmp_path: Path, value: float) -> Path:
    """A training run's final checkpoint folder, as the learner leaves it."""
    folder = tmp_path / "runs" / "r" / "final"
    folder.mkdir(parents=True)
    os.replace(weights_file(tmp_path, value), folder / WEIGHTS_FILE)
    (folder / CONFIG_FILE).write_text(json.dumps({"step": 10, "training": {"seed": 0}}, indent=2, sort_keys=True))
    return folder


def test_registering_a_run_folder_hard_links_its_weights(cat, tmp_path):
    run = _run_folder(tmp_path, 1.0)
    config = json.loads((run / CONFIG_FILE).read_text())
    entry = cat.save_checkpoint("run", 10, run / WEIGHTS_FILE, config)
    stored = Path(entry.path) / WEIGHTS_FILE
    assert os.path.samefile(stored, run / WEIGHTS_FILE) and os.stat(stored).st_nlink == 2
    assert folder_checkpoint_id(entry.path) == folder_checkpoint_id(run) == entry.id


def test_weights_are_copied_only_where_a_link_is_impossible(cat, tmp_path, monkeypatch):
    run = _run_folder(tmp_path, 2.0)

    def cross_device(src, dst):
        raise OSError(errno.EXDEV, "Invalid cross-device link")

    monkeypatch.setattr(checkpoint_format.os, "link", cross_device)
    entry = cat.save_checkpoint("run", 10, run / WEIGHTS_FILE, json.loads((run / CONFIG_FILE).read_text()))
    stored = Path(entry.path) / WEIGHTS_FILE
    assert not os.path.samefile(stored, run / WEIGHTS_FILE)
    assert stored.read_bytes() == (run / WEIGHTS_FILE).read_bytes()


def test_a_deterministic_rerun_under_a_new_name_becomes_an_alias(cat, tmp_path):
    make_dataset(cat, "grasp-base", 1, "base", 100)
    data = [cat.resolve_data("data:grasp-base@v1").use()]
    config = {"step": 500, "training": {"seed": 0, "lr": 3e-4}}  # a learner's config holds no run name
    first = cat.save_checkpoint("seed0", 500, weights_file(tmp_path, 3.0), config, data=data)
    again = cat.save_checkpoint("seed0-again", 500, weights_file(tmp_path, 3.0, "again"), config, data=data)
    assert again == first and cat.names(first.id) == ["seed0", "seed0-again"]
    for ref in ("ckpt:seed0-again", "ckpt:seed0-again@500", "ckpt:seed0-again@latest"):
        assert cat.resolve_checkpoint(ref).id == first.id
    assert [c.id for c in cat.checkpoints("seed0-again")] == [first.id]
    assert len(cat.checkpoints()) == 1  # one entry, two names
    cat.add_evaluation(first.id, "base", episodes=10, successes=7, seed=1)
    assert cat.resolve_checkpoint("ckpt:seed0-again@best").id == first.id
    with pytest.raises(ConfigError, match="also a checkpoint name"):
        cat.tag("seed0-again", first.id)
    with pytest.raises(ConfigError, match="another step, parent or data"):
        cat.save_checkpoint("seed0-more", 500, weights_file(tmp_path, 3.0), config)  # the same, but no data recorded


def test_ckpt_base_is_the_shipped_base_with_its_recorded_data(cat):
    entry = cat.resolve_checkpoint("ckpt:base")
    record = json.loads((SHIPPED / "command.json").read_text())
    assert entry.name == "base" and entry.parent is None and entry.shift == "base"
    assert entry.id == folder_checkpoint_id(SHIPPED)
    assert [(u.dataset, u.version, u.weight, u.hash) for u in entry.data] == [
        (d["dataset"], d["version"], d["weight"], d["hash"]) for d in record["data"]
    ]
    assert (Path(entry.path) / WEIGHTS_FILE).read_bytes() == (SHIPPED / WEIGHTS_FILE).read_bytes()
    assert cat.resolve_checkpoint("ckpt:base@latest") == entry and len(cat.checkpoints()) == 1
    assert cat.checkpoint(f"ckpt:base@{entry.step}") == entry


@pytest.mark.parametrize("command", [["show"], ["lineage"], ["lineage", "--descendants"], ["verify"]])
def test_catalog_commands_know_ckpt_base_in_an_empty_workspace(command, capsys):
    assert not workspace.catalog_path().exists()
    record = json.loads((SHIPPED / "command.json").read_text())
    assert run_cli("catalog", command[0], "ckpt:base", *command[1:]) == 0
    out = capsys.readouterr().out
    assert ("ok: 1 checkpoint(s)" if command == ["verify"] else "base@") in out
    if command == ["lineage"]:
        for d in record["data"]:
            tier = f":{d['tier']}" if d.get("tier") else ""  # a first-K view of the dataset
            assert (
                f"data: {d['dataset']}@v{d['version']}{tier} (not in this catalog, content {d['hash'][7:19]}), "
                f"weight {d['weight']:g}" in out
            )
        assert "data: none recorded" not in out


def test_without_a_shipped_base_ckpt_base_is_unknown(cat, monkeypatch, tmp_path):
    monkeypatch.setattr(workspace, "shipped_base_dir", lambda: tmp_path / "nothing")
    with pytest.raises(UnknownReferenceError, match="unknown checkpoint 'base'"):
        cat.resolve_checkpoint("ckpt:base")


def test_training_again_under_a_new_name_adds_an_alias_and_shares_the_weights(capsys):
    assert (
        run_cli(
            "collect",
            "--shift",
            "base",
            "--episodes",
            "4",
            "--policy",
            "oracle:0.5",
            "--data",
            "tiny",
            "--num-envs",
            "4",
        )
        == 0
    )
    train = ("train", "--data", "tiny", "--steps", "2", "--batch-size", "8", "--seed", "3")
    assert run_cli(*train, "--name", "first") == 0
    assert run_cli(*train, "--name", "second") == 0  # same data, seed and parent: the same weights
    with Catalog() as cat:
        first, second = cat.resolve_checkpoint("ckpt:first"), cat.resolve_checkpoint("ckpt:second@2")
        assert first == second and cat.names(first.id) == ["first", "second"] and len(cat.checkpoints()) == 1
    stored = Path(first.path) / WEIGHTS_FILE
    for run in ("first", "second"):
        final = workspace.runs_dir() / run / "final" / WEIGHTS_FILE
        assert final.read_bytes() == stored.read_bytes()
    assert os.path.samefile(stored, workspace.runs_dir() / "first" / "final" / WEIGHTS_FILE)  # linked, not copied
    assert f"checkpoint ckpt:second@2 ({first.short_id})" in capsys.readouterr().out
