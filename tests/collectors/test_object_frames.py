"""Labelled frames of the train objects (the supervised features' data): reproducible, train objects only."""

from __future__ import annotations

import numpy as np
import pytest

from nsl.collectors import POSE_LABELS, object_classes, object_frames
from nsl.collectors.labelled_frames import CAMERA_HEIGHT
from nsl.collectors.objects import object_ids
from nsl.errors import ConfigError


def test_frames_are_labelled_by_train_object_and_reproducible():
    images, labels, poses = object_frames(per_class=3, seed=7, classes=4)
    assert images.shape == (12, 64, 64, 3) and images.dtype == np.uint8
    assert labels.tolist() == [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3]
    again = object_frames(per_class=3, seed=7, classes=4)
    other = object_frames(per_class=3, seed=8, classes=4)
    assert np.array_equal(images, again.images) and not np.array_equal(images, other.images)
    assert np.array_equal(poses, again.poses) and not np.array_equal(poses, other.poses)
    # the pose: the object within 3 cm of the wrist on each axis (a distance of at most 3 cm * sqrt 2 whatever the
    # yaw), the wrist 15-30 cm above the table and so above the object's centre by less than that
    assert poses.shape == (12, len(POSE_LABELS)) and poses.dtype == np.float32
    assert (np.hypot(poses[:, 0], poses[:, 1]) <= 0.03 * np.sqrt(2) + 1e-6).all()
    assert (poses[:, 2] < CAMERA_HEIGHT[1]).all() and (poses[:, 2] > 0).all()
    assert len({tuple(p) for p in poses}) == 12
    # every frame differs (pose, colour, viewpoint) and shows something besides the empty bin
    assert len({f.tobytes() for f in images}) == 12
    assert all(f.std() > 10 for f in images)


def test_the_classes_are_the_899_train_objects_and_never_a_test_object():
    classes = object_classes()
    assert len(classes) == 899 and set(classes) == set(object_ids("train"))
    assert not set(classes) & set(object_ids("test"))
    assert object_classes(5) == classes[:5]
    with pytest.raises(ConfigError, match="classes 1 is out of range"):
        object_classes(1)
