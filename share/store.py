"""A cluster without a shared file system: folders of ``NSL_HOME`` move through an object store (``--store URL``).

The driver's ``NSL_HOME`` stays the record of truth.  Before a unit runs, the driver pushes the folders it reads
(dataset versions, checkpoint folders); the unit's node pulls them into its own ``NSL_HOME`` (a per-node cache,
``nsl.cluster.node_home``), runs, and pushes the folders it made (a dataset version, a training run), which the
driver pulls before it registers them (``nsl.study``).  A folder travels as a *tree*: its files under
``URL/home/REL/`` and, written last, ``URL/trees/REL.json`` with every file's size and sha256.  A pull checks every
byte against it, writes each file under a temporary name and renames it, and skips a tree its node already holds
unchanged.

Any fsspec URL works (``s3://bucket/prefix``, ``gs://``, ``file:///shared``); credentials and endpoints come
from fsspec's own configuration, as for ``nsl push``.
"""

from __future__ import annotations

import hashlib
import json
import os
import posixpath
import tempfile
from pathlib import Path

from nsl.errors import ConfigError, CorruptDataError, UnknownReferenceError

STORE_ENV = "NSL_STORE"
FILES = "home"  # URL/home/REL/...: a tree's files
TREES = "trees"  # URL/trees/REL.json: a tree's manifest
RECORD_DIR = ".store"  # under a node's (or the driver's) NSL_HOME: the manifests of the trees it holds


def parse_store(value: str | None) -> str | None:
    """The store URL from ``--store``, else ``$NSL_STORE``, else None (a shared ``NSL_HOME``)."""
    url = (value or os.environ.get(STORE_ENV) or "").strip()
    if not url:
        return None
    if "://" not in url:
        where = "--store" if value else f"${STORE_ENV}"
        raise ConfigError(
            f"{where} {url!r} is not a URL; give an fsspec URL such as s3://bucket/prefix (or file:///shared/path)"
        )
    return url.rstrip("/")


def _safe(rel: str) -> str:
    parts = rel.split("/")
    if not rel or rel.startswith("/") or any(p in ("", ".", "..") for p in parts):
        raise ConfigError(f"store path {rel!r} is not a folder inside NSL_HOME")
    return rel


def _sha256(path: Path) -> str:
    from .transfer import sha256_file

    return sha256_file(path)


def _files(folder: Path) -> list[str]:
    return sorted(
        p.relative_to(folder).as_posix()
        for p in folder.rglob("*")
        if p.is_file() and not p.name.endswith(".tmp") and not p.name.startswith(".")
    )


class Store:
    """Trees of ``NSL_HOME`` folders on one fsspec URL."""

    def __init__(self, url: str):
        from .fsremote import FsRemote
        from .remotes import parse_remote

        self.url = url
        self.remote = FsRemote(parse_remote(url))

    def manifest(self, rel: str) -> dict | None:
        return self.remote.read_json(f"{TREES}/{_safe(rel)}.json")

    def push(self, home: Path, rel: str) -> int:
        """Upload the folder ``home/rel`` (files that differ from the store's copy); returns how many were sent."""
        folder = Path(home) / _safe(rel)
        if not folder.is_dir():
            raise UnknownReferenceError(f"{folder} is not in NSL_HOME {home}; nothing to push to the store {self.url}")
        names = _files(folder)
        have = self.manifest(rel) or {"files": {}}
        record = _record_path(home, self.url, rel)
        sizes = {n: (folder / n).stat().st_size for n in names}
        if have["files"] and {n: f["size"] for n, f in have["files"].items()} == sizes and _read(record) == have:
            return 0  # this folder was pushed (or pulled) unchanged: trees are immutable once made
        table = {n: {"size": sizes[n], "sha256": _sha256(folder / n)} for n in names}
        sent = 0
        for n in names:
            if have["files"].get(n) != table[n]:
                self.remote.put(f"{FILES}/{rel}/{n}", folder / n)
                sent += 1
        manifest = {"tree": rel, "files": table}
        self.remote.put(f"{TREES}/{rel}.json", _encode(manifest))  # last: the tree is complete
        _write(record, manifest)
        return sent

    def pull(self, home: Path, rel: str) -> int:
        """Download the tree ``rel`` into ``home/rel``, every file checked; returns how many were fetched."""
        manifest = self.manifest(rel)
        if manifest is None:
            raise UnknownReferenceError(
                f"store {self.url} holds no {rel}; the driver pushes a unit's inputs before it starts it, so run the "
                "study again from the driver"
            )
        folder = Path(home) / _safe(rel)
        record = _record_path(home, self.url, rel)
        files = manifest["files"]
        if _read(record) == manifest and all((folder / n).is_file() for n in files):
            return 0  # the node's cache holds this tree
        fetched = 0
        for n in sorted(files, key=lambda n: (n == "manifest.json", n)):  # a dataset's manifest last
            want = files[n]
            path = folder / _safe(n)
            if path.is_file() and path.stat().st_size == want["size"] and _sha256(path) == want["sha256"]:
                continue
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            os.close(fd)
            try:
                self.remote.fetch(f"{FILES}/{rel}/{n}", Path(tmp))
                got = _sha256(Path(tmp))
                if got != want["sha256"]:
                    raise CorruptDataError(
                        f"store {self.url}: {rel}/{n} has sha256 {got[:12]}, its tree says {want['sha256'][:12]}; "
                        "the store is damaged, run the study again from the driver to push it again"
                    )
                os.replace(tmp, path)
            finally:
                Path(tmp).unlink(missing_ok=True)
            fetched += 1
        _write(record, manifest)
        return fetched


def _record_path(home: Path, url: str, rel: str) -> Path:
    return Path(home) / RECORD_DIR / hashlib.sha256(url.encode()).hexdigest()[:12] / f"{rel}.json"


def _read(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _encode(obj: dict) -> bytes:
    return (json.dumps(obj, indent=1, sort_keys=True) + "\n").encode()


def _write(path: Path, obj: dict) -> None:
    from nsl.workspace import atomic_write_bytes

    atomic_write_bytes(path, _encode(obj))


def relative(path: str | Path, home: Path, what: str) -> str:
    """``path`` as a folder relative to ``home``; a one-line error when it lies outside (a store moves only
    ``NSL_HOME``'s folders)."""
    try:
        return posixpath.join(*Path(path).resolve().relative_to(Path(home).resolve()).parts)
    except ValueError:
        raise ConfigError(
            f"{what} at {path} is outside NSL_HOME {home}; --store moves only NSL_HOME's folders, so copy it into "
            "the workspace (nsl pull) first"
        ) from None
