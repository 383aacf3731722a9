"""Where fine-tuning changes a network: the cosine distance between two checkpoints' weights, layer by layer
(the source study's Fig. 5.8).

A layer is a module of the Q-network (its weight and bias together, flattened into one vector);
the distance is ``1 - cos(a, b)``: 0 for unchanged weights, growing as the fine-tune turns them away from the
pre-trained ones (scale-free, so a layer's size or norm does not weigh in).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _layers(path: Path) -> dict[str, np.ndarray]:
    from safetensors.numpy import load_file

    from .checkpoint import MODEL_FILE

    tensors = load_file(str(Path(path) / MODEL_FILE))
    layers: dict[str, list[np.ndarray]] = {}
    for name in sorted(tensors):
        layers.setdefault(name.rsplit(".", 1)[0], []).append(tensors[name].astype(np.float64).ravel())
    return {k: np.concatenate(v) for k, v in layers.items()}


def layer_distances(pretrained: Path, finetuned: Path) -> dict[str, float]:
    """``{layer: 1 - cosine similarity}`` between two checkpoint folders' weights, in the network's order of
    names; layers missing from either (a new head, a PNN column) are left out."""
    a, b = _layers(pretrained), _layers(finetuned)
    out = {}
    for name, x in a.items():
        y = b.get(name)
        if y is None or y.shape != x.shape:
            continue
        norm = float(np.linalg.norm(x) * np.linalg.norm(y))
        out[name] = 0.0 if norm == 0 else float(1.0 - np.dot(x, y) / norm)
    return out
