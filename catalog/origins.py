"""Origins: where a pulled dataset version or checkpoint came from.

``nsl pull`` registers what it brings in like anything else, then records an
origin row: the remote URL, the revision (a Hub commit id, or the remote's
version), and what was published with it.  For a checkpoint that is its
*published lineage*: the chain of checkpoints it descends from, each with the
datasets it was trained on (name, version, tier, weight, content hash) and its
pooled evaluations, as the publishing workspace's catalog knew them.  So
``nsl catalog lineage`` shows the parent and the data of a pulled checkpoint
even when neither was pulled, and pushing it on passes the chain along.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from nsl.errors import ConfigError, UnknownReferenceError

from .records import CheckpointEntry, dumps
from .render import pooled_results
from .schema import utc_now

if TYPE_CHECKING:
    from .store import Catalog

KINDS = ("dataset", "checkpoint")


@dataclass(frozen=True)
class Origin:
    kind: str  # "dataset" or "checkpoint"
    entry: str  # dataset NAME@vN, or checkpoint id
    hash: str  # what was pulled: the dataset's content hash, or the checkpoint id
    url: str
    revision: str
    created: str
    published: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def lineage(self) -> list[dict[str, Any]]:
        """The published lineage (checkpoints only): this checkpoint first, then its ancestors."""
        return list(self.published.get("lineage") or [])


def record_origin(
    cat: Catalog,
    kind: str,
    entry: str,
    *,
    hash: str,
    url: str,
    revision: str,
    published: Mapping[str, Any] | None = None,
) -> Origin:
    """Record that ``entry`` was pulled from ``url`` at ``revision``; the same record twice is kept once."""
    if kind not in KINDS:
        raise ConfigError(f"origin kind {kind!r} must be one of {KINDS}")
    if "@" in url.split("://", 1)[-1].split("/", 1)[0]:
        raise ConfigError(f"origin URL {url!r} carries credentials; record the URL without them")
    with cat.write() as c:
        row = c.execute(
            "SELECT * FROM origins WHERE kind = ? AND entry = ? AND hash = ? AND url = ? AND revision = ?",
            (kind, entry, hash, url, revision),
        ).fetchone()
        if row is None:
            c.execute(
                "INSERT INTO origins (kind, entry, hash, url, revision, published, created) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                (kind, entry, hash, url, revision, dumps(dict(published or {})), utc_now()),
            )
    found = origin_of(cat, kind, entry, hash)
    assert found is not None
    return found


def origin_of(cat: Catalog, kind: str, entry: str, hash: str | None = None) -> Origin | None:
    """The newest origin of ``entry`` (for this content ``hash``, if given), or None if it was made here."""
    q, args = "SELECT * FROM origins WHERE kind = ? AND entry = ?", [kind, entry]
    if hash is not None:
        q += " AND hash = ?"
        args.append(hash)
    r = cat.conn.execute(q + " ORDER BY seq DESC LIMIT 1", args).fetchone()
    if r is None:
        return None
    _seq, kind, entry, h, url, revision, published, created = r
    return Origin(kind, entry, h, url, revision, created, json.loads(published))


def _node(cat: Catalog, c: CheckpointEntry) -> dict[str, Any]:
    data = []
    for u in c.data:
        d = {"dataset": u.dataset, "version": u.version, "tier": u.tier, "weight": u.weight, "hash": u.hash}
        try:
            row = cat.dataset(u.dataset, u.version)
            d.update(shift=row.shift_name, episodes=row.episodes)
        except UnknownReferenceError:
            pass
        data.append(d)
    return {
        "id": c.id,
        "name": c.name,
        "step": c.step,
        "shift": c.shift,
        "parent": c.parent,
        "created": c.created,
        "code_version": c.code_version,
        "data": data,
        "evaluations": pooled_results(cat.evaluations(c.id)),
    }


def published_lineage(cat: Catalog, entry: CheckpointEntry) -> list[dict[str, Any]]:
    """What ``nsl push`` publishes about ``entry``: it and its ancestors, newest first.

    Nodes known here come from the catalog; a pulled node contributes the
    data it was published with, and the chain goes on with the published
    ancestors of the oldest node found here.
    """
    chain = cat.lineage(entry.id)
    out = []
    for c in chain:
        node = _node(cat, c)
        o = origin_of(cat, "checkpoint", c.id)
        if o is not None and o.lineage and o.lineage[0].get("id") == c.id:
            node["data"] = o.lineage[0].get("data", node["data"])
            node["origin"] = {"url": o.url, "revision": o.revision}
        out.append(node)
    last = chain[-1]
    o = origin_of(cat, "checkpoint", last.id)
    if o is not None and o.lineage and o.lineage[0].get("id") == last.id:
        out += o.lineage[1:]
    return out
