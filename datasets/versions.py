"""Dataset names, immutable versions, references, manifests and verification.

A dataset ``NAME`` lives in ``$NSL_HOME/datasets/NAME/`` with one directory per
version (``v1``, ``v2``, ...).  A version never changes after it is published.
Its identity is a content hash: sha256 over the sorted list of
``(path, size, sha256)`` of every file in the version except ``manifest.json``,
which records that list, the hash, and the volatile facts of its creation
(time, code version, worker count) that must not change the hash.

References: ``NAME[@vN][:K]`` (an optional leading ``data:`` is accepted).
Without ``@vN`` the latest version is meant; ``:K`` is the tier made of the
first K episodes, a view (nothing is copied), so tiers are nested by
construction.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from pathlib import Path
from typing import Any

from nsl import refs
from nsl.errors import ConfigError, CorruptDataError, unknown
from nsl.refs import DataRef, parse_data_ref
from nsl.workspace import atomic_write_json, datasets_dir, file_sha256

from . import layout

STANDARD_TIERS = (25, 50, 100, 200, 400, 800)  # the study's target-data sizes (NOTES, Table 5.2)
HASH_PREFIX = "sha256:"

Ref = DataRef  # a parsed reference (the grammar lives in nsl.refs, shared with the catalog)
parse_ref = parse_data_ref


def check_name(name: str) -> str:
    return refs.check_name("dataset", name)


def dataset_root(name: str) -> Path:
    return datasets_dir() / check_name(name)


def version_dir(name: str, version: int) -> Path:
    return dataset_root(name) / layout.VERSION_DIR.format(version=version)


def dataset_names() -> list[str]:
    root = datasets_dir()
    if not root.is_dir():
        return []
    return sorted(
        p.name for p in root.iterdir() if p.is_dir() and refs.NAME_RE.fullmatch(p.name) and list_versions(p.name)
    )


def list_versions(name: str) -> list[int]:
    """Published versions of ``name`` (directories ``vN`` holding a manifest), ascending."""
    root = datasets_dir() / name
    if not root.is_dir():
        return []
    out = []
    for p in root.iterdir():
        m = re.fullmatch(r"v(\d+)", p.name)
        if m and (p / layout.MANIFEST_PATH).is_file():
            out.append(int(m[1]))
    return sorted(out)


def resolve(ref: str | Ref) -> tuple[Ref, Path]:
    """The concrete reference (version filled in) and its directory; unknown names list near matches."""
    r = parse_ref(ref) if isinstance(ref, str) else ref
    versions = list_versions(r.name)
    if not versions:
        raise unknown("dataset", r.name, dataset_names(), "list datasets with `nsl dataset ls`")
    v = versions[-1] if r.version is None else r.version
    if v not in versions:
        raise unknown("dataset version", f"{r.name}@v{v}", [f"{r.name}@v{x}" for x in versions])
    return Ref(r.name, v, r.tier), version_dir(r.name, v)


# -- manifests and hashes --------------------------------------------------------------------------------------------


def content_files(root: Path) -> list[str]:
    """Relative paths of every file of a version except the manifest (and temporary files)."""
    root = Path(root)
    out = []
    for dirpath, _, names in os.walk(root):
        for n in names:
            rel = (Path(dirpath) / n).relative_to(root).as_posix()
            if rel != layout.MANIFEST_PATH and not n.endswith(".tmp"):
                out.append(rel)
    return sorted(out)


def hash_of(files: dict[str, dict[str, Any]]) -> str:
    """The version hash of a ``{path: {"size", "sha256"}}`` file table."""
    h = hashlib.sha256()
    for rel in sorted(files):
        h.update(f"{rel}\0{files[rel]['size']}\0{files[rel]['sha256']}\n".encode())
    return HASH_PREFIX + h.hexdigest()


def build_manifest(
    root: Path, known: dict[str, dict[str, Any]] | None = None, created: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Hash every file of ``root``; ``known`` reuses hashes of hard-linked files from a parent version."""
    files = {}
    for rel in content_files(root):
        p = Path(root) / rel
        size = p.stat().st_size
        k = (known or {}).get(rel)
        same_inode = k is not None and k.get("_inode") == (p.stat().st_ino, p.stat().st_dev) and k["size"] == size
        files[rel] = {"size": size, "sha256": k["sha256"] if same_inode and k is not None else file_sha256(p)}
    return {"format": layout.NSL_FORMAT, "hash": hash_of(files), "files": files, "created": created or {}}


def load_manifest(root: Path) -> dict[str, Any]:
    path = Path(root) / layout.MANIFEST_PATH
    try:
        m = json.loads(path.read_text())
        m["files"], m["hash"]  # noqa: B018  # required fields
    except FileNotFoundError:
        raise CorruptDataError(f"{path} is missing; the version was not published completely") from None
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError):
        raise CorruptDataError(f"{path} is damaged; restore it or re-collect the dataset") from None
    return m


def check_files(
    root: Path, manifest: dict[str, Any], only: list[str] | None = None, quick: bool = False, label: str = ""
) -> None:
    """Raise CorruptDataError naming the first file that is missing, truncated or altered.

    ``only`` restricts the check to some files; ``quick`` compares sizes, not hashes.
    """
    root = Path(root)
    label = label or str(root)
    files = manifest["files"]
    for rel in sorted(only if only is not None else files):
        want = files.get(rel)
        p = root / rel
        if want is None:
            raise CorruptDataError(f"{label}: file {rel} is not in the manifest (added after publication?)")
        if not p.is_file():
            raise CorruptDataError(f"{label}: file {p} is missing")
        size = p.stat().st_size
        if size != want["size"]:
            kind = "truncated" if size < want["size"] else "altered"
            raise CorruptDataError(
                f"{label}: file {p} is {kind} ({size} bytes, manifest says {want['size']}); "
                "restore the version or re-collect it"
            )
        if not quick and file_sha256(p) != want["sha256"]:
            raise CorruptDataError(
                f"{label}: file {p} is altered (sha256 differs from the manifest); restore the version or re-collect it"
            )


def verify(root: Path, label: str = "") -> str:
    """Re-hash a version; return its hash or raise CorruptDataError naming the first bad file."""
    m = load_manifest(root)
    check_files(root, m, label=label)
    extra = sorted(set(content_files(root)) - set(m["files"]))
    if extra:
        raise CorruptDataError(
            f"{label or root}: file {Path(root) / extra[0]} is not in the manifest (added after publication); remove it"
        )
    if hash_of(m["files"]) != m["hash"]:
        raise CorruptDataError(
            f"{label or root}: {layout.MANIFEST_PATH} records hash {m['hash']} that does not match its file list"
        )
    return m["hash"]


def tier_hash(episode_hashes: list[str]) -> str:
    """Content hash of a tier (the first K episodes), equal in every version that contains them."""
    h = hashlib.sha256()
    for e in episode_hashes:
        h.update(e.encode() + b"\n")
    return HASH_PREFIX + h.hexdigest()


# -- publishing ------------------------------------------------------------------------------------------------------


def link_or_copy(src: Path, dst: Path) -> None:
    """Hard-link ``src`` to ``dst`` (a new version shares its parent's immutable files), else copy."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def inode_table(root: Path, manifest: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The manifest's file table with inode ids, so hard-linked files need not be re-hashed."""
    out = {}
    for rel, f in manifest["files"].items():
        p = Path(root) / rel
        if p.is_file():
            st = p.stat()
            out[rel] = {**f, "_inode": (st.st_ino, st.st_dev)}
    return out


def publish(tmp: Path, name: str, version: int, manifest: dict[str, Any]) -> Path:
    """Write the manifest into the finished temporary directory and rename it to ``vN`` (atomic)."""
    atomic_write_json(Path(tmp) / layout.MANIFEST_PATH, manifest)
    final = version_dir(name, version)
    if final.exists():
        raise ConfigError(
            f"dataset {name}@v{version} already exists (another collection published it); "
            "run the command again to append a new version"
        )
    os.rename(tmp, final)
    return final
