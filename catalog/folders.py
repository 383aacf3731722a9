"""Checkpoint folders shaped like Hugging Face model repositories, and content hashes.

A checkpoint folder holds ``model.safetensors`` (the weights), ``config.json``
(everything needed to rebuild the model) and a generated ``README.md`` model
card.  The checkpoint id is a content hash of the weights and the config, so
the same weights and config always get the same id and a changed weight or
setting gives a different one.  The card is derived from the catalog and may be
regenerated (for example after new evaluations); it is not part of the id.

Folders are written completely in a hidden temporary sibling
(``.tmp-NAME-...``) and renamed into place, so a folder under its final name
is always whole.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import struct
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, CorruptDataError
from nsl.workspace import atomic_write_bytes

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
CARD_FILE = "README.md"
CONTENT_FILES = (WEIGHTS_FILE, CONFIG_FILE)  # the files the checkpoint id covers
TMP_PREFIX = ".tmp-"  # temporary folders; `nsl catalog gc` removes stale ones
_CHUNK = 1 << 20


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def is_temp_name(name: str) -> bool:
    """Names used for files and folders being written (ours and ``atomic_write_bytes``')."""
    return name.startswith(TMP_PREFIX) or (name.startswith(".") and name.endswith(".tmp"))


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


def canonical_config(config: Mapping[str, Any]) -> bytes:
    """Compact sorted JSON of ``config`` as it reads back from ``config.json`` (the form the id hashes)."""
    return json.dumps(json.loads(encode_config(config)), sort_keys=True, separators=(",", ":")).encode()


def checkpoint_id(weights: bytes | Path, config: Mapping[str, Any]) -> str:
    """The checkpoint id: sha256 over the weights file bytes, a NUL byte and the canonical config.

    The same definition as ``nsl.learners``' ``checkpoint_id(folder)``, so both
    name a checkpoint alike; formatting-only edits of ``config.json`` keep the id
    (``verify`` still reports them, as it compares whole-file digests).
    """
    h = hashlib.sha256()
    if isinstance(weights, (bytes, bytearray, memoryview)):
        h.update(weights)
    else:
        with open(weights, "rb") as f:
            while chunk := f.read(_CHUNK):
                h.update(chunk)
    h.update(b"\0")
    h.update(canonical_config(config))
    return h.hexdigest()


def folder_checkpoint_id(folder: Path) -> str:
    """The id of the checkpoint stored in ``folder`` (see :func:`checkpoint_id`)."""
    folder_digests(folder)  # clear error if a content file is missing
    return checkpoint_id(Path(folder) / WEIGHTS_FILE, read_config(folder))


def folder_digests(folder: Path) -> dict[str, str]:
    """Digests of the content files of a checkpoint folder (raises if one is missing)."""
    folder = Path(folder)
    missing = [f for f in CONTENT_FILES if not (folder / f).is_file()]
    if missing:
        raise CorruptDataError(f"{folder} is not a checkpoint folder: {', '.join(missing)} missing; "
                               f"it needs {' and '.join(CONTENT_FILES)}")
    return {name: file_sha256(folder / name) for name in CONTENT_FILES}


def encode_config(config: Mapping[str, Any]) -> bytes:
    """``config.json`` bytes: sorted keys, two-space indent, so equal configs hash equally."""
    try:
        return (json.dumps(dict(config), indent=2, sort_keys=True, allow_nan=False) + "\n").encode()
    except (TypeError, ValueError) as e:
        raise ConfigError(f"checkpoint config is not plain JSON data ({e}); convert paths, tuples of "
                          "objects and NaN to strings/lists/numbers first") from None


def check_safetensors(head: bytes, what: str) -> None:
    """Cheap check that ``head`` (the first bytes of a file) starts a safetensors file."""
    if len(head) < 8:
        raise ConfigError(f"{what} is not a safetensors file (only {len(head)} bytes)")
    (n,) = struct.unpack("<Q", head[:8])
    if not 2 <= n <= 100_000_000 or head[8:9] != b"{":
        raise ConfigError(f"{what} is not a safetensors file (bad header); save weights with "
                          "safetensors.torch.save(state_dict) or safetensors.numpy.save_file")


def read_config(folder: Path) -> dict[str, Any]:
    path = Path(folder) / CONFIG_FILE
    try:
        config = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise CorruptDataError(f"{path} is not readable JSON ({e}); the checkpoint folder is damaged") from None
    if not isinstance(config, dict):
        raise CorruptDataError(f"{path} holds {type(config).__name__}, not a JSON object")
    return config


def _write_file(path: Path, data: bytes) -> None:
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_model_folder(dest: Path, weights: bytes | Path, config: Mapping[str, Any], card: str) -> dict[str, str]:
    """Write ``model.safetensors``, ``config.json`` and ``README.md`` as the folder ``dest``.

    ``weights`` is the safetensors bytes (``safetensors.torch.save(sd)``) or
    the path of a ``.safetensors`` file to copy.  Everything goes into a
    temporary sibling folder that is renamed to ``dest`` at the end.  If
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
        src = Path(weights)
        if not src.is_file():
            raise ConfigError(f"weights file {src} does not exist; pass safetensors bytes or an existing file")
        with open(src, "rb") as f:
            check_safetensors(f.read(9), str(src))
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{dest.name}-", dir=dest.parent))
    try:
        if isinstance(weights, bytes):
            _write_file(tmp / WEIGHTS_FILE, weights)
        else:
            shutil.copyfile(weights, tmp / WEIGHTS_FILE)
            with open(tmp / WEIGHTS_FILE, "rb+") as f:
                os.fsync(f.fileno())
        _write_file(tmp / CONFIG_FILE, config_bytes)
        _write_file(tmp / CARD_FILE, card.encode())
        digests = {name: file_sha256(tmp / name) for name in CONTENT_FILES}
        os.chmod(tmp, 0o755)
        try:
            os.rename(tmp, dest)
        except OSError:
            if not dest.exists():
                raise
            existing = folder_digests(dest) if all((dest / f).is_file() for f in CONTENT_FILES) else {}
            if existing != digests:
                raise CorruptDataError(f"{dest} already exists with other contents; move it away or run "
                                       "`nsl catalog gc` if no catalog entry uses it") from None
            write_card(dest, card)
        _fsync_dir(dest.parent)
        return digests
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def write_card(folder: Path, card: str) -> Path:
    """Replace ``README.md`` in ``folder`` atomically."""
    path = Path(folder) / CARD_FILE
    atomic_write_bytes(path, card.encode())
    return path
