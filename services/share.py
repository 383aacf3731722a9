"""Share dataset versions and checkpoints: push them to a remote, pull them into the workspace and catalogue them.

The remotes are those of ``nsl.share`` (the Hugging Face Hub, or any fsspec
URL such as ``s3://bucket/prefix`` or ``file:///path``).  Every file is checked
against the published sha256 digests before anything is placed or registered.
:func:`checkpoint_folder` finds a checkpoint by folder, catalog reference or
remote (what ``nsl.load_policy`` loads); a remote one is pulled into the cache.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["Pulled", "Pushed", "checkpoint_folder", "fetch_checkpoint", "pull", "push"]


@dataclass(frozen=True)
class Pushed:
    """What :func:`push` published: the local ref, the remote URL and revision, and the files sent or kept."""

    what: str  # data:NAME@vN or ckpt:NAME@STEP (id)
    url: str
    revision: str
    tags: tuple[str, ...]
    uploaded: tuple[str, ...]
    unchanged: tuple[str, ...]


@dataclass(frozen=True)
class Pulled:
    """What :func:`pull` placed in the workspace: the local ref, where it came from, and the files fetched."""

    what: str  # data:NAME@vN (hash) or ckpt:NAME@STEP (id)
    url: str
    revision: str
    downloaded: tuple[str, ...]
    reused: tuple[str, ...]


# ------------------------------------------------------------------- push
def push(ref: str, dest: str) -> Pushed:
    """Publish dataset version ``data:NAME@vN`` or checkpoint ``ckpt:NAME[@STEP|@best|@TAG]`` to ``dest``."""
    from nsl.errors import ConfigError

    ref = ref.strip()
    result: Any
    if ref.startswith("data:"):
        result, what = _push_dataset(ref, dest)
    elif ref.startswith("ckpt:"):
        result, what = _push_checkpoint(ref, dest)
    else:
        raise ConfigError(
            f"push reference {ref!r} needs a prefix: data:NAME@vN for a dataset version or "
            "ckpt:NAME@STEP for a checkpoint"
        )
    return Pushed(
        what, result.url, result.revision, tuple(result.tags), tuple(result.uploaded), tuple(result.unchanged)
    )


def _push_dataset(ref: str, dest: str):
    from nsl.datasets import api
    from nsl.errors import ConfigError
    from nsl.share import dataset_card, push_dataset

    view = api.open_view(ref)
    v = view.version
    if view.num_episodes != v.num_episodes:
        raise ConfigError(
            f"{ref} is a tier; push whole versions (data:{v.ref}), or write the tier as its own "
            f"dataset with `nsl dataset export {ref} --out DIR`"
        )
    api.verify(v.ref)  # publish only what still matches its manifest
    spec = v.provenance["collections"][-1]["spec"]
    env = spec.get("env", {})
    card = dataset_card(
        name=v.name,
        version=v.version,
        content_hash=v.hash,
        episodes=v.num_episodes,
        frames=v.num_frames,
        success_rate=view.success_rate,
        shift=str(env.get("shift_spec", {}).get("name") or env.get("shift", "base")),  # engine:NAME+... off MuJoCo
        policy=str(spec.get("policy_ref", "?")),
        env_version=str(env.get("env_version", "?")),
        codebase_version=api.layout.CODEBASE_VERSION,
        provenance=v.provenance,
    )
    return push_dataset(v.root, name=v.name, version=v.version, dest=dest, card=card), f"data:{v.ref}"


def _push_checkpoint(ref: str, dest: str):
    from nsl.catalog import Catalog, folder_checkpoint_id, published_lineage, render_model_card
    from nsl.errors import CorruptDataError, UnknownReferenceError
    from nsl.share import push_checkpoint

    from .refs import resolve_init

    with Catalog() as cat:
        entry = resolve_init(cat, ref)
        if folder_checkpoint_id(Path(entry.path)) != entry.id:
            raise CorruptDataError(
                f"checkpoint {entry.path} no longer matches its catalog id {entry.short_id}; "
                "run `nsl catalog verify` and restore it before pushing"
            )
        datasets = {}
        for u in entry.data:
            try:
                datasets[(u.dataset, u.version)] = cat.dataset(u.dataset, u.version)
            except UnknownReferenceError:
                pass
        published = published_lineage(cat, entry)
        card = render_model_card(
            entry, cat.lineage(entry.id)[1:], datasets, cat.evaluations(entry.id), {"published": published}
        )
    checkpoint = {
        "id": entry.id,
        "name": entry.name,
        "step": entry.step,
        "shift": entry.shift,
        "code_version": entry.code_version,
    }
    result = push_checkpoint(Path(entry.path), dest=dest, card=card, checkpoint=checkpoint, lineage=published)
    return result, f"ckpt:{entry.ref} ({entry.short_id})"


# ------------------------------------------------------------------- pull
def pull(src: str, as_name: str | None = None) -> Pulled:
    """Download ``src`` (a remote, optionally ``@REVISION``), verify it, place it in the workspace, catalogue it.

    ``as_name`` is the local dataset or checkpoint name (default: the published one).  An interrupted pull
    resumes, skipping the files it already verified.
    """
    from nsl import workspace
    from nsl.catalog import Catalog
    from nsl.share import pull as fetch

    pulled = fetch(src, workspace.cache_dir() / "pull")
    with Catalog() as cat:
        if pulled.kind == "dataset":
            what = _place_dataset(cat, pulled, as_name)
        else:
            what = _place_checkpoint(cat, pulled, as_name)
    shutil.rmtree(pulled.folder, ignore_errors=True)  # gone already when it was moved into place
    return Pulled(what, pulled.url, pulled.revision, tuple(pulled.downloaded), tuple(pulled.reused))


def _place_dataset(cat, pulled, as_name: str | None) -> str:
    from nsl.catalog import record_origin
    from nsl.datasets import api
    from nsl.datasets.versions import hash_of
    from nsl.errors import ConfigError, CorruptDataError
    from nsl.locks import dataset_lock

    from .refs import register_dataset

    m = pulled.manifest
    if hash_of(m["files"]) != m["hash"]:
        raise CorruptDataError(
            f"{pulled.url}: manifest.json records hash {m['hash']} that does not match its "
            "file list; the remote is damaged, ask for it to be pushed again"
        )
    name = api.parse_ref(as_name or pulled.location.name).name
    staged = api.DatasetVersion(name, pulled.version, pulled.folder)
    staged.episodes  # noqa: B018  # the metadata must agree with info.json before anything is placed
    target = api.dataset_root(name) / api.layout.VERSION_DIR.format(version=pulled.version)
    with dataset_lock(name):  # a collection of the same name cannot publish this version meanwhile
        if target.exists():
            here = api.open_version(f"{name}@v{pulled.version}")
            if here.hash != m["hash"]:
                raise ConfigError(
                    f"dataset {name}@v{pulled.version} already exists here with hash {here.hash}, the "
                    f"pulled one is {m['hash']}; pull it under another name with --as NAME"
                )
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            os.rename(pulled.folder, target)
    version = api.open_version(f"{name}@v{pulled.version}")
    register_dataset(cat, version)
    record_origin(
        cat,
        "dataset",
        version.ref,
        hash=version.hash,
        url=pulled.url,
        revision=pulled.revision,
        published={"name": pulled.location.name, "version": pulled.version, "requested": str(pulled.location)},
    )
    return f"data:{version.ref} ({version.hash})"


def checkpoint_folder(source) -> Path:
    """The folder of a checkpoint named by ``source``: a catalog reference (``ckpt:NAME[@STEP|@best|@TAG]``,
    ``base``), a checkpoint folder, or a shared checkpoint (``hf://OWNER/NAME``, a bare Hub repo id
    ``OWNER/NAME``, or an fsspec URL such as ``s3://bucket/prefix``; ``@REVISION`` optional), which is pulled
    and verified into the workspace's cache (:func:`fetch_checkpoint`).
    """
    import re

    from nsl.catalog import Catalog
    from nsl.errors import UnknownReferenceError

    from .refs import pinned, resolve_init

    text = str(source).strip()
    if text.startswith("ckpt:") or text == "base":
        entry = pinned(text)
        if entry is None:
            with Catalog() as cat:
                entry = resolve_init(cat, text)
        return Path(entry.path)
    folder = Path(text).expanduser()
    if folder.is_dir():
        return folder
    hub_repo = re.fullmatch(r"[A-Za-z0-9][\w.-]*/[A-Za-z0-9][\w.-]*(@[\w.-]+)?", text)
    if "://" in text or hub_repo:
        return fetch_checkpoint(text if "://" in text else "hf://" + text)
    raise UnknownReferenceError(
        f"checkpoint {text!r} is neither a folder, a catalog reference (ckpt:NAME) nor a shared one "
        "(OWNER/NAME on the Hub, hf://OWNER/NAME, s3://...)"
    )


def fetch_checkpoint(src: str) -> Path:
    """The folder of the checkpoint shared at ``src`` (a Hub repo or fsspec URL, ``@REVISION`` optional), pulled
    and verified into the workspace's cache, not catalogued (as ``from_pretrained`` caches a Hub model).

    A second call re-verifies the cached files and downloads only what changed.
    """
    from nsl import workspace
    from nsl.errors import ConfigError
    from nsl.share import pull as fetch

    pulled = fetch(src, workspace.cache_dir() / "policies")
    if pulled.kind != "checkpoint":
        raise ConfigError(f"{pulled.url} holds a dataset version, not a checkpoint; `nsl pull {src}` brings it in")
    _verified_checkpoint_id(pulled)
    return pulled.folder


def _verified_checkpoint_id(pulled) -> str:
    """The pulled checkpoint's content id, checked against its manifest's, and its config and weights loaded."""
    from nsl.catalog import folder_checkpoint_id
    from nsl.errors import CorruptDataError
    from nsl.learners import load_checkpoint

    ck = pulled.manifest["checkpoint"]
    cid = folder_checkpoint_id(pulled.folder)
    if cid != ck.get("id"):
        raise CorruptDataError(
            f"{pulled.url}: the pulled files make checkpoint id {cid[:12]}, the manifest says "
            f"{str(ck.get('id'))[:12]}; the remote is inconsistent, ask for it to be pushed again"
        )
    load_checkpoint(pulled.folder)  # its config and weights must load before it is registered
    return cid


def _place_checkpoint(cat, pulled, as_name: str | None) -> str:
    from nsl import workspace
    from nsl.catalog import DataUse, record_origin
    from nsl.errors import ConfigError, UnknownReferenceError

    m = pulled.manifest
    ck, lineage = m["checkpoint"], list(m.get("lineage") or [])
    cid = _verified_checkpoint_id(pulled)
    origin = {
        "hash": cid,
        "url": pulled.url,
        "revision": pulled.revision,
        "published": {"checkpoint": ck, "lineage": lineage, "requested": str(pulled.location)},
    }
    try:
        entry = cat.checkpoint(cid)
    except UnknownReferenceError:
        entry = None
    if entry is not None:  # the same weights and config are here already (pulled before, or made here)
        record_origin(cat, "checkpoint", cid, **origin)
        return f"ckpt:{entry.ref} ({entry.short_id}, already in the catalog)"
    name = as_name or str(ck.get("name"))
    step = int(ck.get("step", 0))
    node = lineage[0] if lineage and lineage[0].get("id") == cid else {}
    parent = node.get("parent")
    if parent:
        try:
            parent = cat.checkpoint(parent).id
        except UnknownReferenceError:
            parent = None  # not in this workspace: the published lineage records it
    uses = []
    for d in node.get("data", []):
        try:
            if cat.dataset(d["dataset"], d["version"]).hash == d.get("hash"):
                uses.append(DataUse(d["dataset"], d["version"], d["weight"], d.get("tier")))
        except UnknownReferenceError:
            pass
    dest = workspace.checkpoints_dir() / name / f"{step:08d}-{cid[:12]}"
    if dest.exists():
        raise ConfigError(f"{dest} exists but is not in the catalog; move it away or run `nsl catalog gc`")
    dest.parent.mkdir(parents=True, exist_ok=True)
    os.rename(pulled.folder, dest)
    try:
        entry = cat.register_checkpoint(
            dest,
            name=name,
            step=step,
            parent=parent,
            data=uses,
            shift=ck.get("shift") or node.get("shift"),
            card_info={"summary": f"Pulled from {pulled.url} (revision {pulled.revision}).", "published": lineage},
        )
    except BaseException:
        os.rename(dest, pulled.folder)  # back to staging: nothing half-registered stays in the workspace
        raise
    record_origin(cat, "checkpoint", cid, **origin)
    return f"ckpt:{entry.ref} ({entry.short_id})"
