"""Checkpoints: safetensors plus config.json, loadable alone, refused with a clear message when inconsistent."""

from __future__ import annotations

import json
import shutil

import pytest
import torch

from nsl.errors import CorruptDataError, IncompatibleVersionError, UnknownReferenceError
from nsl.learners import (
    CONFIG_FILE,
    MODEL_FILE,
    TRAINER_FILE,
    checkpoint_id,
    load_checkpoint,
    read_config,
    save_checkpoint,
)


def _copy(src, tmp_path):
    dst = tmp_path / "ckpt"
    shutil.copytree(src, dst)
    return dst


def _edit_config(path, edit):
    cfg = json.loads((path / CONFIG_FILE).read_text())
    edit(cfg)
    (path / CONFIG_FILE).write_text(json.dumps(cfg))


def test_checkpoint_records_what_made_it_and_loads_without_trainer_state(parent_checkpoint):
    assert not (parent_checkpoint / TRAINER_FILE).exists()
    ckpt = load_checkpoint(parent_checkpoint)
    cfg = ckpt.config
    assert cfg["step"] == 20 and cfg["method"] == "scratch" and cfg["parent"] is None
    assert cfg["training"]["lr"] == 1e-3 and cfg["training"]["gamma"] == 0.9
    assert cfg["architecture"]["hidden"] == 16 and cfg["architecture"]["action_dims"] == [0, 1, 3, 5]
    assert cfg["data"]["sources"][0]["name"] == "random" and cfg["data"]["sources"][0]["weight"] == 1.0
    assert cfg["code_version"].startswith("0.")
    assert not ckpt.net.training


def test_periodic_checkpoints_keep_the_trainer_state_of_the_newest_only(parent_checkpoint):
    steps = sorted((parent_checkpoint.parent / "checkpoints").iterdir())
    assert [p.name for p in steps] == ["step-000000010", "step-000000020"]
    assert not (steps[0] / TRAINER_FILE).exists() and (steps[1] / TRAINER_FILE).exists()
    assert torch.equal(
        load_checkpoint(steps[1]).net.columns[0].out.weight,
        load_checkpoint(parent_checkpoint).net.columns[0].out.weight,
    )


def test_checkpoint_id_is_a_content_hash(parent_checkpoint, tmp_path):
    copy = _copy(parent_checkpoint, tmp_path)
    assert checkpoint_id(copy) == checkpoint_id(parent_checkpoint)
    ckpt = load_checkpoint(copy)
    with torch.no_grad():
        ckpt.net.columns[0].out.bias.add_(1.0)
    save_checkpoint(copy, ckpt.net, ckpt.config)
    assert checkpoint_id(copy) != checkpoint_id(parent_checkpoint)
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_missing_config_is_refused(parent_checkpoint, tmp_path):
    path = _copy(parent_checkpoint, tmp_path)
    (path / CONFIG_FILE).unlink()
    with pytest.raises(CorruptDataError, match=r"has no config\.json"):
        load_checkpoint(path)


def test_missing_weights_are_refused(parent_checkpoint, tmp_path):
    path = _copy(parent_checkpoint, tmp_path)
    (path / MODEL_FILE).unlink()
    with pytest.raises(CorruptDataError, match=r"has no model\.safetensors"):
        load_checkpoint(path)


def test_config_without_required_keys_is_refused(parent_checkpoint, tmp_path):
    path = _copy(parent_checkpoint, tmp_path)
    _edit_config(path, lambda c: c.pop("architecture"))
    with pytest.raises(CorruptDataError, match=r"lacks key\(s\) \['architecture'\]"):
        load_checkpoint(path)


def test_architecture_that_does_not_match_the_weights_is_refused(parent_checkpoint, tmp_path):
    path = _copy(parent_checkpoint, tmp_path)
    _edit_config(path, lambda c: c["architecture"].update(hidden=32))
    with pytest.raises(CorruptDataError, match=r"tensor columns\.0\.\S+ has shape .* but the architecture"):
        load_checkpoint(path)
    _edit_config(path, lambda c: c["architecture"].update(hidden=16, columns=2))
    with pytest.raises(CorruptDataError, match=r"weights do not match the architecture .*missing \['columns\.1"):
        load_checkpoint(path)


def test_invalid_or_unknown_architecture_fields_are_refused(parent_checkpoint, tmp_path):
    path = _copy(parent_checkpoint, tmp_path)
    _edit_config(path, lambda c: c["architecture"].update(action_dims=[0, 7]))
    with pytest.raises(CorruptDataError, match=r"invalid 'architecture' .*action_dims"):
        load_checkpoint(path)
    _edit_config(path, lambda c: c["architecture"].update(action_dims=[0, 1], colour="red"))
    with pytest.raises(CorruptDataError, match=r"unknown field\(s\) \['colour'\]"):
        load_checkpoint(path)


def test_newer_format_version_is_refused(parent_checkpoint, tmp_path):
    path = _copy(parent_checkpoint, tmp_path)
    _edit_config(path, lambda c: c.update(version=99))
    with pytest.raises(IncompatibleVersionError, match="format version 99"):
        read_config(path)


def test_truncated_weights_and_missing_folders_are_refused(parent_checkpoint, tmp_path):
    path = _copy(parent_checkpoint, tmp_path)
    data = (path / MODEL_FILE).read_bytes()
    (path / MODEL_FILE).write_bytes(data[: len(data) // 2])
    with pytest.raises(CorruptDataError, match="truncated or altered"):
        load_checkpoint(path)
    with pytest.raises(UnknownReferenceError, match="no checkpoint folder"):
        load_checkpoint(tmp_path / "nowhere")
