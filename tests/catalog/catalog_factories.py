"""Factories for catalog tests: real dataset folders and real (tiny) safetensors checkpoints."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
from safetensors.numpy import save_file

from nsl import workspace
from nsl.catalog import Catalog, CheckpointEntry, DatasetEntry, DataUse


def make_dataset(cat: Catalog, name: str, version: int = 1, shift: str = "base", episodes: int = 10) -> DatasetEntry:
    """A dataset version folder with a data file and a manifest, registered in ``cat``."""
    root = workspace.datasets_dir() / name / f"v{version}"
    root.mkdir(parents=True, exist_ok=True)
    payload = f"{name}-{version}-{shift}-{episodes}".encode() * 16
    (root / "data.bin").write_bytes(payload)
    content_hash = hashlib.sha256(payload).hexdigest()
    (root / "manifest.json").write_text(json.dumps({"hash": content_hash, "files": ["data.bin"]}))
    spec = {"version": 1, "name": shift, "shifts": [] if shift == "base" else [{"name": shift, "severity": 1.0}]}
    return cat.register_dataset(
        name,
        version,
        root,
        hash=content_hash,
        shift=spec,
        episodes=episodes,
        provenance={"policy": "oracle:0.5", "seed": version},
    )


def manifest_hasher(root: Path) -> str:
    """What a datasets loader would do: re-hash the files its manifest lists."""
    files = json.loads((root / "manifest.json").read_text())["files"]
    h = hashlib.sha256()
    for f in files:
        h.update((root / f).read_bytes())
    return h.hexdigest()


def weights_file(tmp: Path, value: float, name: str = "w") -> Path:
    """A real tiny safetensors file whose content depends on ``value``."""
    path = Path(tmp) / f"{name}-{value}.safetensors"
    save_file(
        {"conv.weight": np.full((2, 3, 3), value, np.float32), "head.bias": np.arange(4, dtype=np.float32) + value},
        str(path),
    )
    return path


def make_checkpoint(
    cat: Catalog,
    tmp: Path,
    name: str,
    step: int,
    value: float,
    *,
    parent: str | None = None,
    data: list[DataUse] | tuple = (),
    shift: str | None = None,
) -> CheckpointEntry:
    config = {"model": {"channels": 8, "image_size": 64}, "train": {"lr": 1e-4, "name": name, "steps": step}}
    return cat.save_checkpoint(
        name,
        step,
        weights_file(tmp, value, name),
        config,
        parent=parent,
        data=list(data),
        shift=shift,
        code_version="test",
    )
