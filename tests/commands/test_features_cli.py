"""``nsl features``: supervised features trained on rendered train objects, or a torchvision ResNet from a file;
catalogued, idempotent, and refused in one line for a bad encoder."""

from __future__ import annotations

import json

import pytest
import torch
import torchvision

from nsl.catalog import Catalog
from nsl.learners import load_checkpoint
from tests.conftest import run_cli


def test_features_are_trained_on_the_train_objects_in_the_bases_architecture_and_catalogued(capsys):
    argv = ("features", "--classes", "3", "--frames", "4", "--steps", "3", "--batch-size", "8", "--name", "feat")
    assert run_cli(*argv) == 0
    out = capsys.readouterr().out
    assert out.startswith("ckpt:feat@0: 3 classes, held-out accuracy") and "(chance 33.33%)" in out
    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:feat")
        base = cat.resolve_checkpoint("ckpt:base")
    ckpt, parent = load_checkpoint(entry.path), load_checkpoint(base.path)
    assert ckpt.config["method"] == "supervised" and entry.parent is None
    assert ckpt.architecture == parent.architecture  # the base's trunk and head shapes
    assert ckpt.config["training"]["lr"] == parent.lr and ckpt.config["training"]["n_step"] == 8
    assert ckpt.config["data"]["frames"] == {"objects": "train", "classes": 3, "per_class": 4}
    # the same call again returns the same checkpoint; other settings under the same name are refused
    assert run_cli(*argv) == 0
    with Catalog() as cat:
        assert cat.resolve_checkpoint("ckpt:feat").id == entry.id
    assert run_cli(*argv[:-1], "feat", "--seed", "1") == 2
    assert "run 'feat' exists with a different configuration" in capsys.readouterr().err
    # the pose label: where the object is relative to the camera, its error against the mean's
    assert run_cli(*argv[:-1], "pose", "--label", "pose") == 0
    out = capsys.readouterr().out
    assert out.startswith("ckpt:pose@0: pose on held-out frames: squared error ") and "of the mean's (u " in out
    assert "held-out accuracy" not in out


def test_a_resnet_state_dict_becomes_the_features_trunk(tmp_path, capsys):
    path = tmp_path / "resnet18.pth"
    torch.manual_seed(0)
    torch.save(torchvision.models.resnet18().state_dict(), path)
    assert run_cli("features", "--encoder", str(path), "--name", "imagenet") == 0
    assert capsys.readouterr().out.startswith("ckpt:imagenet@0: resnet18 trunk from resnet18.pth (sha256 ")
    with Catalog() as cat:
        ckpt = load_checkpoint(cat.resolve_checkpoint("ckpt:imagenet").path)
    assert ckpt.architecture.encoder == "resnet18"
    assert json.loads(json.dumps(ckpt.config["data"]["encoder"]))["file"] == "resnet18.pth"


@pytest.mark.parametrize("kind", ["missing", "wrong architecture"])
def test_a_bad_encoder_fails_in_one_line(tmp_path, capsys, kind):
    path = tmp_path / "weights.pth"
    if kind == "wrong architecture":
        torch.save(torchvision.models.mobilenet_v3_small().state_dict(), path)
    assert run_cli("features", "--encoder", str(path)) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and err[0].startswith(f"nsl: error: --encoder {path}")
    assert ("no such file" if kind == "missing" else "is not a torchvision ResNet-18/34/50 state dict") in err[0]
