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

from nsl.errors import UnknownReferenceError

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
    except UnknownReferenceError:
        what = f"not in this catalog, content {short_hash(u.hash)}" if u.hash else "not in this catalog"
    return f"data: {u.label} ({what}), weight {u.weight:g}"


def _eval_lines(cat: Catalog, c: CheckpointEntry) -> list[str]:
    out = []
    for r in pooled_results(cat.evaluations(c.id)):
        out.append(f"eval: {r['shift']} ({r['split']} objects) {100 * r['rate']:.1f}% "
                   f"[{100 * r['ci_low']:.1f}, {100 * r['ci_high']:.1f}] over {r['episodes']} episodes")
    return out


def format_lineage(cat: Catalog, ref: str, evaluations: bool = True) -> str:
    """The ancestry of ``ref`` as an indented tree, newest checkpoint on top."""
    chain = cat.lineage(ref)
    lines: list[str] = []
    for depth, c in enumerate(chain):
        pad = INDENT * depth
        lines.append(_head(c) if depth == 0 else f"{INDENT * (depth - 1)}└─ from {_head(c)}")
        items = [_data_line(cat, u) for u in c.data] or ["data: none recorded"]
        if evaluations:
            items += _eval_lines(cat, c)
        for item in items:
            lines.append(f"{pad}├─ {item}")
        if depth == len(chain) - 1:
            tail = (f"from {c.parent[:12]} (removed from the catalog)" if c.parent else "from scratch (no parent)")
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
