"""Where fine-tuning changes a network (Fig. 5.8): the cosine distance per layer between two checkpoints."""

from __future__ import annotations

import numpy as np
import pytest


def _checkpoint(folder, tensors: dict[str, np.ndarray]):
    from safetensors.numpy import save_file

    from nsl.learners import MODEL_FILE

    folder.mkdir()
    save_file({k: v.astype(np.float32) for k, v in tensors.items()}, str(folder / MODEL_FILE))
    return folder


def test_the_distance_is_zero_for_the_same_weights_scale_free_and_two_for_opposite_ones(tmp_path):
    from nsl.learners import layer_distances

    rng = np.random.default_rng(0)
    w = {"conv.0.weight": rng.normal(size=(4, 3)), "conv.0.bias": rng.normal(size=4), "head.weight": rng.normal(size=5)}
    a = _checkpoint(tmp_path / "a", w)
    b = _checkpoint(tmp_path / "b", {**w, "conv.0.weight": 3 * w["conv.0.weight"], "conv.0.bias": 3 * w["conv.0.bias"]})
    c = _checkpoint(tmp_path / "c", {**w, "head.weight": -w["head.weight"], "new.weight": np.ones(2)})
    assert layer_distances(a, a) == pytest.approx({"conv.0": 0.0, "head": 0.0}, abs=1e-6)
    assert layer_distances(a, b) == pytest.approx({"conv.0": 0.0, "head": 0.0}, abs=1e-6)  # scaled: no turn
    d = layer_distances(a, c)  # the head reversed; a layer only the fine-tune has is left out
    assert d == pytest.approx({"conv.0": 0.0, "head": 2.0}, abs=1e-6)
    x, y = np.concatenate([w["conv.0.bias"], w["conv.0.weight"].ravel()]), rng.normal(size=16)
    e = _checkpoint(tmp_path / "e", {**w, "conv.0.bias": y[:4], "conv.0.weight": y[4:].reshape(4, 3)})
    want = 1 - x @ y / (np.linalg.norm(x) * np.linalg.norm(y))  # weight and bias flattened together
    assert layer_distances(a, e)["conv.0"] == pytest.approx(want, rel=1e-5)
