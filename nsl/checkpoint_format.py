"""The checkpoint folder format, shared by the learner that writes folders and the catalog that records them.

A checkpoint is a folder shaped like a Hugging Face model repository::

    model.safetensors     the weights (safetensors)
    config.json           everything needed to rebuild the model (sorted keys, two-space indent)
    README.md             optional: the model card the catalog generates
    trainer_state.pt      optional: what the learner needs to resume the run that wrote it

The checkpoint id is a content hash: sha256 over the bytes of
``model.safetensors``, a NUL byte and the canonical (compact, sorted) JSON
of the config, so formatting-only edits of ``config.json`` keep the id.

A folder is written whole in a hidden temporary sibling (``.tmp-NAME-*.tmp``)
and renamed into place, so a folder under its final name is always
complete.  Files are never changed in place, which is what lets a catalog
entry share the weights file of a run folder through a hard link.

``nsl.learners`` adds the learner's own schema on top (format name, version,
architecture, training config); this module knows only files and JSON.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import struct
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, CorruptDataError, UnknownReferenceError
from nsl.workspace import file_sha256

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
CARD_FILE = "README.md"
TRAINER_FILE = "trainer_state.pt"
CONTENT_FILES = (WEIGHTS_FILE, CONFIG_FILE)  # the files the checkpoint id covers
TMP_PREFIX = ".tmp-"  # temporary folders; `nsl catalog gc` removes stale ones
TMP_SUFFIX = ".tmp"

FileSource = bytes | Path  # what a folder file is made from: its bytes, or an existing file to link or copy


def is_temp_name(name: str) -> bool:
    """Names of files and folders being written (ours and ``nsl.workspace.atomic_write_bytes``')."""
    return name.startswith(TMP_PREFIX) or (name.startswith(".") and name.endswith(TMP_SUFFIX))


# ----------------------------------------------------------------- config
def encode_config(config: Mapping[str, Any]) -> bytes:
    """``config.json`` bytes: sorted keys, two-space indent, so equal configs give equal files."""
    try:
        return (json.dumps(dict(config), indent=2, sort_keys=True, allow_nan=False) + "\n").encode()
    except (TypeError, ValueError) as e:
        raise ConfigError(
            f"checkpoint config is not plain JSON data ({e}); convert paths, tuples of "
            "objects and NaN to strings/lists/numbers first"
        ) from None


def canonical_config(config: Mapping[str, Any]) -> bytes:
    """Compact sorted JSON of ``config`` as it reads back from ``config.json`` (the form the id hashes)."""
    return json.dumps(json.loads(encode_config(config)), sort_keys=True, separators=(",", ":")).encode()


def read_config(folder: Path) -> dict[str, Any]:
    """The ``config.json`` of the checkpoint folder ``folder`` as a dict (no schema check)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UnknownReferenceError(
            f"no checkpoint folder at {folder}; pass the folder that holds {WEIGHTS_FILE} and {CONFIG_FILE}"
        )
    path = folder / CONFIG_FILE
    if not path.is_file():
        raise CorruptDataError(f"checkpoint {folder} has no {CONFIG_FILE}; it is incomplete or not an nsl checkpoint")
    try:
        config = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise CorruptDataError(
            f"checkpoint {folder}: {CONFIG_FILE} is not valid JSON ({e}); restore it or retrain"
        ) from None
    if not isinstance(config, dict):
        raise CorruptDataError(
            f"checkpoint {folder}: {CONFIG_FILE} must hold a JSON object, not {type(config).__name__}"
        )
    return config


# --------------------------------------------------------------------- ids
def checkpoint_id(weights: bytes | Path, config: Mapping[str, Any]) -> str:
    """The checkpoint id: sha256 over the weights file bytes, a NUL byte and the canonical config."""
    if isinstance(weights, (bytes, bytearray, memoryview)):
        h = hashlib.sha256(weights)
    else:
        with open(weights, "rb") as f:
            h = hashlib.file_digest(f, "sha256")
    h.update(b"\0")
    h.update(canonical_config(config))
    return h.hexdigest()


def folder_digests(folder: Path) -> dict[str, str]:
    """``{file name: sha256}`` of the content files of a checkpoint folder (raises if one is missing)."""
    folder = Path(folder)
    missing = [f for f in CONTENT_FILES if not (folder / f).is_file()]
    if missing:
        raise CorruptDataError(
            f"{folder} is not a checkpoint folder: {', '.join(missing)} missing; it needs {' and '.join(CONTENT_FILES)}"
        )
    return {name: file_sha256(folder / name) for name in CONTENT_FILES}


def folder_checkpoint_id(folder: Path) -> str:
    """The id of the checkpoint stored in ``folder`` (see :func:`checkpoint_id`)."""
    folder = Path(folder)
    config = read_config(folder)
    if not (folder / WEIGHTS_FILE).is_file():
        raise CorruptDataError(f"checkpoint {folder} has no {WEIGHTS_FILE}; it is incomplete")
    return checkpoint_id(folder / WEIGHTS_FILE, config)


def check_safetensors(head: bytes, what: str) -> None:
    """Cheap check that ``head`` (the first bytes of a file) starts a safetensors file."""
    if len(head) < 8:
        raise ConfigError(f"{what} is not a safetensors file (only {len(head)} bytes)")
    (n,) = struct.unpack("<Q", head[:8])
    if not 2 <= n <= 100_000_000 or head[8:9] != b"{":
        raise ConfigError(
            f"{what} is not a safetensors file (bad header); save weights with "
            "safetensors.torch.save(state_dict) or safetensors.numpy.save_file"
        )


# ------------------------------------------------------------------ writing
def _fsync_file(path: Path) -> None:
    with open(path, "rb") as f:
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


def link_or_copy(src: Path, dest: Path) -> str:
    """Hard-link ``src`` as ``dest``; copy it only where a link is impossible (another file system).

    Returns ``"link"`` or ``"copy"``.  Sharing the inode is safe because
    checkpoint files are never modified in place, only replaced by renames.
    """
    try:
        os.link(src, dest)
        return "link"
    except OSError as e:
        if e.errno not in (errno.EXDEV, errno.EPERM, errno.EMLINK, errno.ENOTSUP, errno.EOPNOTSUPP):
            raise
    shutil.copyfile(src, dest)
    _fsync_file(dest)
    return "copy"


def temp_folder(dest: Path) -> Path:
    """A new empty hidden sibling of ``dest`` to fill and then rename with :func:`publish_folder`."""
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{dest.name}-", suffix=TMP_SUFFIX, dir=dest.parent))


def write_into(folder: Path, files: Mapping[str, FileSource]) -> None:
    """Write ``{name: bytes or source path}`` into ``folder`` durably (source paths are hard-linked)."""
    for name, data in files.items():
        target = Path(folder) / name
        if isinstance(data, (bytes, bytearray, memoryview)):
            with open(target, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
        else:
            link_or_copy(Path(data), target)


def publish_folder(tmp: Path, dest: Path, replace: bool = False) -> bool:
    """Rename the finished folder ``tmp`` to ``dest``; False (``tmp`` left alone) if ``dest`` exists.

    ``replace=True`` swaps out an existing ``dest`` instead (the learner's
    rolling checkpoints): it is renamed aside first, then deleted, so
    ``dest`` is never half-written.
    """
    tmp, dest = Path(tmp), Path(dest)
    os.chmod(tmp, 0o755)
    old = None
    if replace and dest.exists():
        old = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{dest.name}-old-", suffix=TMP_SUFFIX, dir=dest.parent))
        os.replace(dest, old / dest.name)
    try:
        os.rename(tmp, dest)
    except OSError:
        if not dest.exists():
            raise
        return False
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    _fsync_dir(dest.parent)
    return True


def write_folder(dest: Path, files: Mapping[str, FileSource], replace: bool = False) -> bool:
    """Write a checkpoint folder ``dest`` from ``{file name: bytes or source path}``, atomically.

    Returns False, writing nothing, if ``dest`` already exists and ``replace``
    is False (the caller decides whether the existing folder is the same).
    """
    tmp = temp_folder(dest)
    try:
        write_into(tmp, files)
        return publish_folder(tmp, dest, replace=replace)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
