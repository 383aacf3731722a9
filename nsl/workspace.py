"""Where nsl keeps its files: datasets, checkpoints, the catalog and runs; atomic file writes.

The workspace root is ``$NSL_HOME`` if set, otherwise ``~/.nsl``.  The base
checkpoint shipped with the package lives outside it (:func:`shipped_base_dir`).
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

DEFAULT_HOME = "~/.nsl"


def home() -> Path:
    return Path(os.environ.get("NSL_HOME") or DEFAULT_HOME).expanduser()


def datasets_dir() -> Path:
    return home() / "datasets"


def checkpoints_dir() -> Path:
    return home() / "checkpoints"


def runs_dir() -> Path:
    return home() / "runs"


def catalog_path() -> Path:
    return home() / "catalog.sqlite"


def cache_dir() -> Path:
    return home() / "cache"


def shipped_base_dir() -> Path:
    """The base checkpoint that ships with nsl (``ckpt:base`` in a workspace that has no checkpoint of that name)."""
    return Path(__file__).resolve().parent / "assets" / "base"


def file_sha256(path: Path) -> str:
    """The sha256 hex digest of a file."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_json(path: Path, obj: Any) -> None:
    atomic_write_bytes(path, (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode())
