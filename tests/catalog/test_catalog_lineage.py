"""Registration, references, @best, tags, lineage and model cards on a real catalog."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
from catalog_factories import make_checkpoint, make_dataset, weights_file
from safetensors.numpy import load_file

from nsl.catalog import (
    CARD_FILE,
    CONFIG_FILE,
    WEIGHTS_FILE,
    Catalog,
    DataUse,
    best_checkpoint,
    checkpoint_id,
    folder_checkpoint_id,
    format_descendants,
    format_lineage,
    parse_checkpoint_ref,
    parse_data_ref,
)
from nsl.errors import ConfigError, UnknownReferenceError


@pytest.fixture
def cat():
    with Catalog() as c:
        yield c


@pytest.fixture
def chain(cat, tmp_path):
    """base -> harsh -> harsh-transparent, each stage mixing base data 50/50 with its target data."""
    base_data = make_dataset(cat, "grasp-base", 1, "base", 3000)
    harsh_data = make_dataset(cat, "harsh", 1, "harsh_lighting", 800)
    clear_data = make_dataset(cat, "clear", 2, "transparent_objects", 800)
    base = make_checkpoint(cat, tmp_path, "base", 50000, 0.0, data=[cat.resolve_data("data:grasp-base").use()])
    harsh = make_checkpoint(
        cat,
        tmp_path,
        "harsh",
        20000,
        1.0,
        parent=base.id,
        data=[cat.resolve_data("data:grasp-base@v1").use(0.5), cat.resolve_data("data:harsh@v1:800").use(0.5)],
    )
    clear = make_checkpoint(
        cat,
        tmp_path,
        "harsh-clear",
        20000,
        2.0,
        parent=harsh.id,
        data=[cat.resolve_data("data:grasp-base").use(0.5), cat.resolve_data("data:clear@v2:400").use(0.5)],
    )
    return {"data": (base_data, harsh_data, clear_data), "ckpts": (base, harsh, clear)}


def test_parse_references():
    assert parse_checkpoint_ref("ckpt:harsh@best:base").shift == "base"
    assert parse_checkpoint_ref("harsh@1500").selector == "1500"
    assert parse_data_ref("data:harsh@v3:800") == parse_data_ref("harsh@v3:800")
    assert parse_data_ref("data:harsh:800").version is None
    with pytest.raises(ConfigError, match=r"version '3'; write it as @vN"):
        parse_data_ref("data:harsh@3")
    with pytest.raises(ConfigError, match="is a dataset reference"):
        parse_checkpoint_ref("data:harsh")
    with pytest.raises(ConfigError, match="checkpoint name 'bad name' is not valid"):
        parse_checkpoint_ref("ckpt:bad name")


def test_lineage_across_three_step_fine_tuning_chain(cat, chain):
    base, harsh, clear = chain["ckpts"]
    lineage = cat.lineage("ckpt:harsh-clear")
    assert [c.id for c in lineage] == [clear.id, harsh.id, base.id]
    assert [c.shift for c in lineage] == ["transparent_objects", "harsh_lighting", "base"]
    assert [(u.dataset, u.version, u.tier, u.weight) for u in lineage[0].data] == [
        ("grasp-base", 1, None, 0.5),
        ("clear", 2, 400, 0.5),
    ]
    assert lineage[1].data[1].hash == chain["data"][1].hash
    text = format_lineage(cat, "ckpt:harsh-clear")
    lines = text.splitlines()
    assert lines[0].startswith(f"harsh-clear@20000  {clear.short_id}  trained for transparent_objects")
    assert "└─ from harsh@20000" in text and "└─ from base@50000" in text
    assert "data: clear@v2:400 (transparent_objects, 800 episodes), weight 0.5" in text
    assert "data: harsh@v1:800 (harsh_lighting, 800 episodes), weight 0.5" in text
    assert lines[-1].strip() == "└─ from scratch (no parent)"
    # each ancestor's own data is nested under it, deeper than the child's
    assert text.index("harsh@v1:800") > text.index("└─ from harsh@20000") > text.index("clear@v2:400")
    tree = format_descendants(cat, "ckpt:base").splitlines()
    assert tree[1].startswith("└─ harsh@20000") and tree[2].startswith("   └─ harsh-clear")


def test_checkpoint_folder_is_a_model_repo(cat, chain, tmp_path):
    base, harsh, clear = chain["ckpts"]
    folder = Path(clear.path)
    assert sorted(p.name for p in folder.iterdir()) == sorted([WEIGHTS_FILE, CONFIG_FILE, CARD_FILE])
    # the id: sha256(weights bytes, NUL, compact sorted config JSON), as nsl.learners defines it
    config = json.loads((folder / CONFIG_FILE).read_text())
    expected = hashlib.sha256(
        (folder / WEIGHTS_FILE).read_bytes()
        + b"\0"
        + json.dumps(config, sort_keys=True, separators=(",", ":")).encode()
    ).hexdigest()
    assert clear.id == expected == folder_checkpoint_id(folder) == checkpoint_id(folder / WEIGHTS_FILE, config)
    assert load_file(folder / WEIGHTS_FILE)["head.bias"].tolist() == [2.0, 3.0, 4.0, 5.0]
    assert json.loads((folder / CONFIG_FILE).read_text())["train"]["name"] == "harsh-clear"
    card = (folder / CARD_FILE).read_text()
    assert card.startswith("---\n") and "library_name: nsl" in card and "pipeline_tag: robotics" in card
    assert f"parent: {harsh.id}" in card
    assert "| `clear@v2` | transparent_objects | 800 | 400 | 0.5 |" in card
    assert f"- `harsh@20000` (`{harsh.short_id}`)" in card and f"- `base@50000` (`{base.short_id}`)" in card
    assert "Not evaluated yet" in card
    cat.add_evaluation(clear.id, "transparent_objects", episodes=50, successes=33, seed=0)
    cat.write_model_card("ckpt:harsh-clear")
    card = (folder / CARD_FILE).read_text()
    assert "| transparent_objects | test | 50 | 66.0% |" in card and "value: 0.66" in card
    assert folder_checkpoint_id(folder) == clear.id  # the card is not part of the id


def test_entries_are_append_only_and_registration_idempotent(cat, chain, tmp_path):
    base, harsh, _ = chain["ckpts"]
    before = cat.conn.execute("SELECT * FROM checkpoints WHERE id = ?", (base.id,)).fetchone()
    again = make_checkpoint(cat, tmp_path, "base", 50000, 0.0, data=[cat.resolve_data("data:grasp-base").use()])
    assert again == base
    assert cat.conn.execute("SELECT COUNT(*) FROM checkpoints").fetchone()[0] == 3
    # fine-tuning again from base gives a new entry; the parent row is untouched
    make_checkpoint(cat, tmp_path, "checker", 100, 5.0, parent=base.id)
    assert cat.conn.execute("SELECT * FROM checkpoints WHERE id = ?", (base.id,)).fetchone() == before
    with pytest.raises(ConfigError, match=r"already registered as ckpt:base@50000 .* append-only"):
        cat.save_checkpoint("renamed", 50000, Path(base.path) / WEIGHTS_FILE, base.config)
    d = chain["data"][1]
    assert make_dataset(cat, "harsh", 1, "harsh_lighting", 800) == d
    with pytest.raises(ConfigError, match=r"harsh@v1 is already registered with hash .* as harsh@v2"):
        make_dataset(cat, "harsh", 1, "harsh_lighting", 801)
    with pytest.raises(UnknownReferenceError, match="unknown version of dataset 'harsh' 'v7'"):
        cat.save_checkpoint("x", 1, weights_file(tmp_path, 9.0), {}, data=[DataUse("harsh", 7)])
    e = cat.add_evaluation(harsh.id, "base", episodes=20, successes=10, seed=3)
    assert cat.add_evaluation(harsh.id, "base", episodes=20, successes=10, seed=3) == e
    with pytest.raises(ConfigError, match="already recorded with 10 successes; evaluate with another --seed"):
        cat.add_evaluation(harsh.id, "base", episodes=20, successes=11, seed=3)


def test_best_follows_the_evaluations(cat, tmp_path):
    make_dataset(cat, "harsh", 1, "harsh_lighting", 800)
    uses = [cat.resolve_data("data:harsh").use()]
    ck = [make_checkpoint(cat, tmp_path, "harsh", step, float(step), data=uses) for step in (1000, 2000, 3000)]
    assert ck[0].shift == "harsh_lighting"  # from the last dataset it was trained on
    with pytest.raises(
        UnknownReferenceError,
        match=r"no checkpoint of 'harsh' has an evaluation on shift "
        r"'harsh_lighting'; run `nsl eval",
    ):
        cat.resolve_checkpoint("ckpt:harsh@best")
    cat.add_evaluation(ck[0].id, "harsh_lighting", episodes=100, successes=40, seed=0)
    cat.add_evaluation(ck[1].id, "harsh_lighting", episodes=100, successes=55, seed=0)
    cat.add_evaluation(ck[2].id, "harsh_lighting", episodes=100, successes=30, seed=0)
    cat.add_evaluation(ck[2].id, "base", episodes=100, successes=90, seed=0)
    assert cat.resolve_checkpoint("ckpt:harsh@best").step == 2000
    assert cat.resolve_checkpoint("ckpt:harsh@best:base").step == 3000
    assert cat.resolve_checkpoint("ckpt:harsh@best", shift="base").step == 3000
    assert cat.resolve_checkpoint("ckpt:harsh").step == 3000  # @latest is the newest, not the best
    # a second seed for step 1000 lifts its pooled rate to (40 + 79) / 200 = 59.5% > 55%
    cat.add_evaluation(ck[0].id, "harsh_lighting", episodes=100, successes=79, seed=1)
    entry, score = best_checkpoint(cat, "harsh")
    assert entry.step == 1000 and score["episodes"] == 200 and score["rate"] == pytest.approx(0.595)
    # only test-object evaluations when a split is asked for
    cat.add_evaluation(ck[2].id, "harsh_lighting", episodes=100, successes=100, seed=0, split="train")
    assert cat.resolve_checkpoint("ckpt:harsh@best", split="test").step == 1000
    assert cat.resolve_checkpoint("ckpt:harsh@best").step == 3000  # pooled over splits: 130/200 = 65%


def test_unknown_references_suggest_near_matches(cat, chain):
    with pytest.raises(UnknownReferenceError, match=r"unknown checkpoint 'hars'; did you mean 'harsh'"):
        cat.resolve_checkpoint("ckpt:hars@latest")
    with pytest.raises(UnknownReferenceError, match=r"unknown dataset 'grasp-bse'; did you mean 'grasp-base'"):
        cat.resolve_data("data:grasp-bse@v1")
    with pytest.raises(UnknownReferenceError, match=r"checkpoint 'harsh' has no step 200; its steps are 20000"):
        cat.resolve_checkpoint("ckpt:harsh@200")
    with pytest.raises(UnknownReferenceError, match=r"unknown version of dataset 'clear' 'v1'; did you mean 'v2'"):
        cat.resolve_data("data:clear@v1")
    cat.tag("production", "ckpt:harsh")
    with pytest.raises(UnknownReferenceError, match=r"unknown tag 'prodution'; did you mean 'production'"):
        cat.resolve_checkpoint("ckpt:harsh@prodution")


def test_tags_alias_move_and_delete(cat, chain):
    base, harsh, clear = chain["ckpts"]
    cat.tag("prod", "ckpt:harsh")
    assert cat.resolve_checkpoint("ckpt:prod") == harsh
    assert cat.resolve_checkpoint("ckpt:harsh@prod") == harsh
    with pytest.raises(ConfigError, match="tag 'prod' points to ckpt:harsh@20000, not to a checkpoint of 'base'"):
        cat.resolve_checkpoint("ckpt:base@prod")
    cat.tag("prod", clear.id)
    assert cat.resolve_checkpoint("ckpt:prod") == clear
    assert cat.conn.execute("SELECT COUNT(*) FROM tags WHERE tag = 'prod'").fetchone()[0] == 2  # history kept
    cat.untag("prod")
    assert "prod" not in cat.tags()
    with pytest.raises(UnknownReferenceError, match="unknown checkpoint 'prod'"):
        cat.resolve_checkpoint("ckpt:prod")
    with pytest.raises(ConfigError, match="would read as a selector"):
        cat.tag("best", "ckpt:base")
    with pytest.raises(ConfigError, match="also a checkpoint name"):
        cat.tag("harsh", "ckpt:base")
    assert cat.resolve_checkpoint(base.id[:8]) == base
