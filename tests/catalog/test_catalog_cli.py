"""`nsl catalog ...` through the real entry point."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
from catalog_factories import make_checkpoint, make_dataset

from nsl import workspace
from nsl.catalog import WEIGHTS_FILE, Catalog
from tests.conftest import run_cli


@pytest.fixture
def chain(tmp_path):
    with Catalog() as cat:
        make_dataset(cat, "grasp-base", 1, "base", 3000)
        make_dataset(cat, "harsh", 1, "harsh_lighting", 800)
        base = make_checkpoint(cat, tmp_path, "base", 50000, 0.0, data=[cat.resolve_data("data:grasp-base").use()])
        h1 = make_checkpoint(
            cat,
            tmp_path,
            "harsh",
            1000,
            1.0,
            parent=base.id,
            data=[cat.resolve_data("data:grasp-base").use(0.5), cat.resolve_data("data:harsh:800").use(0.5)],
        )
        h2 = make_checkpoint(cat, tmp_path, "harsh", 2000, 2.0, parent=base.id, data=h1.data)
        cat.add_evaluation(h1.id, "harsh_lighting", episodes=100, successes=61, seed=7)
        cat.add_evaluation(h2.id, "harsh_lighting", episodes=100, successes=48, seed=7)
        return base, h1, h2


def test_ls_show_and_json(chain, capsys):
    base, h1, h2 = chain
    assert run_cli("catalog", "ls") == 0
    out = capsys.readouterr().out
    assert "datasets (2)" in out and "checkpoints (3)" in out and "evaluations (2)" in out
    assert f"{h1.short_id}  harsh@1000  harsh_lighting  base@50000  grasp-base@v1 x0.5, harsh@v1:800 x0.5" in out
    assert run_cli("catalog", "ls", "checkpoints", "--name", "harsh", "--json") == 0
    listed = json.loads(capsys.readouterr().out)["checkpoints"]
    assert [c["id"] for c in listed] == [h1.id, h2.id] and listed[0]["parent"] == base.id
    assert run_cli("catalog", "show", "ckpt:harsh@best") == 0
    out = capsys.readouterr().out
    assert "checkpoint harsh@1000" in out and f"parent     base@50000 ({base.short_id})" in out
    assert "61.0%" in out
    assert run_cli("catalog", "show", "data:harsh@v1:800") == 0
    out = capsys.readouterr().out
    assert "dataset    harsh@v1  (tier 800)" in out and "trained    harsh@1000, harsh@2000" in out


def test_lineage_prints_a_tree(chain, capsys):
    base, h1, h2 = chain
    assert run_cli("catalog", "lineage", "ckpt:harsh@best") == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith(f"harsh@1000  {h1.short_id}  trained for harsh_lighting")
    assert out[1] == "├─ data: grasp-base@v1 (base, 3000 episodes), weight 0.5"
    assert out[2] == "├─ data: harsh@v1:800 (harsh_lighting, 800 episodes), weight 0.5"
    assert out[3].startswith("├─ eval: harsh_lighting (test objects) 61.0% [")
    assert out[4].startswith(f"└─ from base@50000  {base.short_id}  trained for base")
    assert out[-1] == "   └─ from scratch (no parent)"
    assert run_cli("catalog", "lineage", "--descendants", "ckpt:base") == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1].startswith("├─ harsh@1000") and out[2].startswith("└─ harsh@2000")


def test_tag_then_use_and_delete(chain, capsys):
    assert run_cli("catalog", "tag", "ckpt:harsh@best", "harsh-best") == 0
    assert "tagged harsh@1000" in capsys.readouterr().out
    assert run_cli("catalog", "show", "ckpt:harsh-best", "--json") == 0
    assert json.loads(capsys.readouterr().out)["tags"] == ["harsh-best"]
    assert run_cli("catalog", "tag", "--delete", "harsh-best") == 0
    assert run_cli("catalog", "show", "ckpt:harsh-best") == 2
    assert "unknown checkpoint 'harsh-best'" in capsys.readouterr().err


def test_errors_are_one_line(chain, capsys):
    assert run_cli("catalog", "show", "ckpt:hrash") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("nsl: error: unknown checkpoint 'hrash'; did you mean 'harsh'?")
    assert run_cli("catalog", "rm", "ckpt:base") == 2
    assert "has dependents: 2 child checkpoint(s) (harsh@1000, harsh@2000)" in capsys.readouterr().err


def test_rm_verify_and_gc(chain, capsys):
    base, h1, h2 = chain
    assert run_cli("catalog", "verify") == 0
    assert "ok: 3 checkpoint(s) and 2 dataset(s)" in capsys.readouterr().out
    weights = Path(h2.path) / WEIGHTS_FILE
    weights.write_bytes(weights.read_bytes()[:-4] + b"\0\0\0\0")
    assert run_cli("catalog", "verify") == 2
    captured = capsys.readouterr()
    assert f"ckpt:harsh@2000: {weights}: altered" in captured.out
    assert "verify found 1 problem(s)" in captured.err
    assert run_cli("catalog", "rm", "ckpt:harsh@2000", "--force", "--keep-files") == 0
    assert "removed 1 evaluation(s)" in capsys.readouterr().out
    assert Path(h2.path).is_dir()  # kept, now unreferenced: gc's job
    old = time.time() - 7200
    os.utime(h2.path, (old, old))
    for f in Path(h2.path).iterdir():
        os.utime(f, (old, old))
    assert run_cli("catalog", "gc") == 0  # no terminal under pytest and no --yes: lists only
    out = capsys.readouterr().out
    assert "unregistered checkpoint folder" in out and "dry run" in out and Path(h2.path).is_dir()
    assert run_cli("catalog", "gc", "--yes") == 0
    assert "removed 1 item(s)" in capsys.readouterr().out and not Path(h2.path).exists()
    assert run_cli("catalog", "gc", "--yes") == 0
    assert capsys.readouterr().out.strip() == "nothing to remove"
    assert run_cli("catalog", "verify") == 0
    assert workspace.catalog_path().exists()
