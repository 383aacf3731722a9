"""The shared core: one dataset reference grammar and one checkpoint folder format for every folder."""

from __future__ import annotations

import json

import pytest

from nsl import checkpoint_format as fmt
from nsl.catalog import Catalog, DataUse
from nsl.datasets import api
from nsl.errors import ConfigError, CorruptDataError
from nsl.refs import DataRef, parse_data_ref


@pytest.mark.parametrize(
    "text, expected",
    [
        ("grasp", DataRef("grasp")),
        ("data:grasp@v2", DataRef("grasp", 2)),
        ("grasp-base@v1:800", DataRef("grasp-base", 1, 800)),
        ("data:grasp:25", DataRef("grasp", None, 25)),
    ],
)
def test_datasets_and_catalog_read_references_alike(text, expected):
    assert parse_data_ref(text) == api.parse_ref(text) == expected
    assert isinstance(expected.tier, (int, type(None)))


@pytest.mark.parametrize(
    "text, message",
    [
        ("grasp@2", r"malformed: version '2'; write it as @vN"),
        ("grasp@v0", "malformed: version 'v0'"),
        ("grasp@v1:abc", "tier 'abc' is not a number of episodes"),
        ("grasp@v1:0", "tier '0' must be at least 1 episode"),
        ("ckpt:base", "is a checkpoint reference"),
        ("bad name", "dataset name 'bad name' is not valid"),
    ],
)
def test_bad_references_are_refused_with_one_line(text, message):
    with pytest.raises(ConfigError, match=message):
        parse_data_ref(text)


def test_the_catalog_records_a_tier_as_the_episode_count():
    use = DataUse("harsh", 1, 0.5, "800")  # as an older catalog row stores it
    assert use.tier == 800 and use == DataUse("harsh", 1, 0.5, 800) and use.ref == "data:harsh@v1:800"
    with pytest.raises(ConfigError, match="tier of dataset 'harsh'"):
        DataUse("harsh", 1, 0.5, "all")


def test_resolved_data_hands_the_loader_the_same_tier(tmp_path):
    root = tmp_path / "harsh"
    root.mkdir()
    (root / "f").write_bytes(b"x")
    with Catalog() as cat:
        cat.register_dataset("harsh", 1, root, hash="h", shift="harsh_lighting", episodes=800)
        assert cat.resolve_data("data:harsh@v1:400").tier == api.parse_ref("harsh@v1:400").tier == 400


def test_folders_appear_whole_and_are_not_overwritten_unless_asked(tmp_path):
    dest = tmp_path / "ckpt"
    assert fmt.write_folder(dest, {fmt.CONFIG_FILE: b'{"a": 1}\n', fmt.WEIGHTS_FILE: b"w1"})
    assert not fmt.write_folder(dest, {fmt.CONFIG_FILE: b'{"a": 2}\n', fmt.WEIGHTS_FILE: b"w2"})
    assert fmt.read_config(dest) == {"a": 1}
    assert fmt.write_folder(dest, {fmt.CONFIG_FILE: b'{"a": 3}\n', fmt.WEIGHTS_FILE: b"w3"}, replace=True)
    assert fmt.read_config(dest) == {"a": 3} and (dest / fmt.WEIGHTS_FILE).read_bytes() == b"w3"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ckpt"]  # no temporary folder left behind


def test_the_id_ignores_config_formatting_but_not_content(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    fmt.write_folder(a, {fmt.CONFIG_FILE: fmt.encode_config({"x": 1, "y": [1, 2]}), fmt.WEIGHTS_FILE: b"w"})
    fmt.write_folder(b, {fmt.CONFIG_FILE: json.dumps({"y": [1, 2], "x": 1}).encode(), fmt.WEIGHTS_FILE: b"w"})
    assert fmt.folder_checkpoint_id(a) == fmt.folder_checkpoint_id(b) == fmt.checkpoint_id(b"w", {"x": 1, "y": [1, 2]})
    assert fmt.checkpoint_id(b"w", {"x": 2, "y": [1, 2]}) != fmt.folder_checkpoint_id(a)
    (b / fmt.CONFIG_FILE).write_text("[1]")
    with pytest.raises(CorruptDataError, match="must hold a JSON object"):
        fmt.folder_checkpoint_id(b)
