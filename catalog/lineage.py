"""Lineage trees of the catalog: ancestry and descendants of a checkpoint, as text.

Ancestry (``nsl catalog lineage REF``) walks the parent chain: each node
shows the datasets that training step used (version, tier, shift, episodes,
batch weight) and the checkpoint's pooled evaluations; the last branch of a
node is the checkpoint it was fine-tuned from.  Descendants (``--descendants``)
draw the tree of every checkpoint that started from REF, directly or not.

This module reads the catalog (:mod:`.store`) and formats with :mod:`.render`;
neither of those imports it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from nsl.errors import UnknownReferenceError

from .origins import origin_of
from .records import CheckpointEntry, DataUse, short_hash
from .render import pooled_results
from .store import Catalog

INDENT = "   "


def _head(c: CheckpointEntry) -> str:
    return f"{c.ref}  {c.short_id}  trained for {c.shift}, {c.created.replace('T', ' ').replace('Z', ' UTC')}"


def _data_line(cat: Catalog, u: DataUse) -> str:
    try:
        d = cat.dataset(u.dataset, u.version)
        what = f"{d.shift_name}, {d.episodes} episodes"
        if u.hash and d.hash != u.hash:
            what += ", CONTENT CHANGED since training"
        o = origin_of(cat, "dataset", d.ref, d.hash)
        if o is not None:
            what += f", pulled from {o.url} at {o.revision[:12]}"
    except UnknownReferenceError:
        what = f"not in this catalog, content {short_hash(u.hash)}" if u.hash else "not in this catalog"
    return f"data: {u.label} ({what}), weight {u.weight:g}"


def _published_data_line(cat: Catalog, d: Mapping[str, Any]) -> str:
    """A dataset named in a pulled checkpoint's published lineage (maybe not in this workspace)."""
    try:
        row = cat.dataset(d["dataset"], d["version"])
        if row.hash == d.get("hash"):
            return _data_line(cat, DataUse(d["dataset"], d["version"], d["weight"], d.get("tier"), d["hash"]))
    except UnknownReferenceError:
        pass
    tier = f":{d['tier']}" if d.get("tier") else ""
    what = ", ".join(x for x in (d.get("shift"), f"{d['episodes']} episodes" if "episodes" in d else None) if x)
    return (
        f"data: {d['dataset']}@v{d['version']}{tier} ({what + ', ' if what else ''}hash "
        f"{short_hash(d.get('hash'))}; published, not in this workspace), weight {d['weight']:g}"
    )


def _eval_text(r: Mapping[str, Any]) -> str:
    return (
        f"eval: {r['shift']} ({r['split']} objects) {100 * r['rate']:.1f}% "
        f"[{100 * r['ci_low']:.1f}, {100 * r['ci_high']:.1f}] over {r['episodes']} episodes"
    )


def _eval_lines(cat: Catalog, c: CheckpointEntry) -> list[str]:
    return [_eval_text(r) for r in pooled_results(cat.evaluations(c.id))]


def _published_tail(cat: Catalog, nodes: Sequence[Mapping[str, Any]], depth: int, evaluations: bool) -> list[str]:
    """Ancestors known only from a pulled checkpoint's published lineage, drawn like local ones."""
    lines = []
    for i, n in enumerate(nodes):
        d = depth + i
        lines.append(
            f"{INDENT * (d - 1)}└─ from {n['name']}@{n['step']}  {str(n['id'])[:12]}  trained for "
            f"{n['shift']} (published lineage; not in this workspace)"
        )
        items = [_published_data_line(cat, x) for x in n.get("data", [])] or ["data: none recorded"]
        if evaluations:
            items += [_eval_text(r) for r in n.get("evaluations", [])]
        lines += [f"{INDENT * d}├─ {item}" for item in items]
    last = nodes[-1]
    tail = f"from {str(last['parent'])[:12]} (not published)" if last.get("parent") else "from scratch (no parent)"
    lines.append(f"{INDENT * (depth + len(nodes) - 1)}└─ {tail}")
    return lines


def format_lineage(cat: Catalog, ref: str, evaluations: bool = True) -> str:
    """The ancestry of ``ref`` as an indented tree, newest checkpoint on top.

    A pulled checkpoint shows where it came from (``origin:``), and the data
    and ancestors of its published lineage that are not in this workspace.
    """
    chain = cat.lineage(ref)
    lines: list[str] = []
    for depth, c in enumerate(chain):
        pad = INDENT * depth
        lines.append(_head(c) if depth == 0 else f"{INDENT * (depth - 1)}└─ from {_head(c)}")
        o = origin_of(cat, "checkpoint", c.id)
        published = o.lineage if o is not None and o.lineage and o.lineage[0].get("id") == c.id else []
        when = o.created.replace("T", " ").replace("Z", " UTC") if o else ""
        items = [f"origin: pulled from {o.url} (revision {o.revision}) on {when}"] if o else []
        if published:  # as published, in its order; datasets that are here show as local ones
            shown = {(d["dataset"], d["version"], d.get("tier")) for d in published[0].get("data", [])}
            data = [_published_data_line(cat, d) for d in published[0].get("data", [])]
            data += [_data_line(cat, u) for u in c.data if (u.dataset, u.version, u.tier) not in shown]
        else:
            data = [_data_line(cat, u) for u in c.data]
        items += data or ["data: none recorded"]
        if evaluations:
            items += _eval_lines(cat, c)
            pub_evals = published[0].get("evaluations", []) if published else []
            items += [_eval_text(r) + " (published)" for r in pub_evals]
        for item in items:
            lines.append(f"{pad}├─ {item}")
        if depth == len(chain) - 1:
            if c.parent is None and len(published) > 1:
                lines += _published_tail(cat, published[1:], depth + 1, evaluations)
                continue
            tail = f"from {c.parent[:12]} (removed from the catalog)" if c.parent else "from scratch (no parent)"
            lines.append(f"{pad}└─ {tail}")
    return "\n".join(lines)


def format_descendants(cat: Catalog, ref: str) -> str:
    """Every checkpoint fine-tuned from ``ref``, directly or through others, as a tree."""
    root = cat.checkpoint(ref)
    lines = [_head(root)]

    def walk(c: CheckpointEntry, prefix: str) -> None:
        kids = cat.children(c.id)
        for i, k in enumerate(kids):
            last = i == len(kids) - 1
            uses = DataUse.mix(k.data)
            lines.append(f"{prefix}{'└─ ' if last else '├─ '}{_head(k)}  data: {uses or 'none'}")
            walk(k, prefix + ("   " if last else "│  "))

    walk(root, "")
    if len(lines) == 1:
        lines.append("└─ (nothing was fine-tuned from it yet)")
    return "\n".join(lines)
