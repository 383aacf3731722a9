"""Checkpoint folders as the catalog keeps them: the shared format plus a model card, and file digests.

The folder format itself (file names, the content-hash id, atomic writes)
belongs to ``nsl.checkpoint_format``; the learner writes folders in the same
format.  A catalogued folder holds ``model.safetensors``, ``config.json`` and
a generated ``README.md`` model card.  The card is derived from the catalog
and may be regenerated (for example after new evaluations); it is not part of
the id.

Registering a folder that already exists elsewhere (a training run's
``final/``) hard-links its weights instead of copying them; a copy is made
only where a link is impossible (another file system).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nsl.checkpoint_format import (  # noqa: F401  (re-exported for nsl.catalog's users)
    CARD_FILE,
    CONFIG_FILE,
    CONTENT_FILES,
    TMP_PREFIX,
    WEIGHTS_FILE,
    check_safetensors,
    checkpoint_id,
    encode_config,
    file_sha256,
    folder_checkpoint_id,
    folder_digests,
    is_temp_name,
    read_config,
    write_folder,
)
from nsl.errors import ConfigError, CorruptDataError
from nsl.workspace import atomic_write_bytes


def hash_tree(root: Path) -> dict[str, str]:
    """``{relative posix path: sha256}`` of every regular file under ``root`` (temp files skipped)."""
    root = Path(root)
    if root.is_file():
        return {root.name: file_sha256(root)}
    out: dict[str, str] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not is_temp_name(d))
        for name in sorted(filenames):
            if is_temp_name(name):
                continue
            p = Path(dirpath) / name
            out[p.relative_to(root).as_posix()] = file_sha256(p)
    return out


def content_digests(weights: bytes | Path, config_bytes: bytes) -> dict[str, str]:
    """The digests :func:`folder_digests` will report once ``weights`` and ``config_bytes`` are written."""
    if isinstance(weights, (bytes, bytearray, memoryview)):
        wdigest = hashlib.sha256(weights).hexdigest()
    elif Path(weights).is_file():
        wdigest = file_sha256(Path(weights))
    else:
        raise ConfigError(f"weights file {weights} does not exist; pass safetensors bytes or an existing file")
    return {WEIGHTS_FILE: wdigest, CONFIG_FILE: hashlib.sha256(config_bytes).hexdigest()}


def write_model_folder(dest: Path, weights: bytes | Path, config: Mapping[str, Any], card: str) -> dict[str, str]:
    """Write ``model.safetensors``, ``config.json`` and ``README.md`` as the folder ``dest``.

    ``weights`` is the safetensors bytes (``safetensors.torch.save(sd)``) or
    the path of a ``.safetensors`` file, which is hard-linked (copied only
    across file systems).  The folder appears whole or not at all.  If
    ``dest`` already holds the same weights and config (an earlier run, or
    another process, wrote it) only its card is refreshed; if it holds
    different ones, nothing is touched and CorruptDataError is raised.
    Returns ``{file name: sha256}`` of the two content files.
    """
    dest = Path(dest)
    config_bytes = encode_config(config)
    if isinstance(weights, (bytes, bytearray, memoryview)):
        weights = bytes(weights)
        check_safetensors(weights[:9], "the weights")
    else:
        weights = Path(weights)
        if not weights.is_file():
            raise ConfigError(f"weights file {weights} does not exist; pass safetensors bytes or an existing file")
        with open(weights, "rb") as f:
            check_safetensors(f.read(9), str(weights))
    digests = content_digests(weights, config_bytes)
    if not write_folder(dest, {WEIGHTS_FILE: weights, CONFIG_FILE: config_bytes, CARD_FILE: card.encode()}):
        existing = folder_digests(dest) if all((dest / f).is_file() for f in CONTENT_FILES) else {}
        if existing != digests:
            raise CorruptDataError(
                f"{dest} already exists with other contents; move it away or run "
                "`nsl catalog gc` if no catalog entry uses it"
            )
        write_card(dest, card)
    return digests


def write_card(folder: Path, card: str) -> Path:
    """Replace ``README.md`` in ``folder`` atomically."""
    path = Path(folder) / CARD_FILE
    atomic_write_bytes(path, card.encode())
    return path
