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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, CorruptDataError, unknown
from nsl.workspace import atomic_write_json, datasets_dir

from . import layout

NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
REF_RE = re.compile(r"^(?:data:)?(?P<name>[^@:]+)(?:@v(?P<version>\d+))?(?::(?P<tier>\d+))?$")
STANDARD_TIERS = (25, 50, 100, 200, 400, 800)  # the study's target-data sizes (NOTES, Table 5.2)
HASH_PREFIX = "sha256:"


@dataclass(frozen=True)
class Ref:
    """A parsed dataset reference."""

    name: str
    version: int | None = None  # None: the latest version
    tier: int | None = None  # None: all episodes; K: the first K episodes

    def __str__(self) -> str:
        v = f"@v{self.version}" if self.version is not None else ""
        t = f":{self.tier}" if self.tier is not None else ""
        return f"{self.name}{v}{t}"


def check_name(name: str) -> str:
    if not NAME_RE.match(name or ""):
        raise ConfigError(f"dataset name {name!r} is invalid; use letters, digits, '.', '_' and '-' "
                          "(e.g. grasp-harsh)")
    return name


def parse_ref(text: str) -> Ref:
    """Parse ``[data:]NAME[@vN][:K]``."""
    m = REF_RE.match(text.strip()) if isinstance(text, str) else None
    if not m:
        raise ConfigError(f"dataset reference {text!r} is malformed; write NAME, NAME@v2 or NAME@v2:100")
    name = check_name(m["name"])
    tier = int(m["tier"]) if m["tier"] is not None else None
    if tier is not None and tier < 1:
        raise ConfigError(f"dataset reference {text!r}: tier {tier} must be at least 1 episode")
    version = int(m["version"]) if m["version"] is not None else None
    if version is not None and version < 1:
        raise ConfigError(f"dataset reference {text!r}: versions start at v1")
    return Ref(name, version, tier)


def dataset_root(name: str) -> Path:
    return datasets_dir() / check_name(name)


def version_dir(name: str, version: int) -> Path:
    return dataset_root(name) / layout.VERSION_DIR.format(version=version)


def dataset_names() -> list[str]:
    root = datasets_dir()
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if p.is_dir() and NAME_RE.match(p.name) and list_versions(p.name))


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

def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


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


def build_manifest(root: Path, known: dict[str, dict[str, Any]] | None = None,
                   created: dict[str, Any] | None = None) -> dict[str, Any]:
    """Hash every file of ``root``; ``known`` reuses hashes of hard-linked files from a parent version."""
    files = {}
    for rel in content_files(root):
        p = Path(root) / rel
        size = p.stat().st_size
        k = (known or {}).get(rel)
        same_inode = k is not None and k.get("_inode") == (p.stat().st_ino, p.stat().st_dev) and k["size"] == size
        files[rel] = {"size": size, "sha256": k["sha256"] if same_inode else file_sha256(p)}
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


def check_files(root: Path, manifest: dict[str, Any], only: list[str] | None = None, quick: bool = False,
                label: str = "") -> None:
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
            raise CorruptDataError(f"{label}: file {p} is {kind} ({size} bytes, manifest says {want['size']}); "
                                   "restore the version or re-collect it")
        if not quick and file_sha256(p) != want["sha256"]:
            raise CorruptDataError(f"{label}: file {p} is altered (sha256 differs from the manifest); "
                                   "restore the version or re-collect it")


def verify(root: Path, label: str = "") -> str:
    """Re-hash a version; return its hash or raise CorruptDataError naming the first bad file."""
    m = load_manifest(root)
    check_files(root, m, label=label)
    extra = sorted(set(content_files(root)) - set(m["files"]))
    if extra:
        raise CorruptDataError(f"{label or root}: file {Path(root) / extra[0]} is not in the manifest "
                               "(added after publication); remove it")
    if hash_of(m["files"]) != m["hash"]:
        raise CorruptDataError(f"{label or root}: {layout.MANIFEST_PATH} records hash {m['hash']} "
                               "that does not match its file list")
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
        raise ConfigError(f"dataset {name}@v{version} already exists (another collection published it); "
                          "run the command again to append a new version")
    os.rename(tmp, final)
    return final
