"""Push and pull: what goes where, what is skipped, and how every byte is checked.

Layout on a remote::

    Hub dataset repo hf://datasets/OWNER/NAME      fsspec folder URL
      (each commit is one version; tags v1, v2,      URL/v1/ , URL/v2/ , ...  (one folder per version)
       and v3.0 = the newest push, for LeRobot)
      meta/info.json, meta/stats.json, ...           the same files, under vN/
      data/chunk-000/file-000.parquet
      meta/nsl.json       provenance (hashed)
      manifest.json       per-file sha256 + version hash (written last on fsspec)
      README.md           dataset card

    Hub model repo hf://OWNER/NAME                 fsspec folder URL
      model.safetensors, config.json                 the same files
      README.md           model card
      manifest.json       nsl-share manifest: sha256 of the two files, checkpoint id, lineage

A dataset version's own ``manifest.json`` is its published manifest.  A
checkpoint gets a share manifest (:func:`checkpoint_manifest`) with the
published lineage (parent chain, datasets with hashes, evaluations), so a
workspace that pulls only the checkpoint still knows where it came from.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, CorruptDataError, UnknownReferenceError

from .remotes import Location, parse_remote
from .transports import open_remote

MANIFEST = "manifest.json"
CARD = "README.md"
SHARE_FORMAT = "nsl-share"  # the "format" of a checkpoint's share manifest
SHARE_VERSION = 1
LEROBOT_TAG = "v3.0"  # LeRobotDataset looks up this codebase-version tag on the Hub
VERSION_TAG = re.compile(r"v(\d+)")
CHECKPOINT_FILES = ("model.safetensors", "config.json")


@dataclass
class PushResult:
    url: str
    revision: str  # Hub: the commit; fsspec: the version folder (datasets) or the checkpoint id
    uploaded: list[str] = field(default_factory=list)  # files sent (data and metadata)
    unchanged: list[str] = field(default_factory=list)  # files the remote already had with the same sha256
    tags: list[str] = field(default_factory=list)


@dataclass
class Pulled:
    kind: str  # "dataset" or "checkpoint"
    location: Location
    revision: str  # Hub: the commit id; fsspec: "vN" (datasets) or the checkpoint id
    manifest: dict[str, Any]
    folder: Path  # holds exactly the manifest's files, each verified (datasets: plus manifest.json)
    version: int | None = None  # datasets: the version number on the remote
    downloaded: list[str] = field(default_factory=list)
    reused: list[str] = field(default_factory=list)  # verified in an earlier, interrupted pull

    @property
    def url(self) -> str:
        return self.location.url


# ------------------------------------------------------------------ hashes
def sha256_file(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def file_table(root: Path, rels: tuple[str, ...] | list[str]) -> dict[str, dict[str, Any]]:
    """``{rel: {"size", "sha256"}}`` of files under ``root``."""
    return {rel: {"size": (Path(root) / rel).stat().st_size, "sha256": sha256_file(Path(root) / rel)} for rel in rels}


def encode(obj: dict[str, Any]) -> bytes:
    return (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode()


def checkpoint_manifest(folder: Path, checkpoint: dict[str, Any], lineage: list[dict[str, Any]]) -> dict[str, Any]:
    """The share manifest of a checkpoint folder: file digests, its identity and its published lineage."""
    return {
        "format": SHARE_FORMAT,
        "version": SHARE_VERSION,
        "kind": "checkpoint",
        "files": file_table(folder, CHECKPOINT_FILES),
        "checkpoint": dict(checkpoint),
        "lineage": lineage,
    }


def kind_of(manifest: dict[str, Any], where: str) -> str:
    if manifest.get("format") == SHARE_FORMAT and manifest.get("kind") == "checkpoint":
        if not isinstance(manifest.get("files"), dict) or not isinstance(manifest.get("checkpoint"), dict):
            raise CorruptDataError(f"{where}: {MANIFEST} lacks 'files' or 'checkpoint'; push the checkpoint again")
        return "checkpoint"
    if isinstance(manifest.get("files"), dict) and isinstance(manifest.get("hash"), str):
        return "dataset"
    raise CorruptDataError(
        f"{where}: {MANIFEST} is neither an nsl dataset manifest nor a checkpoint share "
        "manifest; was it pushed with `nsl push`?"
    )


def _check(path: Path, want: dict[str, Any]) -> str | None:
    """None if ``path`` matches ``want`` (size and sha256), else a description of the difference."""
    size = path.stat().st_size
    if size != want["size"]:
        return f"{size} bytes, the manifest says {want['size']}"
    digest = sha256_file(path)
    if digest != want["sha256"]:
        return f"sha256 {digest[:12]}, the manifest says {want['sha256'][:12]}"
    return None


def _safe_rel(rel: str, where: str) -> str:
    parts = rel.split("/")
    if not rel or rel.startswith("/") or any(p in ("", ".", "..") for p in parts) or "\\" in rel:
        raise CorruptDataError(f"{where}: {MANIFEST} lists an unsafe path {rel!r}; refusing to download it")
    return rel


# -------------------------------------------------------------------- push
def push_dataset(root: Path, *, name: str, version: int, dest: str, card: str) -> PushResult:
    """Publish the dataset version folder ``root`` (``name`` at ``version``) to ``dest``."""
    loc = parse_remote(dest)
    if loc.revision:
        raise ConfigError(
            f"push destination {dest!r} names a revision; leave out '@{loc.revision}' "
            f"(the version tag v{version} comes from the dataset)"
        )
    root = Path(root)
    manifest = json.loads((root / MANIFEST).read_text())
    if loc.is_hub and loc.repo_type != "dataset":
        raise ConfigError(f"{loc.url} is a model repository; push datasets to hf://datasets/{loc.repo_id}")
    remote = open_remote(loc)
    if loc.is_hub:
        return _push_dataset_hub(remote, root, manifest, name, version, card)
    return _push_dataset_fs(remote, root, manifest, version, card)


def _push_dataset_hub(remote, root: Path, manifest: dict, name: str, version: int, card: str) -> PushResult:
    files, tag = manifest["files"], f"v{version}"
    remote.create_repo()
    branches, tags = remote.refs()
    if tag in tags:
        published = remote.read_json(MANIFEST, tags[tag]) or {}
        if published.get("hash") != manifest["hash"]:
            raise ConfigError(
                f"{remote.url} already has {tag} with other content (hash {published.get('hash')}, "
                f"this {name}@v{version} is {manifest['hash']}); push to another repository"
            )
        out = PushResult(remote.url, tags[tag], unchanged=sorted(files))
        if LEROBOT_TAG not in tags:
            remote.tag(LEROBOT_TAG, tags[tag])
            out.tags.append(LEROBOT_TAG)
        return out
    head = branches.get("main")
    current = (remote.read_json(MANIFEST, head) if head else None) or {}
    have = current.get("files") if isinstance(current.get("files"), dict) else {}
    send = {rel: root / rel for rel, f in files.items() if (have.get(rel) or {}).get("sha256") != f["sha256"]}
    delete = sorted(set(have) - set(files))
    commit = remote.commit(
        {**send, CARD: card.encode(), MANIFEST: (root / MANIFEST).read_bytes()},
        delete,
        f"nsl: {name} v{version} ({manifest['hash']})",
    )
    remote.tag(tag, commit)
    moved = []
    newest = max((int(m[1]) for t in tags if (m := VERSION_TAG.fullmatch(t))), default=0)
    if version >= newest:  # LeRobot loads the v3.0 tag: keep it on the newest version
        remote.tag(LEROBOT_TAG, commit, move=LEROBOT_TAG in tags)
        moved = [LEROBOT_TAG]
    return PushResult(
        remote.url,
        commit,
        uploaded=sorted([*send, CARD, MANIFEST]),
        unchanged=sorted(set(files) - set(send)),
        tags=[tag, *moved],
    )


def _push_dataset_fs(remote, root: Path, manifest: dict, version: int, card: str) -> PushResult:
    files, vdir = manifest["files"], f"v{version}"
    published = remote.read_json(f"{vdir}/{MANIFEST}")
    if published is not None and published.get("hash") != manifest["hash"]:
        raise ConfigError(
            f"{remote.url}/{vdir} already holds another version (hash {published.get('hash')}, "
            f"this one is {manifest['hash']}); push to another prefix"
        )
    present = remote.sizes(vdir) if published is not None else {}
    # With the remote manifest naming the same hash, a file of the right size is that file (each object
    # was complete before the manifest, written last, was); without it nothing on the remote is trusted.
    send = [rel for rel, f in sorted(files.items()) if present.get(rel) != f["size"]]
    out = PushResult(remote.url, vdir, unchanged=sorted(set(files) - set(send)))
    for rel in send:
        remote.put(f"{vdir}/{rel}", root / rel)
    out.uploaded += send
    if remote.read_bytes(f"{vdir}/{CARD}") != card.encode():
        remote.put(f"{vdir}/{CARD}", card.encode())
        out.uploaded.append(CARD)
    if send or published is None:
        remote.put(f"{vdir}/{MANIFEST}", (root / MANIFEST).read_bytes())  # last: the version is now complete
        out.uploaded.append(MANIFEST)
    return out


def push_checkpoint(
    folder: Path, *, dest: str, card: str, checkpoint: dict[str, Any], lineage: list[dict[str, Any]]
) -> PushResult:
    """Publish a checkpoint folder (``model.safetensors`` + ``config.json``) as a model repository."""
    loc = parse_remote(dest)
    if loc.revision:
        raise ConfigError(f"push destination {dest!r} names a revision; leave out '@{loc.revision}'")
    if loc.is_hub and loc.repo_type != "model":
        raise ConfigError(f"{loc.url} is a dataset repository; push checkpoints to hf://{loc.repo_id}")
    folder = Path(folder)
    manifest = checkpoint_manifest(folder, checkpoint, lineage)
    remote = open_remote(loc)
    files = manifest["files"]
    if loc.is_hub:
        remote.create_repo()
        branches, _ = remote.refs()
        head = branches.get("main")
        current = (remote.read_json(MANIFEST, head) if head else None) or {}
        have = current.get("files") if isinstance(current.get("files"), dict) else {}
        send: dict[str, Path | bytes] = {
            rel: folder / rel for rel, f in files.items() if (have.get(rel) or {}).get("sha256") != f["sha256"]
        }
        manifest["card_sha256"] = hashlib.sha256(card.encode()).hexdigest()
        if current.get("card_sha256") != manifest["card_sha256"]:
            send[CARD] = card.encode()
        if send or current != manifest:
            send[MANIFEST] = encode(manifest)
        out = PushResult(remote.url, head or "", unchanged=sorted(set(files) - set(send)))
        if send:
            out.revision = remote.commit(
                send, [], f"nsl: {checkpoint.get('name')}@{checkpoint.get('step')} ({checkpoint.get('id', '')[:12]})"
            )
            out.uploaded = sorted(send)
        return out
    published = remote.read_json(MANIFEST)
    if published is not None and (published.get("checkpoint") or {}).get("id") != checkpoint.get("id"):
        other = published.get("checkpoint") or {}
        raise ConfigError(
            f"{remote.url} already holds checkpoint {other.get('name')}@{other.get('step')} "
            f"({str(other.get('id'))[:12]}); push each checkpoint to its own prefix"
        )
    present = remote.sizes() if published is not None else {}
    send_fs = [rel for rel, f in sorted(files.items()) if present.get(rel) != f["size"]]
    out = PushResult(remote.url, str(checkpoint.get("id", "")), unchanged=sorted(set(files) - set(send_fs)))
    for rel in send_fs:
        remote.put(rel, folder / rel)
    out.uploaded += send_fs
    if remote.read_bytes(CARD) != card.encode():
        remote.put(CARD, card.encode())
        out.uploaded.append(CARD)
    if send_fs or published != manifest:
        remote.put(MANIFEST, encode(manifest))
        out.uploaded.append(MANIFEST)
    return out


# -------------------------------------------------------------------- pull
def pull(src: str, staging_root: Path) -> Pulled:
    """Download and verify the dataset version or checkpoint at ``src`` into a staging folder.

    The staging folder (under ``staging_root``, keyed by URL and revision)
    keeps verified files between attempts, so an interrupted pull resumes and
    skips them.  Every file is checked against the remote manifest before
    it is given its final name; a mismatch raises CorruptDataError naming the
    file.  The caller moves ``Pulled.folder`` into the workspace and registers it.
    """
    loc = parse_remote(src)
    remote = open_remote(loc)
    if loc.is_hub:
        pulled, base = _locate_hub(remote, loc)
    else:
        pulled, base = _locate_fs(remote, loc)
    key = hashlib.sha256(f"{loc.url}@{pulled.revision}".encode()).hexdigest()[:16]
    pulled.folder = Path(staging_root) / key
    _download(remote, pulled, base)
    if pulled.kind == "dataset":
        (pulled.folder / MANIFEST).write_bytes(encode(pulled.manifest))
    return pulled


def _locate_hub(remote, loc: Location) -> tuple[Pulled, str]:
    branches, tags = remote.refs()
    rev = loc.revision or "main"
    commit = remote.commit_of(rev, branches, tags)
    manifest = remote.read_json(MANIFEST, commit)
    if manifest is None:
        raise UnknownReferenceError(f"{loc.url}@{rev} has no {MANIFEST}; it was not pushed by nsl (or is empty)")
    kind = kind_of(manifest, f"{loc.url}@{rev}")
    version = None
    if kind == "dataset":
        named = [int(m[1]) for t, c in tags.items() if c == commit and (m := VERSION_TAG.fullmatch(t))]
        if VERSION_TAG.fullmatch(rev):
            version = int(rev[1:])
        elif named:
            version = max(named)
        else:
            raise UnknownReferenceError(
                f"{loc.url}@{rev} carries no nsl version tag (v1, v2, ...); "
                f"name one, e.g. {loc.url}@{_newest_tag(tags) or 'v1'}"
            )
    return Pulled(kind, loc, commit, manifest, Path(), version), ""


def _newest_tag(tags: dict[str, str]) -> str | None:
    versions = sorted(int(m[1]) for t in tags if (m := VERSION_TAG.fullmatch(t)))
    return f"v{versions[-1]}" if versions else None


def _locate_fs(remote, loc: Location) -> tuple[Pulled, str]:
    if loc.revision and not VERSION_TAG.fullmatch(loc.revision):
        raise ConfigError(f"{loc}: an fsspec remote has no revisions but dataset versions; write @vN, e.g. @v1")
    top = None if loc.revision else remote.read_json(MANIFEST)
    if top is not None:
        kind = kind_of(top, loc.url)
        if kind == "checkpoint":
            return Pulled(kind, loc, str(top["checkpoint"].get("id", "")), top, Path()), ""
        m = VERSION_TAG.fullmatch(loc.url.rstrip("/").rsplit("/", 1)[-1])
        if not m:
            raise ConfigError(
                f"{loc.url} holds a dataset version but its folder is not named vN; "
                "push it with `nsl push` to get the layout URL/vN/"
            )
        return Pulled(kind, loc, f"v{m[1]}", top, Path(), int(m[1])), ""
    versions = remote.versions()
    if not versions:
        raise UnknownReferenceError(
            f"{loc.url} holds no checkpoint ({MANIFEST}) and no dataset versions (vN/{MANIFEST}); check the URL"
        )
    version = int(loc.revision[1:]) if loc.revision else versions[-1]
    if version not in versions:
        raise UnknownReferenceError(
            f"{loc.url} has no version v{version}; it has {', '.join(f'v{v}' for v in versions)}"
        )
    manifest = remote.read_json(f"v{version}/{MANIFEST}")
    if manifest is None or kind_of(manifest, f"{loc.url}/v{version}") != "dataset":
        raise CorruptDataError(f"{loc.url}/v{version}/{MANIFEST} is not a dataset manifest; push it again")
    return Pulled("dataset", loc, f"v{version}", manifest, Path(), version), f"v{version}/"


def _fetch(remote, pulled: Pulled, rel: str, dest: Path) -> None:
    if pulled.location.is_hub:
        remote.fetch(rel, dest, pulled.revision)
    else:
        remote.fetch(rel, dest)


def _download(remote, pulled: Pulled, base: str) -> None:
    where = f"{pulled.location.url}@{pulled.revision}" if pulled.location.is_hub else pulled.location.url
    files = pulled.manifest["files"]
    folder = pulled.folder
    folder.mkdir(parents=True, exist_ok=True)
    for p in list(folder.rglob("*.part")) + list(folder.rglob("*.incoming.tmp")):  # an interrupted download
        shutil.rmtree(p) if p.is_dir() else p.unlink()
    wanted = {_safe_rel(rel, where) for rel in files}
    for p in sorted(folder.rglob("*")):  # files of another manifest (e.g. the remote was re-pushed)
        rel = p.relative_to(folder).as_posix()
        if p.is_file() and rel not in wanted and rel != MANIFEST:
            p.unlink()
    for rel in sorted(files):
        want, dest = files[rel], folder / rel
        if dest.is_file() and _check(dest, want) is None:
            pulled.reused.append(rel)
            continue
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(f".{dest.name}.{uuid.uuid4().hex[:8]}.part")
        try:
            try:
                _fetch(remote, pulled, base + rel, tmp)
            except FileNotFoundError:
                raise CorruptDataError(
                    f"{where}: file {rel} is in the published {MANIFEST} but missing on the "
                    "remote; the push was incomplete, push it again"
                ) from None
            problem = _check(tmp, want)
            if problem is not None:
                raise CorruptDataError(
                    f"{where}: file {rel} does not match the published {MANIFEST} ({problem}); "
                    "the remote copy was altered or is incomplete, nothing was registered"
                )
            os.replace(tmp, dest)
        finally:
            if tmp.exists():
                tmp.unlink()
        pulled.downloaded.append(rel)
