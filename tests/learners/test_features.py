"""Supervised features: the trunk trained as a classifier, a torchvision ResNet as the trunk, and the frozen-trunk
fine-tune that starts from either."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import torch
import torchvision
from learner_factories import TINY_NET, random_transitions, tiny_train

from nsl.errors import ConfigError
from nsl.learners import (
    ArraySampler,
    FeatureConfig,
    NetConfig,
    TrainConfig,
    encoder_features,
    load_checkpoint,
    load_encoder,
    train,
    train_features,
)
from nsl.learners.networks import is_head_parameter

TARGET = ArraySampler.from_transitions(random_transitions(64, seed=9), name="target")


def _classes(per_class: int, classes: int = 4, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Noisy images whose colour is their class: a task any trunk learns in a few dozen steps."""
    rng = np.random.default_rng(seed)
    colours = np.array([[230, 30, 30], [30, 230, 30], [30, 30, 230], [230, 230, 30]])[:classes]
    labels = np.repeat(np.arange(classes), per_class)
    noise = rng.integers(-40, 40, (len(labels), 16, 16, 3))
    return np.clip(colours[labels][:, None, None, :] + noise, 0, 255).astype(np.uint8), labels


def _digest(path) -> str:
    return hashlib.sha256((path / "model.safetensors").read_bytes()).hexdigest()


def _features(tmp_path, name: str, seed: int = 0, steps: int = 40):
    images, labels = _classes(per_class=10)
    out = tmp_path / name
    result = train_features(
        images,
        labels,
        architecture=TINY_NET,
        training=TrainConfig(lr=1e-3),
        config=FeatureConfig(steps=steps, batch_size=16, lr=3e-3, seed=seed),
        data={"frames": "colours"},
        out=out,
        per_class=10,
        progress=False,
    )
    return out, result


def test_the_supervised_trunks_pretraining_is_deterministic_and_learns_the_classes(tmp_path):
    a, result = _features(tmp_path, "a")
    b, _ = _features(tmp_path, "b")
    c, _ = _features(tmp_path, "c", seed=1)
    assert _digest(a) == _digest(b) != _digest(c)
    assert result["classes"] == 4 and result["chance"] == 0.25
    assert result["heldout_accuracy"] == 1.0  # 8 frames of 4 colours never trained on
    config = load_checkpoint(a).config
    assert config["method"] == "supervised" and config["parent"] is None
    assert config["data"]["features"]["heldout_accuracy"] == 1.0 and config["data"]["frames"] == "colours"
    assert config["training"]["lr"] == 1e-3  # the recipe a fine-tune from it takes a quarter of


def _located(per_class: int, classes: int = 4, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames of a bright square on a dark noisy field, its position the pose to regress (u, v in pixels, h a
    constant): any trunk learns where the square is."""
    rng = np.random.default_rng(seed)
    n = classes * per_class
    images = rng.integers(0, 40, (n, 16, 16, 3)).astype(np.uint8)
    poses = np.zeros((n, 3), np.float32)
    for i in range(n):
        y, x = rng.integers(0, 12, 2)
        images[i, y : y + 4, x : x + 4] = 230
        poses[i] = (x, y, 1.0)
    return images, np.repeat(np.arange(classes), per_class), poses


def _pose_features(tmp_path, name: str, label: str, steps: int = 150):
    images, labels, poses = _located(per_class=20)
    return train_features(
        images,
        labels,
        architecture=TINY_NET,
        training=TrainConfig(lr=1e-3),
        config=FeatureConfig(steps=steps, batch_size=32, lr=3e-3, holdout=5, label=label),
        data={"frames": "squares"},
        out=tmp_path / name,
        per_class=20,
        poses=poses,
        progress=False,
    )


def test_the_pose_label_trains_the_trunk_to_locate_and_records_its_error_against_the_mean(tmp_path):
    result = _pose_features(tmp_path, "pose", "pose")
    assert "heldout_accuracy" not in result
    ratios = result["heldout_pose_error_ratios"]
    # held-out frames: far better than predicting the mean position (ratio 1), the constant h aside
    assert ratios[0] < 0.3 and ratios[1] < 0.3 and result["heldout_pose_error_ratio"] < 1.0
    features = load_checkpoint(tmp_path / "pose").config["data"]["features"]
    assert features["label"] == "pose" and features["heldout_pose_error_ratios"] == ratios
    from nsl.study.report.gather import features_accuracy  # what a study's report reads of it

    assert features_accuracy(tmp_path / "pose")["heldout_pose_error_ratio"] == result["heldout_pose_error_ratio"]
    untrained = _pose_features(tmp_path, "few", "pose", steps=1)
    assert untrained["heldout_pose_error_ratios"][0] > 2 * ratios[0]  # the fit is the training, not the head
    both = _pose_features(tmp_path, "both", "both", steps=20)
    assert {"heldout_accuracy", "heldout_pose_error_ratio"} <= set(both)
    classes = load_checkpoint(_features(tmp_path, "classes")[0]).config["data"]["features"]
    assert "label" not in classes  # a classifier's record is what it was before the pose label


def test_a_pose_label_without_poses_is_refused(tmp_path):
    images, labels = _classes(per_class=10)
    with pytest.raises(ConfigError, match="label 'pose' needs a pose for each of the 40 frames"):
        train_features(
            images,
            labels,
            architecture=TINY_NET,
            training=TrainConfig(),
            config=FeatureConfig(steps=1, label="pose"),
            data={},
            out=tmp_path / "x",
            per_class=10,
        )
    with pytest.raises(ConfigError, match="label 'poses' is unknown; use one of classes, pose, both"):
        FeatureConfig(label="poses")


def test_new_head_frozen_trains_only_a_fresh_head_and_new_head_trains_the_trunk_too(tmp_path):
    parent, _ = _features(tmp_path, "features")
    before = load_checkpoint(parent).net.state_dict()
    for method in ("new_head_frozen", "new_head"):
        result = train(
            tiny_train(steps=6, lr=1e-2),
            TARGET,
            tmp_path / method,
            init_checkpoint=parent,
            method=method,
            progress=False,
        )
        after = load_checkpoint(result.checkpoint).net.state_dict()
        trunk = [k for k in before if not is_head_parameter(k)]
        head = [k for k in before if is_head_parameter(k)]
        assert all(not torch.equal(before[k], after[k]) for k in head), method
        assert all(torch.equal(before[k], after[k]) for k in trunk) == (method == "new_head_frozen"), method
        assert load_checkpoint(result.checkpoint).config["method"] == method


def test_a_torchvision_resnet_becomes_the_trunk_and_fine_tunes_frozen(tmp_path):
    torch.manual_seed(0)
    resnet = torchvision.models.resnet18()
    path = tmp_path / "resnet18.pth"
    torch.save(resnet.state_dict(), path)
    record = encoder_features(path, architecture=TINY_NET, training=TrainConfig(lr=1e-3), out=tmp_path / "enc")
    assert record["architecture"] == "resnet18" and record["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    ckpt = load_checkpoint(tmp_path / "enc")
    assert ckpt.architecture.encoder == "resnet18" and not ckpt.architecture.coord_channels
    trunk = ckpt.net.columns[0].encoder.state_dict()
    assert torch.equal(trunk["layer4.1.conv2.weight"], resnet.state_dict()["layer4.1.conv2.weight"])
    # the frozen batch norms act per image: a frame's Q-values do not depend on the rest of the batch
    x = torch.rand(3, 3, 16, 16)
    s, a = torch.rand(3, 6), torch.rand(3, 4)
    assert torch.allclose(ckpt.net(x, s, a)[:1], ckpt.net(x[:1], s[:1], a[:1]), atol=1e-6)
    result = train(
        tiny_train(steps=3),
        TARGET,
        tmp_path / "ft",
        init_checkpoint=tmp_path / "enc",
        method="new_head_frozen",
        progress=False,
    )
    after = load_checkpoint(result.checkpoint).net.columns[0].encoder.state_dict()
    assert all(torch.equal(trunk[k], after[k]) for k in trunk)


def test_the_conv_trunks_architecture_record_is_unchanged_by_the_encoder_option():
    assert "encoder" not in NetConfig().to_dict()  # checkpoint ids made before the option hold
    assert NetConfig.from_dict({**NetConfig().to_dict(), "encoder": "conv"}) == NetConfig()
    with pytest.raises(ConfigError, match="net.encoder 'vgg'"):
        NetConfig(encoder="vgg")
    with pytest.raises(ConfigError, match="coord_channels false"):
        NetConfig(encoder="resnet18")


@pytest.mark.parametrize("kind", ["missing", "mobilenet", "junk", "tensor"])
def test_a_bad_encoder_file_fails_in_one_line(tmp_path, kind):
    path = tmp_path / f"{kind}.pth"
    if kind == "mobilenet":
        torch.save(torchvision.models.mobilenet_v3_small().state_dict(), path)
    elif kind == "junk":
        path.write_text("not weights")
    elif kind == "tensor":
        torch.save(torch.zeros(3), path)
    with pytest.raises(ConfigError) as e:
        load_encoder(path)
    message = str(e.value)
    assert "\n" not in message and str(path) in message and "torchvision.models.resnet18" in message
    if kind == "mobilenet":
        assert "not a torchvision ResNet-18/34/50 state dict" in message
